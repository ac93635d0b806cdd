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
"""Humans (futures × humans per scene) per call of the model, about: the futures are imagined
in chunks of whole episodes, whose temporaries stay in the caches (at 64 episodes of 20
humans, one call over all 12,288 futures took about 1.6 times as long per future as calls over
one or two episodes' 192; ``socnav-wm bench plan``). A chunk holds at least one episode's
futures, so an episode is imagined exactly as when it is planned alone (a matrix product of a
few rows can round otherwise than one of many)."""


class _ResidualRollout:
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
        episodes = max(1, CHUNK_AGENTS // max(1, repeats * model.num_humans))
        size = episodes * max(1, repeats)
        self.chunks = [slice(i, i + size) for i in range(0, max(len(points), 1), size)]
        self.points = [torch.as_tensor(points[c], dtype=torch.float32) for c in self.chunks]
        self.velocity = [torch.as_tensor(velocity[c], dtype=torch.float32) for c in self.chunks]
        self.pose = [
            None if pose is None else torch.as_tensor(pose[c], dtype=torch.float32)
            for c in self.chunks
        ]
        self.imagined = 0

    def step(self, actions: np.ndarray) -> np.ndarray:
        a = torch.as_tensor(np.asarray(actions, dtype=np.int64))
        with torch.no_grad():
            for i, c in enumerate(self.chunks):
                self.points[i], self.velocity[i], self.pose[i] = self.model.step(
                    self.points[i],
                    self.velocity[i],
                    self.table[a[c], 0],
                    self.table[a[c], 1],
                    self.pose[i],
                    self.imagined,
                )
        self.imagined += 1
        return torch.cat(self.points).numpy().astype(np.float64)

    def velocities(self) -> np.ndarray:
        return torch.cat(self.velocity).numpy().astype(np.float64)


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
            np.repeat(self._points[chosen], repeats, axis=0),
            np.repeat(self._velocity[chosen], repeats, axis=0),
            None if pose is None else np.repeat(np.asarray(pose), repeats, axis=0),
            self.table,
            repeats,
        )
