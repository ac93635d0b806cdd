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
open-loop rollouts of ``horizon`` steps (the loss averages every step's Euclidean position
error, as PlaNet's overshooting and TD-MPC's latent rollouts do), on the random-policy rollouts
of ``collect``. There is no lossy bottleneck: positions in, positions out.
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import nn

from socnav_wm.data.compatibility import made_with
from socnav_wm.env.core import discrete_commands
from socnav_wm.env.params import EnvParams
from socnav_wm.resources import build_trainable
from socnav_wm.worldmodel.ego import human_velocities, positions
from socnav_wm.worldmodel.fitting import EpochCallback, Fit, fit
from socnav_wm.worldmodel.params import PlanningModelParams


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


@dataclass(frozen=True)
class Sequences:
    """Training samples: the present (``obs`` after ``previous_obs`` and ``previous_action``),
    the next ``horizon`` actions and the observed positions after each (``mask``: the step
    was inside the episode)."""

    previous_obs: np.ndarray  # (N, D)
    obs: np.ndarray  # (N, D)
    previous_action: np.ndarray  # (N,)
    actions: np.ndarray  # (N, K)
    targets: np.ndarray  # (N, K, 1 + H, 2)
    mask: np.ndarray  # (N, K) bool
    pose: np.ndarray | None = None  # (N, 3) the robot's room pose at ``obs``, when known

    def __len__(self) -> int:
        return len(self.obs)


def make_sequences(
    obs: np.ndarray,
    actions: np.ndarray,
    episode_ids: np.ndarray,
    next_obs: np.ndarray,
    horizon: int,
    stride: int,
    pose_after: np.ndarray | None = None,
) -> Sequences:
    """Samples from rollout rows (in episode order): one every ``stride`` steps of an episode,
    from its second step on (a velocity needs two views), each followed up to ``horizon``
    steps or the episode's end. ``pose_after`` (rows, 3): the robot's room pose after each
    row's step (collect's ``robot_x``, ``robot_y``, ``robot_theta``); a sample's present pose
    is the one after the step before it."""
    from socnav_wm.data.windows import _episode_runs

    starts, lengths = _episode_runs(np.asarray(episode_ids))
    # Each episode's observations o_0 … o_n: its rows' obs, then its last next_obs.
    full_start = starts + np.arange(len(starts))
    full = np.empty((len(obs) + len(starts), obs.shape[1]), dtype=np.float64)
    row_pos = np.arange(len(obs)) + np.repeat(np.arange(len(starts)), lengths)
    full[row_pos] = obs
    full[full_start + lengths] = next_obs[starts + lengths - 1]
    full_actions = np.zeros(len(full), dtype=np.int64)
    full_actions[row_pos] = actions
    episode_of, t = [], []
    for e, n in enumerate(lengths):
        ts = np.arange(1, n, stride)
        episode_of.append(np.full(len(ts), e))
        t.append(ts)
    episode = np.concatenate(episode_of) if episode_of else np.zeros(0, dtype=np.int64)
    step = np.concatenate(t) if t else np.zeros(0, dtype=np.int64)
    base = full_start[episode] + step  # index of o_t
    k = np.arange(horizon)
    mask = step[:, None] + k[None, :] < lengths[episode][:, None]
    ahead = np.minimum(base[:, None] + k[None, :], (full_start + lengths)[episode][:, None] - 1)
    return Sequences(
        previous_obs=full[base - 1],
        obs=full[base],
        previous_action=full_actions[base - 1],
        actions=np.where(mask, full_actions[ahead], 0),
        targets=positions(full[ahead + 1]),
        mask=mask,
        # Row starts[e] + t holds o_t; the row before it, the pose that o_t was seen from.
        pose=None
        if pose_after is None
        else np.asarray(pose_after, dtype=np.float64)[starts[episode] + step - 1],
    )


def _start(
    seq_prev: np.ndarray, seq_obs: np.ndarray, prev_action: np.ndarray, env_params: EnvParams
) -> tuple[np.ndarray, np.ndarray]:
    """Present positions and constant velocities (B, 1 + H, 2), float64."""
    return positions(seq_obs), human_velocities(seq_prev, seq_obs, prev_action, env_params)


