"""``wm-mpc``'s model: the planning world model (:mod:`socnav_wm.worldmodel.residual`, constant
velocity plus a learned correction of each human's velocity) as a
:class:`~.models.PlanningModel`. It follows the episodes as the constant-velocity model does and
imagines with the learned correction, in float32 without gradients."""

from __future__ import annotations

import copy

import numpy as np
import torch

from socnav_wm.env.core import discrete_commands
from socnav_wm.env.params import EnvParams
from socnav_wm.planning.models import ConstantVelocityModel, Rollout
from socnav_wm.worldmodel.residual import ResidualDynamics

CHUNK_AGENTS = 4096
"""Humans (distinct futures × humans per scene) per call of the model, about: the futures are
imagined in chunks of whole episodes, whose temporaries stay in the caches (at 64 episodes of
20 humans, one call over all 12,288 futures took about 1.6 times as long per future as calls
over one or two episodes' 192; ``socnav-wm bench plan``). A chunk holds at least one episode's
futures, so an episode is imagined exactly as when it is planned alone (a matrix product of a
few rows can round otherwise than one of many)."""

MIN_ROWS = 16
"""Rows (humans) of one call of the model at least: a chunk with fewer is padded with copies
of its own futures. This torch build's matrix products take another path, which rounds
otherwise, for 1–3 rows and agree from 4 rows on; with the futures imagined once, a chunk can
be that small (one episode whose candidates all agree on their first step)."""


class _ResidualRollout:
    """The futures of a batch, each distinct one imagined once.

    Futures that have taken the same actions from the same present are the same future: the
    candidates share their first actions (``4**k`` distinct ones at step k < prefix_length out of
    every candidate), and a continuation that agrees with another (``goal`` going straight
    ahead as ``forward`` does) follows it. So the rollout keeps the distinct futures only
    (``self.points`` …, episode-major) and which one each row is (``self.row``); a step
    imagines each distinct (future, action) pair once. ``points``, ``velocity`` (N, 1 + H, 2)
    and ``pose`` (N, 3): the N episodes' presents, each the start of ``repeats`` futures.
    """

    def __init__(
        self,
        model: ResidualDynamics,
        points: np.ndarray,
        velocity: np.ndarray,
        pose: np.ndarray | None,
        table: torch.Tensor,
        repeats: int,
    ) -> None:
        self.model, self.table = model, table
        # At the start the futures are their episodes' presents: ``repeats`` rows each.
        self.row = np.repeat(np.arange(len(points)), repeats)
        self.episode = np.arange(len(points))
        self.points = torch.as_tensor(points, dtype=torch.float32)
        self.velocity = torch.as_tensor(velocity, dtype=torch.float32)
        self.pose = None if pose is None else torch.as_tensor(pose, dtype=torch.float32)
        self.imagined = 0

    def _chunks(self) -> list[slice]:
        """Runs of whole episodes of the distinct futures, about CHUNK_AGENTS humans each."""
        starts = np.flatnonzero(np.diff(self.episode, prepend=-1))
        ends = np.append(starts[1:], len(self.episode))
        chunks, first, size = [], 0, 0
        per_future = max(1, self.model.num_humans)
        for start, end in zip(starts, ends, strict=True):
            if size and size + (end - start) * per_future > CHUNK_AGENTS:
                chunks.append(slice(first, start))
                first, size = start, 0
            size += (end - start) * per_future
        if len(self.episode):
            chunks.append(slice(first, len(self.episode)))
        return chunks

    def step(self, actions: np.ndarray) -> np.ndarray:
        actions = np.asarray(actions, dtype=np.int64)
        k, self.imagined = self.imagined, self.imagined + 1
        if not len(self.row):
            return np.zeros((0, *self.points.shape[1:]))
        pairs, self.row = np.unique(self.row * len(self.table) + actions, return_inverse=True)
        parent, action = np.divmod(pairs, len(self.table))
        command = self.table[torch.as_tensor(action)]
        self.episode = self.episode[parent]
        parent = torch.as_tensor(parent)
        points, velocity = self.points[parent], self.velocity[parent]
        pose = None if self.pose is None else self.pose[parent]
        out: list[tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]] = []
        with torch.no_grad():
            for c in self._chunks():
                size = c.stop - c.start
                humans = size * max(1, self.model.num_humans)
                rows = (
                    c
                    if humans >= MIN_ROWS
                    else torch.arange(c.start, c.stop).repeat(-(-MIN_ROWS // humans))
                )
                step = self.model.step(
                    points[rows],
                    velocity[rows],
                    command[rows, 0],
                    command[rows, 1],
                    None if pose is None else pose[rows],
                    k,
                )
                out.append(tuple(None if x is None else x[:size] for x in step))
        self.points = torch.cat([o[0] for o in out])
        self.velocity = torch.cat([o[1] for o in out])
        self.pose = None if pose is None else torch.cat([o[2] for o in out])
        return self.points.numpy()[self.row].astype(np.float64)

    def velocities(self) -> np.ndarray:
        return self.velocity.numpy()[self.row].astype(np.float64)


class ResidualPlanningModel(ConstantVelocityModel):
    """A :class:`~socnav_wm.planning.models.PlanningModel` that follows the episodes as the
    constant-velocity one does and imagines with the learned correction (float32). A model
    that knows the room imagines from the robot's room pose, which the planner passes
    (``planning.walls``)."""

    def __init__(self, model: ResidualDynamics, params: EnvParams) -> None:
        super().__init__(params)
        self.net = copy.deepcopy(model).float().eval()
        self.table = torch.as_tensor(discrete_commands(params), dtype=torch.float32)

    def rollout(
        self, repeats: int, pose: np.ndarray | None = None, rows: np.ndarray | None = None
    ) -> Rollout:
        chosen = slice(None) if rows is None else rows
        if self.net.room_half is not None and pose is None:
            raise ValueError(
                "wm-mpc: its planning model knows the room and needs the robot's pose "
                "(set planning.walls: true)"
            )
        return _ResidualRollout(
            self.net,
            self._points[chosen],
            self._velocity[chosen],
            None if pose is None else np.asarray(pose),
            self.table,
            repeats,
        )
