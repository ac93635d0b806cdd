"""The robot's own motion in its own frame, exact, and the predictors that need no learning.

The observation (paper_spec §2) gives the goal and every human in the robot's frame. The robot
knows its command: a turn by ``Δθ = ω·dt`` then a step of ``v·dt`` along the new heading (the
simulator's unicycle update). A point that does not move in the world, seen from the new frame,
is therefore ``R(−Δθ)·p − (v·dt, 0)``: pure kinematics, nothing to learn.

Three predictors use only the observations and the actions, and every world model is measured
against them (:mod:`socnav_wm.worldmodel.prediction`):

* ``copy-last``: everything stays where it was last seen, in the robot's frame;
* ``static``: the humans stand still in the world; the robot's motion is applied exactly;
* ``constant-velocity``: each human keeps the world velocity of its last step, estimated from
  its last two observations after undoing the robot's motion; the robot's motion is exact.

Positions here are arrays ``(..., 1 + H, 2)``: the goal, then each human, in the robot frame.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from socnav_wm.env.core import discrete_commands
from socnav_wm.env.params import EnvParams

PREDICTORS: tuple[str, ...] = ("copy-last", "static", "constant-velocity")
"""The no-learning predictors, in the order they are reported."""


def positions(obs: np.ndarray) -> np.ndarray:
    """Observations (..., 2 + 7·H) → positions (..., 1 + H, 2): the goal, then each human."""
    obs = np.asarray(obs, dtype=np.float64)
    num_humans = (obs.shape[-1] - 2) // 7
    humans = obs[..., 2:].reshape(*obs.shape[:-1], num_humans, 7)[..., :2]
    return np.concatenate([obs[..., None, :2], humans], axis=-2)


class Motion(NamedTuple):
    """What the robot executes in a step: forward speed ``v`` (m/s) and turn rate ``omega``
    (rad/s); for the holonomic robot also the sideways speed ``vy`` (None: the unicycle)."""

    v: np.ndarray
    omega: np.ndarray
    vy: np.ndarray | None = None


def commands_of(actions: np.ndarray, params: EnvParams) -> Motion:
    """The motion of discrete actions (any shape), or of continuous commands (..., 2) clipped
    to the robot's limits, as the simulator executes them (:meth:`Simulator.commands`)."""
    a = np.asarray(actions)
    holonomic = params.kinematics == "holonomic"
    if np.issubdtype(a.dtype, np.integer):
        table = discrete_commands(params)
        if holonomic:
            return Motion(table[a, 0], np.zeros(a.shape), table[a, 1])
        return Motion(table[a, 0], table[a, 1])
    if holonomic:
        a = a.astype(np.float64)
        speed = np.hypot(a[..., 0], a[..., 1])
        scale = params.robot_max_speed / np.maximum(speed, params.robot_max_speed)
        return Motion(a[..., 0] * scale, np.zeros(a.shape[:-1]), a[..., 1] * scale)
    v = np.clip(a[..., 0], -params.robot_max_speed, params.robot_max_speed)
    w = np.clip(a[..., 1], -params.robot_max_rotation, params.robot_max_rotation)
    return Motion(v.astype(np.float64), w.astype(np.float64))


def ego_step(points: np.ndarray, motion: Motion, dt: float) -> np.ndarray:
    """Robot-frame points (..., P, 2) of static world points, seen after the robot executed
    ``motion`` (shape ``...``) for ``dt``: ``R(−ω·dt)·p − (v·dt, 0)`` for the unicycle,
    ``p − (v·dt, vy·dt)`` for the holonomic robot."""
    x, y = points[..., 0], points[..., 1]
    if motion.vy is not None:
        return np.stack(
            [x - np.asarray(motion.v)[..., None] * dt, y - np.asarray(motion.vy)[..., None] * dt],
            axis=-1,
        )
    angle = np.asarray(motion.omega, dtype=np.float64)[..., None] * dt
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * x + s * y - np.asarray(motion.v)[..., None] * dt, -s * x + c * y], axis=-1)


def advance_pose(pose: np.ndarray, motion: Motion, dt: float) -> np.ndarray:
    """The robot's room pose (N, 3: x, y, θ) after it executes ``motion`` (N,): for the
    unicycle a turn by ``ω·dt``, then a step of ``v·dt`` along the new heading (the simulator's
    update, without its wrap of θ, which changes no position); for the holonomic robot a step
    of ``(v, vy)·dt`` in its frame, the heading unchanged."""
    if motion.vy is not None:
        c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
        return np.column_stack(
            [
                pose[:, 0] + (motion.v * c - motion.vy * s) * dt,
                pose[:, 1] + (motion.v * s + motion.vy * c) * dt,
                pose[:, 2],
            ]
        )
    theta = pose[:, 2] + motion.omega * dt
    step = motion.v * dt
    return np.column_stack(
        [pose[:, 0] + step * np.cos(theta), pose[:, 1] + step * np.sin(theta), theta]
    )


def rotate_vectors(vectors: np.ndarray, omega: np.ndarray, dt: float) -> np.ndarray:
    """Robot-frame vectors (..., P, 2) (velocities) after the robot turned by ``ω·dt``."""
    angle = np.asarray(omega, dtype=np.float64)[..., None] * dt
    c, s = np.cos(angle), np.sin(angle)
    x, y = vectors[..., 0], vectors[..., 1]
    return np.stack([c * x + s * y, -s * x + c * y], axis=-1)


def human_velocities(
    previous_obs: np.ndarray, obs: np.ndarray, previous_action: np.ndarray, params: EnvParams
) -> np.ndarray:
    """Per-step velocities (B, 1 + H, 2) in the current robot frame: each human's displacement
    between the two observations after undoing the robot's motion ``previous_action``; zero for
    the goal, which never moves."""
    current = positions(obs)
    velocity = np.zeros_like(current)
    seen_from_now = ego_step(
        positions(previous_obs), commands_of(previous_action, params), params.dt
    )
    velocity[:, 1:] = current[:, 1:] - seen_from_now[:, 1:]
    return velocity


def advance(
    points: np.ndarray, velocity: np.ndarray, motion: Motion, dt: float
) -> tuple[np.ndarray, np.ndarray]:
    """One step of points moving at ``velocity`` (per step, robot frame) while the robot executes
    ``motion``: the new robot-frame points and velocities (the world velocity is kept)."""
    return ego_step(points + velocity, motion, dt), rotate_vectors(velocity, motion.omega, dt)


def predict_positions(
    name: str,
    previous_obs: np.ndarray,
    obs: np.ndarray,
    previous_action: np.ndarray,
    future_actions: np.ndarray,
    params: EnvParams,
) -> np.ndarray:
    """Open-loop positions (B, K, 1 + H, 2) after each of the ``K`` future actions (B, K).

    ``obs`` (B, D) is the current observation, ``previous_obs`` the one before it and
    ``previous_action`` (B,) the action between them (used by ``constant-velocity`` only).
    """
    if name not in PREDICTORS:
        raise ValueError(f"predictor: unknown {name!r}; expected one of {', '.join(PREDICTORS)}")
    current = positions(obs)
    if name == "constant-velocity":
        velocity = human_velocities(previous_obs, obs, previous_action, params)
    else:
        velocity = np.zeros_like(current)
    motion = commands_of(future_actions, params)
    out = np.empty((current.shape[0], future_actions.shape[1], *current.shape[1:]))
    for k in range(future_actions.shape[1]):
        if name != "copy-last":
            step = Motion(*(None if m is None else m[:, k] for m in motion))
            current, velocity = advance(current, velocity, step, params.dt)
        out[:, k] = current
    return out
