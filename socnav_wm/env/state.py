"""The simulator's state: plain arrays with a leading ``num_envs`` axis.

Headings of humans are stored as unit vectors rather than angles: every consumer (forces,
observation, dmin) needs cos and sin, and computing them once per move instead of in every
kernel is a large part of the simulator's speed.

A single environment is a batch of one; nothing in the simulator holds per-env Python objects.
World frame: origin at the room centre, x right, y up, angles counter-clockwise from +x.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

COLLISION_NONE = 0
COLLISION_HUMAN = 1
COLLISION_WALL = 2
COLLISION_OBSTACLE = 3
COLLISION_NAMES = ("none", "human", "wall", "obstacle")

OBSTACLE_NONE = 0
OBSTACLE_TABLE = 1
OBSTACLE_PLANT = 2


@dataclass
class BatchState:
    """Every mutable quantity of ``num_envs`` environments (float64 for the dynamics)."""

    robot_xy: np.ndarray  # (N, 2) m
    robot_theta: np.ndarray  # (N,) rad, in (-pi, pi]
    robot_v: np.ndarray  # (N,) last commanded linear speed, m/s
    robot_omega: np.ndarray  # (N,) last commanded angular speed, rad/s
    robot_vy: np.ndarray  # (N,) holonomic: last commanded sideways speed (robot frame), m/s
    goal_xy: np.ndarray  # (N, 2) m
    start_xy: np.ndarray  # (N, 2) robot position at reset, m
    human_xy: np.ndarray  # (N, H, 2) m
    human_heading: np.ndarray  # (N, H, 2) unit heading vectors (cos θ_h, sin θ_h)
    human_speed: np.ndarray  # (N, H) m/s
    human_goal: np.ndarray  # (N, H, 2) m
    human_goal_index: np.ndarray  # (N, H) int64: how many goals the human has drawn so far
    human_policy: np.ndarray  # (N, H) int8: scenario.POLICY_SFM or POLICY_ORCA
    human_max_speed: np.ndarray  # (N, H) each human's preferred (and maximum) speed, m/s
    human_sees_robot: np.ndarray  # (N, H) bool: the human reacts to the robot this episode
    human_group: np.ndarray  # (N, H) int64: the group a human belongs to, -1 alone
    group_leader: np.ndarray  # (N, G) int64: a group's first member, -1 for an unused slot
    group_standing: np.ndarray  # (N, G) bool: a standing conversation group
    obstacle_kind: np.ndarray  # (N, O) int8: OBSTACLE_NONE (empty slot), _TABLE or _PLANT
    obstacle_xy: np.ndarray  # (N, O, 2) centres, m
    obstacle_half: np.ndarray  # (N, O, 2) half width and depth of a table; a plant: (r, r), m
    step_count: np.ndarray  # (N,) int64: steps taken in the current episode
    scenario_id: np.ndarray  # (N,) int64: which scenario of the seed runs in each slot
    alive_sum: np.ndarray  # (N,) accumulated alive penalty (paper reward's A)
    discomfort_sum: np.ndarray  # (N,) accumulated discomfort penalty (paper reward's S)
    done: np.ndarray  # (N,) bool: the episode in this slot has ended and awaits a reset

    @classmethod
    def zeros(
        cls, num_envs: int, num_humans: int, num_obstacles: int = 0, num_groups: int = 0
    ) -> BatchState:
        n, h, o, g = num_envs, num_humans, num_obstacles, num_groups
        return cls(
            robot_xy=np.zeros((n, 2)),
            robot_theta=np.zeros(n),
            robot_v=np.zeros(n),
            robot_omega=np.zeros(n),
            robot_vy=np.zeros(n),
            goal_xy=np.zeros((n, 2)),
            start_xy=np.zeros((n, 2)),
            human_xy=np.zeros((n, h, 2)),
            human_heading=np.tile(np.array([1.0, 0.0]), (n, h, 1)),
            human_speed=np.zeros((n, h)),
            human_goal=np.zeros((n, h, 2)),
            human_goal_index=np.zeros((n, h), dtype=np.int64),
            human_policy=np.zeros((n, h), dtype=np.int8),
            human_max_speed=np.zeros((n, h)),
            human_sees_robot=np.zeros((n, h), dtype=bool),
            human_group=np.full((n, h), -1, dtype=np.int64),
            group_leader=np.full((n, g), -1, dtype=np.int64),
            group_standing=np.zeros((n, g), dtype=bool),
            obstacle_kind=np.zeros((n, o), dtype=np.int8),
            obstacle_xy=np.zeros((n, o, 2)),
            obstacle_half=np.zeros((n, o, 2)),
            step_count=np.zeros(n, dtype=np.int64),
            scenario_id=np.zeros(n, dtype=np.int64),
            alive_sum=np.zeros(n),
            discomfort_sum=np.zeros(n),
            done=np.zeros(n, dtype=bool),
        )

    @property
    def num_envs(self) -> int:
        return self.robot_theta.shape[0]

    def robot_pose(self) -> np.ndarray:
        """(N, 3) the robot's room pose: x, y (m) and θ (rad); a copy."""
        return np.column_stack([self.robot_xy, self.robot_theta])

    @property
    def num_humans(self) -> int:
        return self.human_speed.shape[1]

    def human_theta(self) -> np.ndarray:
        """(N, H) human headings, rad."""
        return np.arctan2(self.human_heading[..., 1], self.human_heading[..., 0])

    def copy(self) -> BatchState:
        return BatchState(**{f.name: getattr(self, f.name).copy() for f in fields(self)})

    def robot_velocity(self) -> np.ndarray:
        """(N, 2) world-frame robot velocity during the last step, m/s: the last command
        (forward ``robot_v`` and, holonomic, sideways ``robot_vy``) along the heading."""
        c, s = np.cos(self.robot_theta), np.sin(self.robot_theta)
        return np.stack(
            (self.robot_v * c - self.robot_vy * s, self.robot_v * s + self.robot_vy * c), axis=-1
        )

    def human_velocity(self) -> np.ndarray:
        """(N, H, 2) world-frame human velocities, m/s."""
        return self.human_speed[..., None] * self.human_heading
