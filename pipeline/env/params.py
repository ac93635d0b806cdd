"""Scenario parameters of the simulator, with the paper's values as defaults (paper_spec §1–§3).

One frozen dataclass, validated on construction: ``gym.make("SocNav-v0", **kwargs)``,
``params.yaml``'s ``env`` section and the tests all build it, so a bad value gets the same
one-line error everywhere.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any, Literal

from pydantic import ConfigDict

HumanPolicy = Literal["mixed", "sfm", "orca"]
RewardKind = Literal["paper", "dense"]

HUMAN_POLICIES: tuple[str, ...] = ("mixed", "sfm", "orca")
REWARD_KINDS: tuple[str, ...] = ("paper", "dense")


@dataclass(frozen=True)
class EnvParams:
    """Every constant of the scenario. Lengths in metres, speeds in m/s, angles in radians."""

    # Unknown keys are an error when pydantic validates this dataclass inside params.yaml.
    __pydantic_config__ = ConfigDict(extra="forbid")

    num_humans: int = 3
    """Number of people in the room."""
    room_size: float = 10.0
    """Outer side of the square room (m), centred at the origin."""
    wall_thickness: float = 0.2
    """Walls lie inside the room's outline; their inner faces are at ±(room_size/2 − thickness)."""
    spawn_margin: float = 0.5
    """Robot, humans and goals are drawn uniformly in ±(room_size/2 − spawn_margin)."""
    dt: float = 1.0
    """Simulation time step (s)."""
    max_steps: int = 201
    """Steps after which an episode is truncated (the paper's env stops when ticks > 200)."""
    robot_radius: float = 0.3
    robot_max_speed: float = 0.14
    """Linear speed of the `forward` action and the clip of continuous commands (m/s)."""
    robot_max_rotation: float = 0.387596899
    """Angular speed of the rotate actions and the clip of continuous commands (rad/s)."""
    goal_radius: float = 0.5
    """The goal is reached when the robot centre is within robot_radius + goal_radius."""
    min_goal_distance: float = 0.0
    """Minimum initial robot-goal distance (m); 0 reproduces the paper's uniform draw."""
    human_radius: float = 0.36
    human_max_speed: float = 0.14
    human_goal_radius: float = 0.25
    """A human draws a new goal when within human_radius + human_goal_radius of it."""
    human_speed_threshold: float = 0.05
    """Human speeds below this are set to 0, as in the paper's environment."""
    human_policy: HumanPolicy = "mixed"
    """`mixed` draws SFM or ORCA per human per episode (50/50); `sfm` or `orca` for all."""
    sfm_avoid_robot_prob: float = 0.05
    """Probability, per human per step, that an SFM human treats the robot as an obstacle."""
    orca_avoid_robot: bool = False
    """Whether ORCA humans see the robot (as a non-reciprocating agent). The paper: no."""
    reward: RewardKind = "paper"
    """`paper`: paper_spec §3.1 (sparse, refunded on failure); `dense`: per-step penalties."""
    reach_reward: float = 1.0
    failure_reward: float = -1.0
    alive_penalty: float = -0.0005
    discomfort_distance: float = 0.9999
    discomfort_factor: float = 0.01
    orca_neighbor_dist: float = 1.44
    orca_max_neighbors: int = 3
    orca_time_horizon: float = 5.0
    orca_time_horizon_obst: float = 5.0
    sfm_wall_range: float = 0.05
    """r0 of the exponential wall/robot repulsion exp(−d/r0) (m)."""
    sfm_gamma: float = 0.25
    sfm_n: float = 1.0
    sfm_n_prime: float = 1.0
    sfm_lambda: float = 1.0
    sfm_weight: float = 1.0 / math.sqrt(3.0)
    """Weight of each of the three SFM force terms (goal, obstacles, other humans)."""

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.type in ("int", "float") and (
                isinstance(value, bool) or not isinstance(value, int | float)
            ):
                raise ValueError(f"env.{f.name}: expected a number, got {value!r}")
            if f.type == "int" and not float(value).is_integer():
                raise ValueError(f"env.{f.name}: expected an integer, got {value!r}")
            if f.type == "bool" and not isinstance(value, bool):
                raise ValueError(f"env.{f.name}: expected true or false, got {value!r}")
            if f.type == "float" and not math.isfinite(value):
                raise ValueError(f"env.{f.name}: must be finite, got {value!r}")
        if self.human_policy not in HUMAN_POLICIES:
            raise ValueError(
                f"env.human_policy: must be one of {', '.join(HUMAN_POLICIES)}, "
                f"got {self.human_policy!r}"
            )
        if self.reward not in REWARD_KINDS:
            raise ValueError(
                f"env.reward: must be one of {', '.join(REWARD_KINDS)}, got {self.reward!r}"
            )
        positive = (
            "room_size", "dt", "max_steps", "robot_radius", "robot_max_speed",
            "robot_max_rotation", "goal_radius", "human_radius", "human_max_speed",
            "orca_neighbor_dist", "orca_max_neighbors", "orca_time_horizon",
            "orca_time_horizon_obst", "sfm_wall_range", "sfm_gamma",
        )  # fmt: skip
        for name in positive:
            if getattr(self, name) <= 0:
                raise ValueError(f"env.{name}: must be > 0, got {getattr(self, name)!r}")
        non_negative = (
            "num_humans", "wall_thickness", "spawn_margin", "human_goal_radius",
            "human_speed_threshold", "min_goal_distance", "discomfort_distance",
            "discomfort_factor",
        )  # fmt: skip
        for name in non_negative:
            if getattr(self, name) < 0:
                raise ValueError(f"env.{name}: must be >= 0, got {getattr(self, name)!r}")
        if not 0.0 <= self.sfm_avoid_robot_prob <= 1.0:
            raise ValueError(
                f"env.sfm_avoid_robot_prob: must be in [0, 1], got {self.sfm_avoid_robot_prob!r}"
            )
        if self.spawn_half_size <= max(self.robot_radius, self.human_radius):
            raise ValueError(
                f"env.room_size: a {self.room_size} m room with spawn_margin "
                f"{self.spawn_margin} leaves no room to spawn anything"
            )
        if self.spawn_half_size > self.wall_half_size:
            raise ValueError(
                "env.spawn_margin: must be >= wall_thickness (spawns inside the walls)"
            )
        if self.min_goal_distance >= 2 * math.sqrt(2) * self.spawn_half_size:
            raise ValueError(
                f"env.min_goal_distance: {self.min_goal_distance} m cannot fit in the spawn area"
            )

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

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> EnvParams:
        """Build from a mapping, naming any unknown key in the error."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"env: unknown option(s) {', '.join(unknown)}")
        return cls(**values)
