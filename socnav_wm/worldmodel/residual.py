"""The planning world model: constant velocity with the robot's own motion exact, plus a learned
correction of each human's velocity.

What a planner needs predicted is where the goal and the humans will be, in metres. The robot
knows its own kinematics (:mod:`socnav_wm.worldmodel.ego`): the goal's motion in the robot frame
is pure kinematics, and so is the part of every human's apparent motion that the robot causes.
What is unknown is how the humans move in the world. This model keeps each human's last world
velocity (the constant-velocity baseline) and learns only its change at each step::

    u_h ← cap(u_h + f(features_h))     (the human's velocity per step, robot frame)
    p, u ← advance(p, u, v, ω)         (exact: the human moves by u_h, the robot by (v, ω))

where ``cap`` scales a velocity above the humans' top speed back to it, as the simulator does.

``f`` is one small MLP shared by every human. Its features are seen from the human: the human's
own speed, and the position and velocity, relative to it, of every other human and of the
robot (whose velocity follows from the action it executes), all rotated into the frame of the
human's heading of motion, so one turn of the scene is one turn of the answer. Its last layer
starts at zero: an untrained model *is* the constant-velocity baseline. It is trained through
open-loop rollouts of ``horizon`` steps (:mod:`socnav_wm.worldmodel.residual_training`), on the
random-policy rollouts of ``collect``. There is no lossy bottleneck: positions in, positions out.

This module is the model and its open-loop predictions, all that a planner or ``predict``
executes; the training samples and the training loop live in
:mod:`socnav_wm.worldmodel.residual_training`, so a change there reruns the trainings only.
"""

from __future__ import annotations

import copy

import numpy as np
import torch
from torch import nn

from socnav_wm.env.core import discrete_commands
from socnav_wm.env.params import EnvParams
from socnav_wm.worldmodel.ego import human_velocities, positions


def _rotate(x: torch.Tensor, c: torch.Tensor, s: torch.Tensor) -> torch.Tensor:
    """Vectors (..., 2) turned by −φ, where ``c, s = cos φ, sin φ`` (shape ``...``)."""
    return torch.stack([c * x[..., 0] + s * x[..., 1], -s * x[..., 0] + c * x[..., 1]], dim=-1)


def _unrotate(x: torch.Tensor, c: torch.Tensor, s: torch.Tensor) -> torch.Tensor:
    """Vectors (..., 2) turned by +φ."""
    return torch.stack([c * x[..., 0] - s * x[..., 1], s * x[..., 0] + c * x[..., 1]], dim=-1)


def _off_diagonal(x: torch.Tensor) -> torch.Tensor:
    """(B, H, H + 1, 2) → (B, H, H, 2) without the entries (i, i). In the flattened (H, H + 1)
    block, row i's H + 1 entries after its own lie between two diagonal ones, so slices of one
    view pick them (a boolean mask would find them anew at every call, several times slower);
    the gradient flows back through the same copies, bit for bit as through the mask."""
    b, h = x.shape[0], x.shape[1]
    if h < 2:
        return x[:, :, 1:]
    flat = x.reshape(b, h * (h + 1), 2)[:, 1:]
    body = flat[:, : (h - 1) * (h + 2)].reshape(b, h - 1, h + 2, 2)[:, :, : h + 1]
    return torch.cat([body.reshape(b, -1, 2), flat[:, -1:]], dim=1).reshape(b, h, h, 2)


