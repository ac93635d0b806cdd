"""Classic crowd-navigation controllers for the robot: ORCA (RVO2) and the Social Force Model.

These are the textbook controllers the paper meant, not its authors' scripts, which mixed the
robot and world frames and misordered RVO2's arguments (paper_spec §6). Both read the
simulator's world-frame state (they are not learned from the 23-d observation), compute a
desired world-frame velocity, and turn it into the robot's unicycle command ``(v, ω)`` through
one shared function, :func:`unicycle_command`; the simulator clips the command to its limits
(±0.14 m/s, ±0.3876 rad/s by default) as for any continuous action.

Both controllers are stateless and batched over the ``N`` environments of a
:class:`~socnav_wm.env.state.BatchState`: ``policy.act(sim.state, sim.params)`` returns the
``(N, 2)`` float64 commands for ``sim.step``. The robot's current velocity is its last command
along its heading (``robot_v``·(cos θ, sin θ)), which is how it actually moved during the last
step.

Usage::

    policy = make_baseline("orca", safety_margin=0.1)
    commands = policy.act(sim.state, sim.params)
    sim.step(commands)
"""

from __future__ import annotations

import math
from typing import Any, Protocol

import numpy as np

from socnav_wm.agents.baseline_params import OrcaBaselineParams, SfmBaselineParams
from socnav_wm.env import orca
from socnav_wm.env.obstacles import nearest_points, obstacle_map, polygon_sizes, polygons
from socnav_wm.env.params import EnvParams
from socnav_wm.env.state import BatchState

__all__ = [
    "BASELINES",
    "BaselinePolicy",
    "OrcaBaseline",
    "OrcaBaselineParams",
    "SfmBaseline",
    "SfmBaselineParams",
    "holonomic_command",
    "make_baseline",
    "unicycle_command",
]

# Desired velocities shorter than this (m/s) carry no direction: the robot stays put.
_MIN_SPEED = 1e-9


class BaselinePolicy(Protocol):
    """A controller that reads the simulator state and returns continuous commands."""

    name: str

    def act(self, state: BatchState, params: EnvParams) -> np.ndarray:
        """(N, 2) float64 commands (v m/s, ω rad/s) for every env of ``state``.

        Finished envs (``state.done``) get commands too; the simulator ignores them.
        """
        ...


def unicycle_command(
    desired_velocity: np.ndarray,
    robot_theta: np.ndarray,
    *,
    max_speed: float,
    max_rotation: float,
    dt: float,
    heading_gain: float = 1.0,
) -> np.ndarray:
    """Turn world-frame desired velocities into unicycle commands within the robot's limits.

    The robot turns towards the desired velocity and advances in proportion to how well its
    heading already agrees with it::

        e = wrap(atan2(v_des) − θ)                        heading error, (−π, π]
        ω = clip(heading_gain · e / dt, −max_rotation, max_rotation)
        v = clip(‖v_des‖ · max(0, cos e), 0, max_speed)

    so a velocity straight ahead is followed at its speed, one at 90° or behind gives a turn in
    place, and the robot never reverses (its sensors and the paper's actions face forward). The
    error is measured before the turn: the simulator turns first and then advances, so the
    advance ends up better aligned than ``cos e`` assumes, which errs on the side of caution.

    Args:
        desired_velocity: (N, 2) world-frame velocities, m/s.
        robot_theta: (N,) robot headings, rad.
        max_speed: the robot's linear speed limit, m/s.
        max_rotation: the robot's angular speed limit, rad/s.
        dt: the simulation step, s.
        heading_gain: fraction of the heading error corrected in one step (1: all of it, as far
            as ``max_rotation`` allows).

    Returns:
        (N, 2) float64 commands (v m/s, ω rad/s); zero where the desired speed is ~0.
    """
    desired_velocity = np.asarray(desired_velocity, dtype=np.float64)
    robot_theta = np.asarray(robot_theta, dtype=np.float64)
    speed = np.linalg.norm(desired_velocity, axis=-1)
    direction = np.arctan2(desired_velocity[:, 1], desired_velocity[:, 0])
    error = direction - robot_theta
    # Wrap to (−π, π]: the shorter way round.
    error = error - 2.0 * np.pi * np.ceil((error - np.pi) / (2.0 * np.pi))
    moving = speed > _MIN_SPEED
    omega = np.clip(heading_gain * error / dt, -max_rotation, max_rotation)
    v = np.clip(speed * np.maximum(0.0, np.cos(error)), 0.0, max_speed)
    commands = np.zeros((robot_theta.shape[0], 2))
    commands[:, 0] = np.where(moving, v, 0.0)
    commands[:, 1] = np.where(moving, omega, 0.0)
    return commands


def _robot_velocity(state: BatchState) -> np.ndarray:
    """(N, 2) world-frame robot velocity during the last step, m/s."""
    return state.robot_velocity()