def _step_errors(
    predicted: torch.Tensor, target: torch.Tensor, humans: torch.Tensor | None = None
) -> torch.Tensor:
    """(B, K) the humans' mean Euclidean position error (m) at each step; ``humans`` (B, H):
    each human's weight in the mean (None: alike)."""
    squared = ((predicted[:, :, 1:] - target[:, :, 1:]) ** 2).sum(-1)
    error = torch.sqrt(squared + 1e-12)
    if humans is None:
        return error.mean(-1)
    return (error * humans[:, None]).sum(-1) / humans.sum(-1, keepdim=True)


def _masked_loss(
    predicted: torch.Tensor,
    target: torch.Tensor,
    mask: torch.Tensor,
    weights: torch.Tensor | None = None,
    humans: torch.Tensor | None = None,
) -> torch.Tensor:
    """Mean Euclidean position error (m) of the humans over the real steps: the metric itself
    (a squared error rewards hedging, slowing every human down towards the mean turn, which
    raises the typical error of the many who walk straight); ``weights`` (K,): each step's
    weight; ``humans`` (B, H): each human's."""
    error = _step_errors(predicted, target, humans)
    if weights is not None:
        error = error * weights
    return (error * mask).sum() / mask.sum().clamp(min=1)


@dataclass
class ResidualTrainResult:
    model: ResidualDynamics
    history: list[dict[str, float]]
    metrics: dict[str, float]
    env: dict[str, Any] | None = None
    """The scenarios it was trained for (:func:`socnav_wm.data.compatibility.made_with`)."""


def train_residual(
    train: Sequences,
    val: Sequences,
    env_params: EnvParams,
    params: PlanningModelParams,
    *,
    seed: int,
    on_epoch: EpochCallback | None = None,
) -> ResidualTrainResult:
    """Adam on the open-loop rollout loss, its learning rate decayed to zero over
    ``max_epochs`` (cosine); the weights of the best validation epoch are kept (the untrained
    model, constant velocity, is epoch 0). ``params.room``: the model knows the room (the
    samples must carry the robot's poses). ``params.relative_weight`` ``p``: step ``k``'s error
    is weighted by ``1 / e_k^p`` (normalised to a mean of 1), where ``e_k`` is constant
    velocity's mean error at ``k`` on the training samples: with 0 the long steps' errors, 100×
    the first ones', decide alone; with 1 every step counts relative to constant velocity.
    Validation uses the plain mean (the metric). ``horizon``, ``stride`` and ``val_fraction``
    are the caller's (the samples are already made)."""
    room, relative_weight = params.room, params.relative_weight
    torch.manual_seed(seed)
    model = build_trainable(
        "planning_model.hidden_dim",
        f"the planning model (hidden_dim {params.hidden_dim})",
        lambda: ResidualDynamics(
            env_params.num_humans,
            params.hidden_dim,
            env_params.dt,
            env_params.human_max_speed,
            env_params.spawn_half_size if room else None,
            params.neighbours,
            env_params.kinematics == "holonomic",
        ),
    )
    if room and (train.pose is None or val.pose is None):
        raise ValueError("planning_model.room: the training samples carry no robot poses")
    table = torch.as_tensor(discrete_commands(env_params))

    def tensors(seqs: Sequences) -> tuple[torch.Tensor, ...]:
        points, velocity = _start(seqs.previous_obs, seqs.obs, seqs.previous_action, env_params)
        actions = torch.as_tensor(seqs.actions)
        return (
            torch.as_tensor(points, dtype=torch.float32),
            torch.as_tensor(velocity, dtype=torch.float32),
            table[actions, 0].float(),
            table[actions, 1].float(),
            torch.as_tensor(seqs.targets, dtype=torch.float32),
            torch.as_tensor(seqs.mask, dtype=torch.float32),
            # A model that does not know the room ignores the pose (zeros when none was recorded).
            torch.as_tensor(
                np.zeros((len(seqs), 3)) if seqs.pose is None else seqs.pose, dtype=torch.float32
            ),
        )

    train_t, val_t = tensors(train), tensors(val)

    def validation_loss() -> float:
        model.eval()
        total, weight = 0.0, 0.0
        with torch.no_grad():
            for i in range(0, len(val), 4096):
                p, u, v, w, y, m, pose = (x[i : i + 4096] for x in val_t)
                predicted = model.rollout(p, u, v, w, pose)
                total += float(_masked_loss(predicted, y, m)) * float(m.sum())
                weight += float(m.sum())
        return total / max(weight, 1.0)

    weights = None
    if relative_weight:
        with torch.no_grad():
            p, u, v, w, y, m, pose = (x[:20_000] for x in train_t)
            error = _step_errors(model.rollout(p, u, v, w, pose), y)
            per_step = (error * m).sum(0) / m.sum(0).clamp(min=1)
        weights = per_step.clamp(min=1e-6) ** -relative_weight
        weights = weights / weights.mean()

    near = None
    if params.near_robot_weight:
        # In the robot's frame: a human's distance from the robot is its position's length.
        distance = torch.linalg.vector_norm(train_t[0][:, 1:], dim=-1)  # (N, H)
        near = 1.0 + params.near_robot_weight * (distance <= params.near_robot_distance)

    def batch_loss(rows: torch.Tensor) -> tuple[torch.Tensor, float]:
        p, u, v, w, y, m, pose = (x[rows] for x in train_t)
        humans = None if near is None else near[rows]
        return _masked_loss(model.rollout(p, u, v, w, pose), y, m, weights, humans), 1.0

    optimizer = torch.optim.Adam(model.parameters(), lr=params.learning_rate)
    updates = params.max_epochs * -(-len(train) // params.batch_size)
    task = Fit(
        name="planning model",
        model=model,
        optimizer=optimizer,
        rows=len(train),
        batch_size=params.batch_size,
        generator=torch.Generator().manual_seed(seed),
        device=torch.device("cpu"),
        batch_loss=batch_loss,
        validate=lambda: {"val_loss": validation_loss()},
        max_grad_norm=1.0,
        scheduler=torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, T_max=updates),
        train_loss=lambda losses, _: float(np.mean(losses)),
        validate_untrained=True,
    )

    def report(epoch: int, row: dict[str, float]) -> None:
        if on_epoch is not None:
            on_epoch(epoch, {"train_loss": row["train_loss"], "val_loss": row["val_loss"]})

    start = time.process_time()
    fitted = fit(task, max_epochs=params.max_epochs, patience=params.patience, on_epoch=report)
    history = [
        {"epoch": int(row["epoch"]), "train_loss": row["train_loss"], "val_loss": row["val_loss"]}
        for row in fitted.history
    ]
    metrics = {
        "best_epoch": fitted.best_epoch,
        "val_loss": fitted.best_loss,
        "val_loss_constant_velocity": history[0]["val_loss"],
        "epochs": len(history) - 1,
        "train_samples": len(train),
        "cpu_seconds": time.process_time() - start,
    }
    return ResidualTrainResult(
        model=model, history=history, metrics=metrics, env=made_with(env_params)
    )


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
    points, velocity = _start(previous_obs, obs, previous_action, env_params)
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


