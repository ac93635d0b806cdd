"""Scenario parameters of the simulator, with the paper's values as defaults (paper_spec §1–§3).

One frozen pydantic model, validated on construction: ``gym.make("SocNav-v0", **kwargs)``,
``params.yaml``'s ``env`` section and the tests all build it, so a bad value gets the same
one-line error everywhere.
"""

from __future__ import annotations

import math
from typing import ClassVar, Literal, Self

from pydantic import Field, model_validator

from socnav_wm.section import Section, finite, non_negative, positive

__all__ = ["HUMAN_POLICIES", "REWARD_KINDS", "EnvParams"]

HumanPolicy = Literal["mixed", "sfm", "orca"]
RewardKind = Literal["paper", "dense"]

HUMAN_POLICIES: tuple[str, ...] = ("mixed", "sfm", "orca")
REWARD_KINDS: tuple[str, ...] = ("paper", "dense")


class EnvParams(Section):
    """Every constant of the scenario. Lengths in metres, speeds in m/s, angles in radians."""

    SECTION: ClassVar[str] = "env"

    num_humans: int = Field(3, ge=0)
    """Number of people in the room."""
    room_size: float = positive(10.0)
    """Outer side of the square room (m), centred at the origin."""
    wall_thickness: float = non_negative(0.2)
    """Walls lie inside the room's outline; their inner faces are at ±(room_size/2 − thickness)."""
    spawn_margin: float = non_negative(0.5)
    """Robot, humans and goals are drawn uniformly in ±(room_size/2 − spawn_margin)."""
    dt: float = positive(1.0)
    """Simulation time step (s)."""
    max_steps: int = Field(201, gt=0)
    """Steps after which an episode is truncated (the paper's env stops when ticks > 200)."""
    robot_radius: float = positive(0.3)
    """Radius of the robot's disc (m)."""
    robot_max_speed: float = positive(0.14)
    """Linear speed of the `forward` action and the clip of continuous commands (m/s)."""
    robot_max_rotation: float = positive(0.387596899)
    """Angular speed of the rotate actions and the clip of continuous commands (rad/s)."""
    goal_radius: float = positive(0.5)
    """The goal is reached when the robot centre is within robot_radius + goal_radius."""
    min_goal_distance: float = non_negative(0.0)
    """Minimum initial robot-goal distance (m); 0 reproduces the paper's uniform draw."""
    human_radius: float = positive(0.36)
    """Radius of a person's disc (m)."""
    human_max_speed: float = positive(0.14)
    """Preferred (and maximum) walking speed of the people (m/s)."""
    human_goal_radius: float = non_negative(0.25)
    """A human draws a new goal when within human_radius + human_goal_radius of it."""
    human_speed_threshold: float = non_negative(0.05)
    """Human speeds below this are set to 0, as in the paper's environment."""
    human_policy: HumanPolicy = "mixed"
    """`mixed` draws SFM or ORCA per human per episode (50/50); `sfm` or `orca` for all."""
    sfm_avoid_robot_prob: float = Field(0.05, ge=0, le=1, allow_inf_nan=False)
    """Probability, per human per step, that an SFM human treats the robot as an obstacle."""
    orca_avoid_robot: bool = False
    """Whether ORCA humans see the robot (as a non-reciprocating agent). The paper: no."""
    reward: RewardKind = "paper"
    """`paper`: paper_spec §3.1 (sparse, refunded on failure); `dense`: per-step penalties."""
    reach_reward: float = finite(1.0)
    """Reward for reaching the goal."""
    failure_reward: float = finite(-1.0)
    """Reward for a collision (with a person or a wall)."""
    alive_penalty: float = finite(-0.0005)
    """`dense` reward: added at every step."""
    discomfort_distance: float = non_negative(0.9999)
    """`dense` reward: people closer than this to the robot (m) cost discomfort."""
    discomfort_factor: float = non_negative(0.01)
    """`dense` reward: weight of the discomfort penalty."""
    orca_neighbor_dist: float = positive(1.44)
    """ORCA humans: others closer than this (m) are avoided."""
    orca_max_neighbors: int = Field(3, gt=0)
    """ORCA humans: at most this many nearest others are avoided."""
    orca_time_horizon: float = positive(5.0)
    """ORCA humans: collisions with others are avoided over this horizon (s)."""
    orca_time_horizon_obst: float = positive(5.0)
    """ORCA humans: collisions with walls are avoided over this horizon (s)."""
    sfm_wall_range: float = positive(0.05)
    """r0 of the exponential wall/robot repulsion exp(−d/r0) (m)."""
    sfm_gamma: float = positive(0.25)
    """SFM humans: γ of the anisotropic interaction with other humans."""
    sfm_n: float = finite(1.0)
    """SFM humans: n of the interaction's angular decay."""
    sfm_n_prime: float = finite(1.0)
    """SFM humans: n′ of the interaction's angular decay (sideways part)."""
    sfm_lambda: float = finite(1.0)
    """SFM humans: λ weighting the direction of motion against the relative position."""
    sfm_weight: float = finite(1.0 / math.sqrt(3.0))
    """Weight of each of the three SFM force terms (goal, obstacles, other humans)."""

    @model_validator(mode="after")
    def _fits_in_the_room(self) -> Self:
        if self.spawn_half_size <= max(self.robot_radius, self.human_radius):
            raise ValueError(
                f"room_size: a {self.room_size} m room with spawn_margin "
                f"{self.spawn_margin} leaves no room to spawn anything"
            )
        if self.spawn_half_size > self.wall_half_size:
            raise ValueError("spawn_margin: must be >= wall_thickness (spawns inside the walls)")
        if self.min_goal_distance >= 2 * math.sqrt(2) * self.spawn_half_size:
            raise ValueError(
                f"min_goal_distance: {self.min_goal_distance} m cannot fit in the spawn area"
            )
        # Every disc (robot, its goal, each human and its goal) is drawn so that it touches
        # nothing: beyond the room's area, spawning could never succeed (and would retry for
        # as long as it is let).
        per_human = math.pi * (self.human_radius**2 + self.human_goal_radius**2)
        robot = math.pi * (self.robot_radius**2 + self.goal_radius**2)
        fit = int(((2 * self.wall_half_size) ** 2 - robot) // per_human)
        if self.num_humans > fit:
            raise ValueError(
                f"num_humans: {self.num_humans} humans and their goals cannot be placed in a "
                f"{self.room_size} m room (their discs alone need more than its area; "
                f"at most {max(fit, 0)})"
            )
        return self

    @property
    def wall_half_size(self) -> float:
        """Half-side of the free square inside the walls (m): 4.8 for the paper's room."""
        return self.room_size / 2.0 - self.wall_thickness

    @property
    def spawn_half_size(self) -> float:
        """Half-side of the square where positions and goals are drawn (m): 4.5 by default."""
        return self.room_size / 2.0 - self.spawn_margin

    @property
    def success_distance(self) -> float:
        """Robot-goal centre distance under which the goal is reached (m): 0.8 by default."""
        return self.robot_radius + self.goal_radius