def holonomic_command(desired_velocity: np.ndarray, robot_theta: np.ndarray) -> np.ndarray:
    """World-frame desired velocities (N, 2) as the holonomic robot's commands: the same
    velocity in its frame, (vx, vy) m/s (the simulator clips the speed)."""
    c, s = np.cos(robot_theta), np.sin(robot_theta)
    x, y = desired_velocity[:, 0], desired_velocity[:, 1]
    return np.stack((c * x + s * y, -s * x + c * y), axis=-1)


def _goal_direction(state: BatchState) -> tuple[np.ndarray, np.ndarray]:
    """(N, 2) unit vectors from the robot to its goal, and (N,) the distances, m."""
    to_goal = state.goal_xy - state.robot_xy
    distance = np.linalg.norm(to_goal, axis=-1)
    unit = np.divide(
        to_goal, distance[:, None], out=np.zeros_like(to_goal), where=distance[:, None] > 0.0
    )
    return unit, distance


# --------------------------------------------------------------------------------------------
# ORCA
# --------------------------------------------------------------------------------------------


class _VelocityBaseline:
    """A baseline that picks a world-frame velocity (:meth:`desired_velocity`) and drives the
    robot towards it with :func:`unicycle_command`."""

    config: OrcaBaselineParams | SfmBaselineParams

    def desired_velocity(self, state: BatchState, params: EnvParams) -> np.ndarray:
        raise NotImplementedError

    def act(self, state: BatchState, params: EnvParams) -> np.ndarray:
        """(N, 2) commands (v m/s, ω rad/s; holonomic: (vx, vy) m/s) for every env."""
        if params.kinematics == "holonomic":
            return holonomic_command(self.desired_velocity(state, params), state.robot_theta)
        return unicycle_command(
            self.desired_velocity(state, params),
            state.robot_theta,
            max_speed=params.robot_max_speed,
            max_rotation=params.robot_max_rotation,
            dt=params.dt,
            heading_gain=self.config.heading_gain,
        )


class OrcaBaseline(_VelocityBaseline):
    """The robot as one ORCA agent among the humans (RVO2's algorithm, batched).

    Every step, per env, the robot (radius + ``safety_margin``, max speed the robot's) solves
    ORCA against the humans at their current velocities and the room's walls, with a preferred
    velocity of full speed towards its goal; only the robot's slot is computed. The new velocity
    goes through :func:`unicycle_command`.
    """

    name = "orca"

    def __init__(self, config: OrcaBaselineParams | None = None) -> None:
        self.config = config if config is not None else OrcaBaselineParams()
        self._walls: dict[float, orca.Obstacles] = {}

    def _obstacles(self, wall_half_size: float) -> orca.Obstacles:
        # Preprocessing the walls (RVO2's processObstacles) is plain Python: do it once per room.
        if wall_half_size not in self._walls:
            self._walls[wall_half_size] = orca.room_obstacles(wall_half_size)
        return self._walls[wall_half_size]

    def desired_velocity(self, state: BatchState, params: EnvParams) -> np.ndarray:
        """(N, 2) world-frame velocity ORCA picks for the robot, m/s."""
        c = self.config
        n, h = state.num_envs, state.num_humans
        goal_dir, _ = _goal_direction(state)
        cos_b, sin_b = math.cos(-c.symmetry_bias), math.sin(-c.symmetry_bias)
        preferred = params.robot_max_speed * np.stack(
            (
                cos_b * goal_dir[:, 0] - sin_b * goal_dir[:, 1],
                sin_b * goal_dir[:, 0] + cos_b * goal_dir[:, 1],
            ),
            axis=-1,
        )
        # Agent 0 is the robot, agents 1..H the humans (in RVO2's neighbour order, ties between
        # equidistant humans are then broken by human index, as in the simulator).
        position = np.concatenate((state.robot_xy[:, None], state.human_xy), axis=1)
        velocity = np.concatenate((_robot_velocity(state)[:, None], state.human_velocity()), axis=1)
        pref = velocity.copy()
        pref[:, 0] = preferred
        radius = np.empty((n, h + 1))
        radius[:, 0] = params.robot_radius + c.safety_margin
        radius[:, 1:] = params.human_radius
        max_speed = np.empty((n, h + 1))
        max_speed[:, 0] = params.robot_max_speed
        max_speed[:, 1:] = state.human_max_speed
        compute = np.zeros((n, h + 1), dtype=bool)
        compute[:, 0] = True
        orca_params = orca.OrcaParams(
            neighbor_dist=c.neighbor_dist,
            max_neighbors=int(c.max_neighbors),
            time_horizon=c.time_horizon,
            time_horizon_obst=c.time_horizon_obst,
            time_step=params.dt,
        )
        own = None
        if obstacle_map(state) is not None:  # the room's tables and plants, as the humans see them
            own = orca.EnvObstacles.from_polygons(
                polygons(state.obstacle_kind, state.obstacle_xy, state.obstacle_half),
                polygon_sizes(state.obstacle_kind),
            )
        new_velocity = orca.orca_velocities(
            position,
            velocity,
            pref,
            radius,
            max_speed,
            compute,
            self._obstacles(params.wall_half_size),
            orca_params,
            own,
        )
        return new_velocity[:, 0]