def fit_residual(
    rollouts: Any,
    env_params: EnvParams,
    params: PlanningModelParams,
    *,
    seed: int,
    on_epoch: EpochCallback | None = None,
) -> ResidualTrainResult:
    """Train on the rollouts' training episodes, validate on the held-out ones (split as the
    VAE's and the LSTM's, by episode with ``seed`` and ``params.val_fraction``); the rollouts
    must have been collected in the scenarios of ``env_params``. Saved by
    :func:`socnav_wm.worldmodel.planning_file.save_residual`."""
    from socnav_wm.data.shards import column_to_numpy, read_rollouts
    from socnav_wm.data.windows import split_episodes

    horizon, stride = params.horizon, params.stride
    for name, value in (("horizon", horizon), ("stride", stride)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"{name}: expected an integer >= 1, got {value!r}")
    poses = ["robot_x", "robot_y", "robot_theta"]
    columns = ["episode_id", "obs", "action", "next_obs", *poses]
    table = read_rollouts(rollouts, columns=columns, env_params=env_params)
    ids = column_to_numpy(table, "episode_id")
    obs = column_to_numpy(table, "obs")
    actions = column_to_numpy(table, "action").astype(np.int64)
    next_obs = column_to_numpy(table, "next_obs")
    pose_after = np.stack([column_to_numpy(table, name) for name in poses], axis=-1)
    train, val = split_episodes(ids, params.val_fraction, seed)

    def sequences(rows: np.ndarray) -> Sequences:
        return make_sequences(
            obs[rows], actions[rows], ids[rows], next_obs[rows], horizon, stride, pose_after[rows]
        )

    return train_residual(
        sequences(train), sequences(val), env_params, params, seed=seed, on_epoch=on_epoch
    )
