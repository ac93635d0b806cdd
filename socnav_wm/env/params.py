"""Scenario parameters of the simulator, with the paper's values as defaults (paper_spec §1–§3).

One frozen pydantic model, validated on construction: ``gym.make("SocNav-v0", **kwargs)``,
``params.yaml``'s ``env`` section and the tests all build it, so a bad value gets the same
one-line error everywhere.
"""

from __future__ import annotations

import math
from typing import Annotated, ClassVar, Literal, Self

from pydantic import BeforeValidator, Field, model_validator

from socnav_wm.section import Section, as_tuple, finite, non_negative, positive

__all__ = [
    "FAMILIES",
    "HUMAN_POLICIES",
    "KINEMATICS",
    "PAPER_SFM_SEES_ROBOT",
    "REWARD_KINDS",
    "EnvParams",
]

HumanPolicy = Literal["mixed", "sfm", "orca"]
RewardKind = Literal["paper", "dense"]
Family = Literal["room", "circle_crossing", "square_crossing"]
Kinematics = Literal["unicycle", "holonomic"]
CountRange = Annotated[tuple[int, int], BeforeValidator(as_tuple)]
SpeedRange = Annotated[tuple[float, float], BeforeValidator(as_tuple)]
Size = Annotated[tuple[float, float], BeforeValidator(as_tuple)]

FAMILIES: tuple[str, ...] = ("room", "circle_crossing", "square_crossing")
KINEMATICS: tuple[str, ...] = ("unicycle", "holonomic")
PAPER_SFM_SEES_ROBOT = 0.05
"""``humans_see_robot: paper``: the probability, per SFM human per step, that it is pushed by
the robot (as by a wall); the paper's ORCA humans never see it."""

