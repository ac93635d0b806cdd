"""The planning model in the form MLflow serves (see :mod:`socnav_wm.worldmodel.served`)."""

from __future__ import annotations

import torch
from torch import nn

from socnav_wm.worldmodel.residual import ResidualDynamics


class ServedPlanningModel(nn.Module):
    """The planning model's correction of each human's velocity for one step, from one row per
    scene: the goal's and the humans' positions ((1 + H) × 2), their velocities ((1 + H) × 2),
    the robot's command (v and ω; vx and vy for a holonomic model), and for a model that knows
    the room the robot's pose (x, y, θ); all in the robot's frame as
    :meth:`ResidualDynamics.forward` takes them → (batch, H, 2).
    """

    def __init__(self, model: ResidualDynamics) -> None:
        super().__init__()
        self.model = model

    @property
    def input_dim(self) -> int:
        """The width of one row."""
        return 4 * (1 + self.model.num_humans) + 2 + (0 if self.model.room_half is None else 3)

    def forward(self, rows: torch.Tensor) -> torch.Tensor:
        n = 1 + self.model.num_humans
        points = rows[:, : 2 * n].reshape(-1, n, 2)
        velocity = rows[:, 2 * n : 4 * n].reshape(-1, n, 2)
        v, omega = rows[:, 4 * n], rows[:, 4 * n + 1]
        pose = rows[:, 4 * n + 2 : 4 * n + 5] if self.model.room_half is not None else None
        return self.model(points, velocity, v, omega, pose)