def ego_advance(
    points: torch.Tensor, velocity: torch.Tensor, v: torch.Tensor, omega: torch.Tensor, dt: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`socnav_wm.worldmodel.ego.advance` in torch (differentiable): points (B, P, 2) move
    by ``velocity`` (B, P, 2), then the robot executes ``(v, ω)`` (B,); the new robot-frame
    points and velocities."""
    angle = (omega * dt)[:, None]
    c, s = torch.cos(angle), torch.sin(angle)
    moved = _rotate(points + velocity, c, s)
    shift = torch.zeros_like(moved)
    shift[..., 0] = (v * dt)[:, None]
    return moved - shift, _rotate(velocity, c, s)


def ego_advance_holonomic(
    points: torch.Tensor, velocity: torch.Tensor, vx: torch.Tensor, vy: torch.Tensor, dt: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`ego_advance` for the holonomic robot, which translates by ``(vx, vy)·dt`` in its
    frame and never turns: the points move by ``velocity``, then by minus the robot's step; the
    velocities stay as they are."""
    step = torch.stack([vx * dt, vy * dt], dim=-1)[:, None, :]
    return points + velocity - step, velocity


ROOM_FEATURES = 5
"""Per human, for a model that knows the room: the room's centre seen from the human (in the
frame of its heading, over the half-size of the area where goals are drawn), the distance ahead
to that area's edge along its heading (over the half-size), and its heading in the room (cos,
sin)."""

IMAGINED_UNIT = 0.1
"""The steps-imagined feature is ``IMAGINED_UNIT × k`` (about 1 at the planner's horizon)."""

CORRECTION_UNIT = 0.01
"""The MLP's output unit (m per step). The corrections that matter are millimetres to a few
centimetres per step; in metres, Adam's first steps (learning rate 1e-3) moved every human by
centimetres per step, and every training ended back at constant velocity (best epoch 0)."""


def advance_pose(
    pose: torch.Tensor, v: torch.Tensor, omega: torch.Tensor, dt: float
) -> torch.Tensor:
    """The robot's room pose (B, 3: x, y, θ) after it executes ``(v, ω)`` (B,): a turn by
    ``ω·dt``, then a step of ``v·dt`` along the new heading: the torch twin of
    :func:`socnav_wm.worldmodel.ego.advance_pose`, for the model's differentiable rollouts."""
    theta = pose[:, 2] + omega * dt
    step = v * dt
    x = pose[:, 0] + step * torch.cos(theta)
    y = pose[:, 1] + step * torch.sin(theta)
    return torch.stack([x, y, theta], dim=-1)


def advance_pose_holonomic(
    pose: torch.Tensor, vx: torch.Tensor, vy: torch.Tensor, dt: float
) -> torch.Tensor:
    """The holonomic robot's room pose (B, 3) after a step of ``(vx, vy)·dt`` in its frame, its
    heading unchanged: the torch twin of :func:`socnav_wm.worldmodel.ego.advance_pose`."""
    c, s = torch.cos(pose[:, 2]), torch.sin(pose[:, 2])
    x = pose[:, 0] + (vx * c - vy * s) * dt
    y = pose[:, 1] + (vx * s + vy * c) * dt
    return torch.stack([x, y, pose[:, 2]], dim=-1)


def room_features(
    points: torch.Tensor, velocity: torch.Tensor, pose: torch.Tensor, half: float
) -> torch.Tensor:
    """:data:`ROOM_FEATURES` (B, H, 5) of the humans at robot-frame ``points`` and ``velocity``
    (B, 1 + H, 2), seen by a robot at room pose ``pose`` (B, 3), in a room whose goals are
    drawn in ``[−half, half]²``. A person walks straight to its goal and draws a new one there,
    so the distance to that area's edge bounds how far it can still walk straight."""
    c, s = torch.cos(pose[:, 2])[:, None], torch.sin(pose[:, 2])[:, None]
    where = _unrotate(points[:, 1:], c, s) + pose[:, None, :2]  # (B, H, 2) in the room
    hc, hs = heading_of(_unrotate(velocity[:, 1:], c, s))
    heading = torch.stack([hc, hs], dim=-1)
    safe = torch.where(heading.abs() > 1e-9, heading, torch.full_like(heading, 1e-9))
    to_edge = (torch.where(safe > 0, half, -half) - where) / safe
    ahead = torch.clamp(to_edge.min(dim=-1).values, 0.0, 2.0 * half)
    centre = _rotate(-where, hc, hs)
    return torch.cat([centre / half, (ahead / half)[..., None], heading], dim=-1)


def heading_of(velocity: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """cos, sin (...) of the direction of ``velocity`` (..., 2), the frame a human's features
    are seen in; (1, 0) below 1 cm per step (a person standing, or the float32 noise of the
    observations). The frame is a choice of coordinates, so no gradient flows through it: the
    direction of a near-zero velocity would turn its gradient into noise of order 1/speed."""
    u = velocity.detach()
    speed = torch.linalg.vector_norm(u, dim=-1)
    moving = speed > 0.01
    safe = torch.where(moving, speed, torch.ones_like(speed))
    c = torch.where(moving, u[..., 0] / safe, torch.ones_like(speed))
    s = torch.where(moving, u[..., 1] / safe, torch.zeros_like(speed))
    return c, s


class ResidualDynamics(nn.Module):
    """``f``: each human's change of velocity per step (B, H, 2) from the positions (B, 1 + H, 2)
    and velocities (B, 1 + H, 2) of the goal and the humans, and the robot's command (B,) ×2:
    a row of the env's command table (:func:`socnav_wm.env.core.discrete_commands`), ``(v, ω)``
    for the unicycle, ``(vx, vy)`` in the robot's frame for a holonomic model (the methods name
    the two ``v`` and ``omega`` after the unicycle's).

    Args:
        num_humans: humans in the scene.
        hidden_dim: width of the MLP's two hidden layers.
        dt: the step (s), to turn the robot's command into its displacement per step.
        max_speed: the humans' top speed (m/s): a corrected velocity longer than it is scaled
            back to it, as the simulator caps theirs (None: no cap).
        room_half: the half-size (m) of the square where the humans' goals are drawn, for a
            model that knows the room (:func:`room_features`; every call then needs the
            robot's room pose), or None.
        neighbours: how many other humans each human sees, nearest first (the K nearest, in
            slots by distance, as social pooling does), or None: every other human in spawn
            order (the paper preset's models). The robot always has its own slot.
        holonomic: the robot translates by its command ``(vx, vy)`` and never turns
            (CrowdNav's robot); its turn feature is then always 0.
    """

    def __init__(
        self,
        num_humans: int,
        hidden_dim: int,
        dt: float,
        max_speed: float | None = None,
        room_half: float | None = None,
        neighbours: int | None = None,
        holonomic: bool = False,
    ) -> None:
        super().__init__()
        self.num_humans, self.dt, self.max_speed = num_humans, dt, max_speed
        self.holonomic = bool(holonomic)
        self.room_half = room_half
        if neighbours is not None and neighbours < 1:
            raise ValueError(f"neighbours: expected at least 1 (or None), got {neighbours}")
        self.neighbours = neighbours
        seen = num_humans - 1 if neighbours is None else min(neighbours, num_humans - 1)
        self.seen = max(seen, 0)
        # Own speed, then (relative position, relative velocity) of each other human seen and
        # of the robot, the robot's turn per step and the steps imagined so far; with the room,
        # its ROOM_FEATURES.
        inputs = 1 + 4 * (self.seen + 1) + 2 + (0 if room_half is None else ROOM_FEATURES)
        self.net = nn.Sequential(
            nn.Linear(inputs, hidden_dim),
            nn.Tanh(),
            nn.Linear(hidden_dim, hidden_dim),
            nn.Tanh(),
            nn.Linear(hidden_dim, 2),
        )
        nn.init.zeros_(self.net[-1].weight)
        nn.init.zeros_(self.net[-1].bias)

    def features(
        self,
        points: torch.Tensor,
        velocity: torch.Tensor,
        v: torch.Tensor,
        omega: torch.Tensor,
        pose: torch.Tensor | None = None,
        imagined: int = 0,
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(B, H, inputs) features seen from each human, and the cos, sin (B, H) of the
        heading of its motion (its frame); ``pose`` (B, 3): the robot's in the room;
        ``imagined``: the steps predicted since the last real observation (a person's next
        step is nearly certain, its tenth is not: the median of where it will be changes
        with the lead time, and a model without it has one answer for both)."""
        h = self.num_humans
        p, u = points[:, 1:], velocity[:, 1:]  # (B, H, 2)
        speed = torch.linalg.vector_norm(u, dim=-1)
        c, s = heading_of(u)
        robot_p = torch.zeros_like(p[:, :1])
        robot_u = torch.zeros_like(u[:, :1])
        robot_u[..., 0] = (v * self.dt)[:, None]
        if self.holonomic:  # the command is the robot's velocity (vx, vy); it never turns
            robot_u[..., 1] = (omega * self.dt)[:, None]
        others_p = torch.cat([p, robot_p], dim=1)  # (B, H + 1, 2)
        others_u = torch.cat([u, robot_u], dim=1)
        rel_p = others_p[:, None, :, :] - p[:, :, None, :]  # (B, H, H + 1, 2)
        rel_u = others_u[:, None, :, :] - u[:, :, None, :]
        # Drop each human's own entry: the others in spawn order, then the robot.
        rel_p, rel_u = _off_diagonal(rel_p), _off_diagonal(rel_u)
        if self.neighbours is not None:  # the K nearest others, nearest first; then the robot
            distance = torch.linalg.vector_norm(rel_p[:, :, : h - 1].detach(), dim=-1)
            order = torch.argsort(distance, dim=-1, stable=True)[..., : self.seen]
            index = order[..., None].expand(-1, -1, -1, 2)
            rel_p = torch.cat([rel_p[:, :, : h - 1].gather(2, index), rel_p[:, :, h - 1 :]], 2)
            rel_u = torch.cat([rel_u[:, :, : h - 1].gather(2, index), rel_u[:, :, h - 1 :]], 2)
        cs, ss = c[..., None], s[..., None]
        rel = torch.cat([_rotate(rel_p, cs, ss), _rotate(rel_u, cs, ss)], dim=-1)
        turn = (
            torch.zeros_like(speed[..., None])
            if self.holonomic
            else (omega * self.dt)[:, None, None].expand(-1, h, 1)
        )
        lead = torch.full_like(speed[..., None], IMAGINED_UNIT * imagined)
        parts = [speed[..., None], rel.reshape(*rel.shape[:2], -1), turn, lead]
        if self.room_half is not None:
            if pose is None:
                raise ValueError(
                    "this planning model knows the room: it needs the robot's room pose"
                )
            parts.append(room_features(points, velocity, pose, self.room_half))
        return torch.cat(parts, dim=-1), c, s

    def forward(
        self,
        points: torch.Tensor,
        velocity: torch.Tensor,
        v: torch.Tensor,
        omega: torch.Tensor,
        pose: torch.Tensor | None = None,
        imagined: int = 0,
    ) -> torch.Tensor:
        x, c, s = self.features(points, velocity, v, omega, pose, imagined)
        return _unrotate(CORRECTION_UNIT * self.net(x), c, s)

    def step(
        self,
        points: torch.Tensor,
        velocity: torch.Tensor,
        v: torch.Tensor,
        omega: torch.Tensor,
        pose: torch.Tensor | None = None,
        imagined: int = 0,
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """One predicted step, the ``imagined``-th since the last observation: the corrected
        velocities, then the exact motion; the new points, velocities and robot pose (None
        without one)."""
        humans = velocity[:, 1:] + self(points, velocity, v, omega, pose, imagined)
        if self.max_speed is not None:
            limit = self.max_speed * self.dt
            length = torch.linalg.vector_norm(humans, dim=-1, keepdim=True)
            humans = humans * torch.clamp(limit / length.clamp(min=1e-12), max=1.0)
        velocity = torch.cat([velocity[:, :1], humans], dim=1)
        if self.holonomic:
            points, velocity = ego_advance_holonomic(points, velocity, v, omega, self.dt)
            if pose is not None:
                pose = advance_pose_holonomic(pose, v, omega, self.dt)
            return points, velocity, pose
        points, velocity = ego_advance(points, velocity, v, omega, self.dt)
        if pose is not None:
            pose = advance_pose(pose, v, omega, self.dt)
        return points, velocity, pose

    def rollout(
        self,
        points: torch.Tensor,
        velocity: torch.Tensor,
        v: torch.Tensor,
        omega: torch.Tensor,
        pose: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Open-loop positions (B, K, 1 + H, 2) under the commands ``v, ω`` (B, K), from the
        robot's room pose ``pose`` (B, 3) for a model that knows the room."""
        out = []
        for k in range(v.shape[1]):
            points, velocity, pose = self.step(points, velocity, v[:, k], omega[:, k], pose, k)
            out.append(points)
        return torch.stack(out, dim=1)


def present_state(
    previous_obs: np.ndarray, obs: np.ndarray, previous_action: np.ndarray, env_params: EnvParams
) -> tuple[np.ndarray, np.ndarray]:
    """Where a rollout starts: the present positions and constant velocities (B, 1 + H, 2),
    float64, from the observation ``obs`` after ``previous_obs`` and ``previous_action``."""
    return positions(obs), human_velocities(previous_obs, obs, previous_action, env_params)


def residual_positions(
    model: ResidualDynamics,
    previous_obs: np.ndarray,
    obs: np.ndarray,
    previous_action: np.ndarray,
    future_actions: np.ndarray,
    env_params: EnvParams,
    batch_size: int = 512,
    pose: np.ndarray | None = None,
) -> np.ndarray:
    """Open-loop positions (B, K, 1 + H, 2), as
    :func:`socnav_wm.worldmodel.ego.predict_positions`, in float64 (so they do not depend on
    ``batch_size``); ``pose`` (B, 3): the robot's room pose at ``obs``, which a model that
    knows the room needs."""
    net = copy.deepcopy(model).double().eval()
    points, velocity = present_state(previous_obs, obs, previous_action, env_params)
    table = torch.as_tensor(discrete_commands(env_params), dtype=torch.float64)
    actions = torch.as_tensor(np.asarray(future_actions, dtype=np.int64))
    poses = None if pose is None else torch.as_tensor(np.asarray(pose, dtype=np.float64))
    out = np.empty((len(obs), actions.shape[1], *points.shape[1:]))
    with torch.no_grad():
        for i in range(0, len(obs), batch_size):
            rows = slice(i, i + batch_size)
            out[rows] = net.rollout(
                torch.from_numpy(points[rows]),
                torch.from_numpy(velocity[rows]),
                table[actions[rows], 0],
                table[actions[rows], 1],
                None if poses is None else poses[rows],
            ).numpy()
    return out