PACKING = 1 / 3
"""The share of the humans' square that the discs of the robot, the humans and their goals
may cover (:attr:`EnvParams.most_humans`)."""
OBSTACLE_PACKING = 0.5
"""The share of the room inside the walls that the obstacles, each grown by its clearance, may
cover: random placement jams near half."""
OBSTACLE_CLEARANCE = 2.0
"""Obstacles are kept this many human radii apart from each other and from the walls, so that
no pocket of the room is closed off."""
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
    goal_radius: float = non_negative(0.5)
    """The goal is reached when the robot centre is within robot_radius + goal_radius (CrowdNav:
    within robot_radius, goal_radius 0)."""
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
    human_speed_range: SpeedRange | None = None
    """Each human's preferred (and maximum) speed drawn uniformly in [low, high] per episode
    (m/s); None: every human walks at ``human_max_speed``."""
    humans_see_robot: bool | Literal["paper"] = "paper"
    """Whether the humans react to the robot. ``true``: each human sees it for the whole episode
    unless it drew "ignore" (``ignore_robot_prob``): an ORCA human treats it as an agent that
    does not reciprocate (and keeps right), an SFM human is pushed away from it and to its right
    (``sfm_robot_*``); both step round it. ``false``: no human sees it (CrowdNav's invisible
    robot).
    ``paper``: the paper's environment: SFM humans are pushed by it as by a wall on 5 % of steps
    (``PAPER_SFM_SEES_ROBOT``), ORCA humans never see it."""
    ignore_robot_prob: float = Field(0.0, ge=0, le=1, allow_inf_nan=False)
    """With ``humans_see_robot: true``: the probability that a human ignores the robot for the
    whole episode (drawn per human at reset; SocNavGym's ``prob_to_avoid_robot`` reversed)."""
    observed_humans: int | None = Field(None, ge=0)
    """K, the humans in the observation. None or ``num_humans``: every human, in spawn order
    (the paper's layout). Fewer: the K nearest, nearest first. More: the slots past
    ``num_humans`` are padding, flagged by a radius of 0 (a present human's is > 0)."""
    scenario: Family = "room"
    """Where people start and go. ``room``: the paper's (uniform in the room, new random goals
    on arrival). ``circle_crossing`` (CrowdNav): each human starts on a circle of
    ``crossing_radius`` and walks to the opposite point; the robot goes from (0, −R) to (0, R).
    ``square_crossing`` (CrowdNav): humans start on one side of a square of side 2R and walk to a
    point on the other side. In the crossing families a human at its goal stays there."""
    crossing_radius: float = positive(4.0)
    """R of the crossing families (m): the circle's radius, the square's half-side."""
    crossing_noise: float = non_negative(0.5)
    """Crossing families: each human's start (and so its goal) is moved by up to ± this in x and
    y (m), CrowdNav's ``px_noise``/``py_noise`` (uniform in ±0.5 × its speed of 1 m/s)."""
    kinematics: Kinematics = "unicycle"
    """``unicycle`` (the paper's: turn by ω·dt, then advance v·dt along the heading) or
    ``holonomic`` (CrowdNav's: a command is a velocity (vx, vy) in the robot's frame, clipped
    to ``robot_max_speed``; the heading never changes). The four discrete actions are then stop,
    forward, left and right translations at ``robot_max_speed``."""
    swept_collision: bool = False
    """A robot–human contact is also detected between two steps: the closest approach of the
    two discs moving in a straight line over the step (CrowdNav's test). False: only at the end
    of each step (the paper's)."""
    tables: CountRange = (0, 0)
    """How many tables (axis-aligned rectangles of ``table_size``) each scenario has: a count
    drawn uniformly in [low, high]."""
    table_size: Size = (1.2, 0.8)
    """A table's width (along x) and depth (along y), m."""
    plants: CountRange = (0, 0)
    """How many plants (discs of ``plant_radius``) each scenario has, drawn in [low, high]."""
    plant_radius: float = positive(0.25)
    """A plant's radius (m)."""
    groups: CountRange = (0, 0)
    """How many walking groups each scenario has, drawn in [low, high]: members walk to one
    shared goal and keep together (the cohesion of Moussaïd et al. 2010's group SFM: a member
    farther than (n − 1)/2 m from the group's centre is drawn back to it). Room family only."""
    standing_groups: CountRange = (0, 0)
    """How many standing conversation groups each scenario has, drawn in [low, high]: members
    stand on a circle facing its centre and never move."""
    group_size: CountRange = (2, 4)
    """Members per group, drawn per group in [low, high]; groups take humans in index order,
    the first member of a walking group leads it; humans left over walk alone."""
    observed_obstacles: int = Field(0, ge=0)
    """M, the obstacles in the observation: the M nearest, nearest first, each as the nearest
    point of its outline in the robot's frame, its size (the radius of its enclosing circle)
    and a presence flag (1; slots with no obstacle are all zeros)."""
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
    """ORCA humans: collisions with walls and obstacles are avoided over this horizon (s)."""
    orca_safety: float = non_negative(0.0)
    """ORCA humans: added to every agent's radius in their ORCA (m); CrowdNav's humans use
    0.01 (CrowdNav++'s 0.16)."""
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
    sfm_robot_strength: float = non_negative(0.2)
    """SFM humans who see the robot (``humans_see_robot: true``): the push away from it at
    contact (in the units of the desired force, 0.14 m/s at full weight)."""
    sfm_robot_range: float = positive(0.3)
    """SFM humans who see the robot: the push decays as exp(−gap/range), gap surface to surface
    (m)."""
    sfm_robot_side: float = non_negative(1.0)
    """SFM humans who see the robot: the share of the push turned to the human's right when
    the robot stands between it and its goal (so it steps round it)."""
    sfm_weight: float = finite(1.0 / math.sqrt(3.0))
    """Weight of each of the three SFM force terms (goal, obstacles, other humans)."""

    @model_validator(mode="after")
    def _scenario_parts(self) -> Self:
        for name in ("tables", "plants", "groups", "standing_groups", "group_size"):
            low, high = getattr(self, name)
            if not 0 <= low <= high:
                raise ValueError(
                    f"{name}: expected [low, high] with 0 <= low <= high, got [{low}, {high}]"
                )
        if self.human_speed_range is not None:
            low, high = self.human_speed_range
            if not (math.isfinite(low) and math.isfinite(high) and 0 < low <= high):
                raise ValueError(
                    f"human_speed_range: expected [low, high] with 0 < low <= high, got "
                    f"[{low}, {high}]"
                )
        if any(not (math.isfinite(v) and v > 0) for v in self.table_size):
            raise ValueError(
                f"table_size: expected two positive sizes, got {list(self.table_size)}"
            )
        if self.group_size[0] < 2 and self.max_groups:
            raise ValueError("group_size: a group has at least 2 members")
        members = self.max_groups * self.group_size[1]
        if members > self.num_humans:
            raise ValueError(
                f"groups, standing_groups: up to {self.max_groups} groups of up to "
                f"{self.group_size[1]} need {members} humans, more than num_humans "
                f"{self.num_humans}"
            )
        if self.scenario != "room" and self.max_groups:
            raise ValueError(
                f"groups, standing_groups: groups are placed in the room family only, not in "
                f"{self.scenario}"
            )
        if self.observed_obstacles and not self.max_obstacles:
            raise ValueError("observed_obstacles: the scenario has no tables or plants to observe")
        if self.scenario != "room" and self.max_obstacles:
            raise ValueError(
                f"tables, plants: obstacles are placed in the room family only, not in "
                f"{self.scenario}"
            )
        if self.ignore_robot_prob and self.humans_see_robot is not True:
            raise ValueError(
                "ignore_robot_prob: only with humans_see_robot: true (it is the share of humans "
                "who do not see a visible robot)"
            )
        if self.scenario != "room":
            reach = self.crossing_radius + self.crossing_noise + self.human_radius
            if reach >= self.wall_half_size:
                raise ValueError(
                    f"crossing_radius: a {self.scenario} of {self.crossing_radius} m (noise "
                    f"{self.crossing_noise} m) does not fit inside the walls of a "
                    f"{self.room_size} m room; enlarge room_size"
                )
        return self

    @model_validator(mode="after")
    def _fits_in_the_room(self) -> Self:
        inner = (2 * self.wall_half_size) ** 2
        if self.obstacle_area > OBSTACLE_PACKING * inner:
            raise ValueError(
                f"tables, plants: up to {self.max_obstacles} obstacles with their clearance "
                f"cover {self.obstacle_area:.1f} m², more than half of the {inner:.1f} m² "
                "inside the walls"
            )
        if self.scenario != "room":
            most = self.most_crossing_humans
            if self.num_humans > most:
                raise ValueError(
                    f"num_humans: {self.num_humans} humans do not fit on a {self.scenario} of "
                    f"radius {self.crossing_radius} m with radius {self.human_radius} m (at most "
                    f"{most}; or enlarge crossing_radius)"
                )
            return self
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
        room = (2 * self.centre_half_size(self.human_radius)) ** 2 - self.obstacle_area
        packing = (PACKING * room - math.pi * self.robot_radius**2) / humans
        goal = self.goal_radius
        blocking = math.pi * (
            (goal + self.human_radius) ** 2 + (goal + self.human_goal_radius) ** 2
        )
        left = self.goal_area_left(self.min_goal_distance) * (2 * self.centre_half_size(goal)) ** 2
        return max(0, math.floor(min(packing, GOAL_CROWDING * left / blocking)))

    @property
    def max_groups(self) -> int:
        """The most groups (walking and standing) a scenario can have (the state's slots)."""
        return self.groups[1] + self.standing_groups[1]

    @property
    def max_obstacles(self) -> int:
        """The most obstacles a scenario can have (the state's obstacle slots)."""
        return self.tables[1] + self.plants[1]

    @property
    def num_observed_humans(self) -> int:
        """K: the human slots of the observation."""
        return self.num_humans if self.observed_humans is None else self.observed_humans

    @property
    def obstacle_area(self) -> float:
        """The area the most obstacles of a scenario cover, each with the clearance kept
        around it (m²)."""
        width, depth = self.table_size
        clear = OBSTACLE_CLEARANCE * self.human_radius
        table = (width + 2 * clear) * (depth + 2 * clear)
        plant = math.pi * (self.plant_radius + clear) ** 2
        return self.tables[1] * table + self.plants[1] * plant

    @property
    def most_crossing_humans(self) -> int:
        """Crossing families: the most humans whose starts (and goals) can be spaced on the
        circle or the square's sides without overlap, at a third of the packing (like rooms)."""
        gap = 2 * self.human_radius + self.discomfort_distance
        length = (2 * math.pi if self.scenario == "circle_crossing" else 8) * self.crossing_radius
        return max(0, math.floor(PACKING * length / gap))

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