# --------------------------------------------------------------------------------------------
# Social Force Model
# --------------------------------------------------------------------------------------------


class SfmBaseline(_VelocityBaseline):
    """The robot driven by the Social Force Model, batched with numpy.

    Per env: goal attraction at full speed with relaxation time τ, exponential repulsion from
    every human (weighted by the field of view, with a "keep right" sideways share for humans
    ahead) and from the four walls; the forces change the current velocity over one step, the
    result is capped at the robot's speed and goes through :func:`unicycle_command`.
    """

    name = "sfm"

    def __init__(self, config: SfmBaselineParams | None = None) -> None:
        self.config = config if config is not None else SfmBaselineParams()

    def forces(self, state: BatchState, params: EnvParams) -> np.ndarray:
        """(N, 2) repulsion from humans and walls per unit mass (m/s²), without the goal term."""
        c = self.config
        goal_dir, _ = _goal_direction(state)
        # Humans: n_ij points from the human to the robot.
        offset = state.robot_xy[:, None, :] - state.human_xy  # (N, H, 2)
        distance = np.linalg.norm(offset, axis=-1)  # (N, H)
        away = np.divide(
            offset, distance[..., None], out=np.zeros_like(offset), where=distance[..., None] > 0
        )
        magnitude = c.human_strength * np.exp(
            (params.robot_radius + params.human_radius - distance) / c.human_range
        )
        cos_phi = -np.einsum("nhk,nk->nh", away, goal_dir)  # angle to the human vs goal direction
        weight = c.anisotropy + (1.0 - c.anisotropy) * (1.0 + cos_phi) / 2.0
        # The normal turned counter-clockwise: for a human ahead, it points to the robot's right.
        sideways = np.stack((-away[..., 1], away[..., 0]), axis=-1)
        push = away + c.side_bias * np.maximum(cos_phi, 0.0)[..., None] * sideways
        force = np.einsum("nh,nhk->nk", magnitude * weight, push)
        # Walls: the nearest point of each wall is on its inner face.
        half = params.wall_half_size
        x, y = state.robot_xy[:, 0], state.robot_xy[:, 1]

        def wall(gap: np.ndarray) -> np.ndarray:
            return c.wall_strength * np.exp((params.robot_radius - gap) / c.wall_range)

        force[:, 0] += wall(x + half) - wall(half - x)
        force[:, 1] += wall(y + half) - wall(half - y)
        # Tables and plants: pushed away from the nearest point of each, as from a wall.
        obstacles = obstacle_map(state)
        if obstacles is not None:
            nearest, gap = nearest_points(state.robot_xy, *obstacles)
            away = state.robot_xy[:, None, :] - nearest
            length = np.linalg.norm(away, axis=-1, keepdims=True)
            unit = np.divide(away, length, out=np.zeros_like(away), where=length > 0)
            force += np.einsum("no,nok->nk", np.where(np.isfinite(gap), wall(gap), 0.0), unit)
        return force

    def desired_velocity(self, state: BatchState, params: EnvParams) -> np.ndarray:
        """(N, 2) world-frame velocity the social forces lead to after one step, m/s."""
        c = self.config
        goal_dir, _ = _goal_direction(state)
        target = params.robot_max_speed * goal_dir
        velocity = _robot_velocity(state)
        relaxed = target + (velocity - target) * math.exp(-params.dt / c.relaxation_time)
        desired = relaxed + self.forces(state, params) * params.dt
        speed = np.linalg.norm(desired, axis=-1, keepdims=True)
        scale = np.minimum(1.0, params.robot_max_speed / np.maximum(speed, _MIN_SPEED))
        return desired * scale


# --------------------------------------------------------------------------------------------
# Registry
# --------------------------------------------------------------------------------------------

BASELINES: dict[str, tuple[type, type[OrcaBaselineParams] | type[SfmBaselineParams]]] = {
    "orca": (OrcaBaseline, OrcaBaselineParams),
    "sfm": (SfmBaseline, SfmBaselineParams),
}
"""Baseline name → (policy class, parameter model)."""


def make_baseline(name: str, **overrides: Any) -> BaselinePolicy:
    """The baseline ``name`` ("orca" or "sfm") with its default parameters, some overridden.

    Raises:
        ValueError: unknown name or parameter, or a bad value (one line naming it).
    """
    if name not in BASELINES:
        raise ValueError(f"unknown baseline {name!r}; expected one of {', '.join(BASELINES)}")
    policy_cls, params_cls = BASELINES[name]
    known = set(params_cls.model_fields)
    unknown = sorted(set(overrides) - known)
    if unknown:
        raise ValueError(
            f"baselines.{name}: unknown option(s) {', '.join(unknown)}; "
            f"expected some of {', '.join(sorted(known))}"
        )
    return policy_cls(params_cls(**overrides))
