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

PACKING = 1 / 3
"""The share of the humans' square that the discs of the robot, the humans and their goals
may cover (:attr:`EnvParams.most_humans`)."""
GOAL_CROWDING = 2.3
"""How many times the area left to the robot's goal the discs that keep it away may cover."""
GOAL_AREA_LEFT = 0.005
"""The least share of its square left to the robot's goal by ``min_goal_distance`` from a
robot at the centre: 10,000 attempts then all miss with probability below e**-50."""


def _disc_in_square(half: float, radius: float) -> float:
    """The area of a disc of ``radius`` and a square of half-side ``half``, both centred at the
    origin, in common."""
    if radius <= half:
        return math.pi * radius**2
    if radius >= half * math.sqrt(2):
        return (2 * half) ** 2
    segment = radius**2 * math.acos(half / radius) - half * math.sqrt(radius**2 - half**2)
    return math.pi * radius**2 - 4 * segment


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
        discs = ("robot_radius", "goal_radius", "human_radius", "human_goal_radius")
        for name in discs[: 4 if self.num_humans else 2]:
            if self.centre_half_size(getattr(self, name)) <= 0:
                raise ValueError(
                    f"{name}: a disc of {getattr(self, name)} m does not fit inside the walls "
                    f"of a {self.room_size} m room with spawn_margin {self.spawn_margin}"
                )
        if self.goal_area_left(0.0) < GOAL_AREA_LEFT:
            raise ValueError(
                f"goal_radius: a goal of {self.goal_radius} m beside a robot of "
                f"{self.robot_radius} m has almost no room in a {self.room_size} m room"
            )
        if self.goal_area_left(self.min_goal_distance) < GOAL_AREA_LEFT:
            raise ValueError(
                f"min_goal_distance: {self.min_goal_distance} m leaves the goal almost no room "
                f"when the robot starts near the room's centre (at most "
                f"{self._longest_goal_distance():.2f} m)"
            )
        most = self.most_humans
        if self.num_humans > most:
            raise ValueError(
                f"num_humans: {self.num_humans} humans and their goals cannot be placed in a "
                f"{self.room_size} m room without running out of spawn attempts (at most "
                f"{most} here; or enlarge room_size)"
            )
        return self

    def centre_half_size(self, radius: float) -> float:
        """Half-side of the square where a disc of ``radius`` may be centred: drawn within
        ``spawn_half_size``, not touching the walls (m)."""
        return min(self.spawn_half_size, self.wall_half_size - radius)

    def goal_area_left(self, distance: float) -> float:
        """The share of the robot goal's square that lies ``distance`` or farther from the
        room's centre (and off the robot's disc): what is left to the goal when the robot
        starts there, the worst place."""
        half = self.centre_half_size(self.goal_radius)
        near = max(distance, self.goal_radius + self.robot_radius)
        return 1.0 - _disc_in_square(half, near) / (2 * half) ** 2

    def _longest_goal_distance(self) -> float:
        low, high = 0.0, 2 * math.sqrt(2) * self.spawn_half_size
        for _ in range(60):  # bisection: goal_area_left decreases with the distance
            middle = (low + high) / 2
            low, high = (
                (middle, high) if self.goal_area_left(middle) >= GOAL_AREA_LEFT else (low, middle)
            )
        return low

    @property
    def most_humans(self) -> int:
        """The most humans that spawning places reliably (docs/simulator.md): each disc is
        drawn at random until it touches nothing (10,000 attempts), which jams long before the
        discs fill the room. Two bounds, measured on rooms of 3–20 m, radii of 0.1–1 m and
        margins, with no failure in 3,000 scenarios at the bound (in the paper's room, 40:
        failures begin near 48, at 1 in 10,000 scenarios, and reach half at 60):

        - the discs of the robot, the humans and their goals cover at most a third of the
          square where humans are centred (random packing jams near half of it);
        - the discs that keep the robot's goal away (each human's and each human goal's,
          grown by the goal's radius) cover at most 2.3 times the area left to that goal.
        """
        humans = math.pi * (self.human_radius**2 + self.human_goal_radius**2)
        room = (2 * self.centre_half_size(self.human_radius)) ** 2
        packing = (PACKING * room - math.pi * self.robot_radius**2) / humans
        goal = self.goal_radius
        blocking = math.pi * (
            (goal + self.human_radius) ** 2 + (goal + self.human_goal_radius) ** 2
        )
        left = self.goal_area_left(self.min_goal_distance) * (2 * self.centre_half_size(goal)) ** 2
        return max(0, math.floor(min(packing, GOAL_CROWDING * left / blocking)))

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
