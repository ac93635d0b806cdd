"""One recorded episode (what :func:`socnav_wm.env.rollout.run_episodes` returns, and what the
evaluation's trajectory files hold): plain arrays, readable without the simulator."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Episode"]


@dataclass(frozen=True)
class Episode:
    """One recorded episode; index ``t`` of the ``(T+1, …)`` arrays is the state after step t."""

    scenario_id: int
    robot_xy: np.ndarray  # (T+1, 2) m
    robot_theta: np.ndarray  # (T+1,) rad
    goal_xy: np.ndarray  # (2,) m
    human_xy: np.ndarray  # (T+1, H, 2) m
    human_theta: np.ndarray  # (T+1, H) rad
    actions: np.ndarray  # (T,) or (T, 2): what the policy returned
    rewards: np.ndarray  # (T,)
    dmin: np.ndarray  # (T,) m
    success: bool
    collision: str | None  # "human", "wall", "obstacle" or None
    truncated: bool
    commands: np.ndarray | None = None
    """(T, 2) the (v m/s, ω rad/s) the robot executed at each step (discrete actions looked
    up, continuous commands clipped to the robot's limits); None when not recorded."""
    human_group: np.ndarray | None = None
    """(H,) each human's group (−1: alone); None when not recorded."""
    obstacle_kind: np.ndarray | None = None
    """(O,) int8 the scenario's static obstacle slots: ``OBSTACLE_NONE`` (empty slot),
    ``OBSTACLE_TABLE`` or ``OBSTACLE_PLANT`` (socnav_wm.env.state); None when the scenario has no
    obstacles (the paper's) or they were not recorded."""
    obstacle_xy: np.ndarray | None = None
    """(O, 2) the obstacles' centres (m); None with ``obstacle_kind``."""
    obstacle_half: np.ndarray | None = None
    """(O, 2) a table's half width and depth, a plant's (r, r) (m); None with
    ``obstacle_kind``."""

    @property
    def num_steps(self) -> int:
        return int(self.rewards.shape[0])
