"""Per-episode metrics from one episode's trajectory (pure functions, paper definitions).

The paper ("Predictive World Models for Social Navigation") reports nine metrics
(:data:`PAPER_METRICS`). Its authors' test scripts computed several of them differently from the
paper's text (robot-frame distance, stop-action idle time, a 2.02 m centre-distance "personal
space", see ``shared/design/paper_spec.md`` §6). This module implements the paper's *intent*, the
"clean" definitions, everywhere, in the world frame, and adds a few extra metrics
(:data:`EXTRA_METRICS`), among them the code-faithful personal-space variant so that both numbers
can be reported side by side.

Conventions: a trajectory of ``T`` steps holds ``T + 1`` states (index 0 is the state after reset,
index ``t`` the state after step ``t``) and ``T`` per-step quantities (``dmin``, ``rewards``).
Every metric function takes ``(traj, params)`` and returns a plain ``float``; boolean outcomes are
``0.0`` / ``1.0`` so that means over episodes are rates.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

__all__ = [
    "episodes_to_solve",
    "ALL_METRICS",
    "DEFAULT_PARAMS",
    "EXTRA_METRICS",
    "METRIC_DIRECTIONS",
    "METRIC_FUNCTIONS",
    "METRIC_UNITS",
    "PAPER_METRICS",
    "MetricParams",
    "Trajectory",
    "discomfort",
    "distance_travelled",
    "episode_metrics",
    "human_collision",
    "idle_time",
    "max_steps",
    "minimum_distance_to_human",
    "path_length",
    "personal_space_compliance",
    "personal_space_compliance_code",
    "reward",
    "simulation_time",
    "spl",
    "step_displacements",
    "success",
    "surface_distances",
    "time_to_reach_goal",
    "wall_collision",
    "obstacle_collision",
    "group_crossings",
]

_COLLISION_KINDS = (None, "human", "wall", "obstacle")


@dataclass(frozen=True)
class Trajectory:
    """One episode, as the metrics need it. All positions are world-frame, in metres.

    Attributes:
        robot_xy: ``(T+1, 2)`` robot centre positions; index 0 = after reset, ``t`` = after step t.
        human_xy: ``(T+1, H, 2)`` human centre positions at the same instants (``H`` may be 0).
        goal_xy: ``(2,)`` the robot's goal.
        dmin: ``(T,)`` the simulator's ``dmin`` of each step: the surface-to-surface robot-human
            distance predicted over the step, m.
        rewards: ``(T,)`` the reward of each step.
        success: the robot reached its goal.
        collision: ``"human"``, ``"wall"``, ``"obstacle"`` or ``None`` (the episode's terminal
            collision, if any).
        truncated: the episode hit the step limit.

    The arrays are validated and stored as read-only ``float64`` copies on construction, so a
    malformed episode fails here, with a :class:`ValueError` naming the problem, rather than as a
    silent broadcast inside a metric.
    """

    robot_xy: np.ndarray
    human_xy: np.ndarray
    goal_xy: np.ndarray
    dmin: np.ndarray
    rewards: np.ndarray
    success: bool
    collision: str | None
    truncated: bool
    human_group: np.ndarray | None = None
    """``(H,)`` the group of each human (−1: alone); None: no groups recorded."""

    def __post_init__(self) -> None:
        robot = _as_float_array("robot_xy", self.robot_xy)
        humans = _as_float_array("human_xy", self.human_xy)
        goal = _as_float_array("goal_xy", self.goal_xy)
        dmin = _as_float_array("dmin", self.dmin)
        rewards = _as_float_array("rewards", self.rewards)

        if robot.ndim != 2 or robot.shape[1] != 2:
            raise ValueError(f"robot_xy must have shape (T+1, 2), got {robot.shape}")
        n_steps = robot.shape[0] - 1
        if n_steps < 1:
            raise ValueError(
                f"a trajectory needs at least one step (T >= 1, robot_xy with >= 2 rows), "
                f"got robot_xy with {robot.shape[0]} row(s)"
            )
        if humans.ndim != 3 or humans.shape[0] != n_steps + 1 or humans.shape[2] != 2:
            raise ValueError(
                f"human_xy must have shape (T+1, H, 2) = ({n_steps + 1}, H, 2) to match "
                f"robot_xy {robot.shape}, got {humans.shape}"
            )
        if goal.shape != (2,):
            raise ValueError(f"goal_xy must have shape (2,), got {goal.shape}")
        if dmin.shape != (n_steps,):
            raise ValueError(f"dmin must have shape (T,) = ({n_steps},), got {dmin.shape}")
        if rewards.shape != (n_steps,):
            raise ValueError(f"rewards must have shape (T,) = ({n_steps},), got {rewards.shape}")
        for name, arr in (("robot_xy", robot), ("human_xy", humans), ("goal_xy", goal)):
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"{name} contains non-finite values")
        # dmin may legitimately be +inf in a room with no humans; NaN never is.
        if np.any(np.isnan(dmin)):
            raise ValueError("dmin contains NaN")
        if not np.all(np.isfinite(rewards)):
            raise ValueError("rewards contains non-finite values")
        if self.collision not in _COLLISION_KINDS:
            raise ValueError(f"collision must be one of {_COLLISION_KINDS}, got {self.collision!r}")
        # The simulator checks the goal before collisions, so one step cannot end both ways.
        if self.success and self.collision is not None:
            raise ValueError(
                f"a trajectory cannot be both a success and a {self.collision} collision"
            )

        for name, arr in (
            ("robot_xy", robot),
            ("human_xy", humans),
            ("goal_xy", goal),
            ("dmin", dmin),
            ("rewards", rewards),
        ):
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "success", bool(self.success))
        object.__setattr__(self, "truncated", bool(self.truncated))
        if self.human_group is not None:
            groups = np.array(self.human_group, dtype=np.int64)
            if groups.shape != (humans.shape[1],):
                raise ValueError(
                    f"human_group must have shape (H,) = ({humans.shape[1]},), got {groups.shape}"
                )
            groups.flags.writeable = False
            object.__setattr__(self, "human_group", groups)

    @property
    def num_steps(self) -> int:
        """``T``, the number of steps taken."""
        return int(self.robot_xy.shape[0] - 1)

    @property
    def num_humans(self) -> int:
        """``H``, the number of humans."""
        return int(self.human_xy.shape[1])


def _as_float_array(name: str, value: object) -> np.ndarray:
    try:
        # A copy, so that later changes to the caller's buffer cannot change the metrics.
        return np.array(value, dtype=np.float64, copy=True)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} is not a numeric array: {exc}") from exc


@dataclass(frozen=True)
class MetricParams:
    """Constants of the metric definitions (defaults: the paper's environment).

    Attributes:
        dt: time step, s.
        robot_radius: robot collision radius, m.
        human_radius: human collision radius, m.
        discomfort_distance: a step is uncomfortable when ``dmin`` is below this, m (the code's
            ``0.9999``).
        personal_space: surface-to-surface clearance a human must have for a state to be
            compliant, m (the paper's 0.5 m).
        idle_threshold: a step whose displacement is below this is idle, m per step.
        goal_threshold: the goal is reached within this centre distance, m (0.3 + 0.5).
        code_psc_radius: centre-to-centre radius of the original code's personal-space check, m.
    """

    dt: float = 1.0
    robot_radius: float = 0.3
    human_radius: float = 0.36
    discomfort_distance: float = 0.9999
    personal_space: float = 0.5
    idle_threshold: float = 0.05
    goal_threshold: float = 0.8
    code_psc_radius: float = 2.02

    def __post_init__(self) -> None:
        for name in ("dt", "robot_radius", "human_radius", "code_psc_radius"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"MetricParams.{name} must be a finite number > 0, got {value}")
        for name in ("discomfort_distance", "personal_space", "idle_threshold", "goal_threshold"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"MetricParams.{name} must be a finite number >= 0, got {value}")


DEFAULT_PARAMS = MetricParams()


# --------------------------------------------------------------------------------------------
# Geometry helpers
# --------------------------------------------------------------------------------------------


def step_displacements(traj: Trajectory) -> np.ndarray:
    """World-frame robot displacement of each step, ``‖p_t − p_{t−1}‖``: shape ``(T,)``, m."""
    return np.linalg.norm(np.diff(traj.robot_xy, axis=0), axis=1)


def surface_distances(traj: Trajectory, params: MetricParams = DEFAULT_PARAMS) -> np.ndarray:
    """Robot-human surface-to-surface distances, shape ``(T+1, H)``, m (negative when overlapping).

    ``‖p_h − p_r‖ − r_h − r_r`` for every state ``t = 0..T`` and human ``h``.
    """
    centre = np.linalg.norm(traj.human_xy - traj.robot_xy[:, None, :], axis=2)
    return centre - params.human_radius - params.robot_radius


# --------------------------------------------------------------------------------------------
# The paper's nine metrics
# --------------------------------------------------------------------------------------------


def discomfort(traj: Trajectory, params: MetricParams = DEFAULT_PARAMS) -> float:
    """Number of steps with ``dmin < discomfort_distance`` (steps).

    This is what the code counted (``DISCOMFORT_CROWDNAV``), not SNGNN. Unlike the code, the
    terminal step is counted too: it is a step the human experienced like any other.
    """
    return float(np.count_nonzero(traj.dmin < params.discomfort_distance))


def distance_travelled(traj: Trajectory, params: MetricParams = DEFAULT_PARAMS) -> float:
    """World-frame robot path length ``Σ_t ‖p_t − p_{t−1}‖`` (m).

    The clean version: the original DQN scripts summed changes of the robot-frame goal vector,
    which rotations in place inflate.
    """
    return float(step_displacements(traj).sum())


def simulation_time(traj: Trajectory, params: MetricParams = DEFAULT_PARAMS) -> float:
    """Episode duration ``T · dt`` (s)."""
    return float(traj.num_steps * params.dt)


def human_collision(traj: Trajectory, params: MetricParams = DEFAULT_PARAMS) -> float:
    """1 if the episode ended in a collision with a human, else 0.

    The original code's flag also fired on wall collisions; those are :func:`wall_collision`.
    """
    return 1.0 if traj.collision == "human" else 0.0


def max_steps(traj: Trajectory, params: MetricParams = DEFAULT_PARAMS) -> float:
    """1 if the episode was truncated at the step limit, else 0."""
    return 1.0 if traj.truncated else 0.0


def reward(traj: Trajectory, params: MetricParams = DEFAULT_PARAMS) -> float:
    """Episode return: the undiscounted sum of the step rewards."""
    return float(traj.rewards.sum())


def success(traj: Trajectory, params: MetricParams = DEFAULT_PARAMS) -> float:
    """1 if the robot reached its goal, else 0."""
    return 1.0 if traj.success else 0.0


def idle_time(traj: Trajectory, params: MetricParams = DEFAULT_PARAMS) -> float:
    """Time spent (almost) still: ``dt × #{t : ‖p_t − p_{t−1}‖ < idle_threshold}`` (s).

    The clean version of the paper's "displacement < 0.05 m": measured from world positions, so
    rotating in place is idle whatever action produced it (the DQN scripts counted stop actions).
    """
    n_idle = np.count_nonzero(step_displacements(traj) < params.idle_threshold)
    return float(n_idle * params.dt)


def personal_space_compliance(traj: Trajectory, params: MetricParams = DEFAULT_PARAMS) -> float:
    """Fraction of the post-step states ``t = 1..T`` that respect everyone's personal space.

    A state complies when every human is more than ``personal_space`` m away surface to surface
    (``‖p_h − p_r‖ − r_h − r_r > 0.5``). The state after reset is excluded: the robot has not
    acted yet. With no humans every state complies.
    """
    clear = surface_distances(traj, params)[1:] > params.personal_space  # (T, H)
    return float(np.all(clear, axis=1).mean())


# --------------------------------------------------------------------------------------------
# Extra metrics
# --------------------------------------------------------------------------------------------


def wall_collision(traj: Trajectory, params: MetricParams = DEFAULT_PARAMS) -> float:
    """1 if the episode ended in a collision with a wall, else 0."""
    return 1.0 if traj.collision == "wall" else 0.0


def obstacle_collision(traj: Trajectory, params: MetricParams = DEFAULT_PARAMS) -> float:
    """1 if the episode ended in a collision with a table or a plant, else 0."""
    return 1.0 if traj.collision == "obstacle" else 0.0


GROUP_SPAN = 2.0
"""Two members of a group at most this far apart (m) bound the group's space between them."""


def _crosses(p: np.ndarray, q: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Whether segments p→q and a→b (arrays of 2-d points, (T, 2)) properly intersect."""

    def side(o: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        return (u[:, 0] - o[:, 0]) * (v[:, 1] - o[:, 1]) - (u[:, 1] - o[:, 1]) * (v[:, 0] - o[:, 0])

    return (side(p, q, a) * side(p, q, b) < 0) & (side(a, b, p) * side(a, b, q) < 0)


def group_crossings(traj: Trajectory, params: MetricParams = DEFAULT_PARAMS) -> float:
    """Steps in which the robot passed through a group: its step crossed the line between two
    members of one group (walking or standing) at most :data:`GROUP_SPAN` apart, at the
    step's end. 0 without groups."""
    groups = traj.human_group
    if groups is None or not np.any(groups >= 0):
        return 0.0
    start, end = traj.robot_xy[:-1], traj.robot_xy[1:]
    crossed = np.zeros(start.shape[0], dtype=bool)
    for group in np.unique(groups[groups >= 0]):
        members = np.flatnonzero(groups == group)
        for k, i in enumerate(members):
            for j in members[k + 1 :]:
                a, b = traj.human_xy[1:, i], traj.human_xy[1:, j]
                close = np.linalg.norm(a - b, axis=-1) <= GROUP_SPAN
                crossed |= close & _crosses(start, end, a, b)
    return float(crossed.sum())


def minimum_distance_to_human(traj: Trajectory, params: MetricParams = DEFAULT_PARAMS) -> float:
    """Smallest robot-human surface-to-surface distance over ``t = 0..T`` and all humans (m).

    Negative when the robot and a human overlap (a collision); ``+inf`` when there are no humans.
    """
    dist = surface_distances(traj, params)
    return float(dist.min()) if dist.size else math.inf


def time_to_reach_goal(traj: Trajectory, params: MetricParams = DEFAULT_PARAMS) -> float:
    """``T · dt`` for a successful episode (s); NaN otherwise, so that means skip failures."""
    return float(traj.num_steps * params.dt) if traj.success else math.nan


def path_length(traj: Trajectory, params: MetricParams = DEFAULT_PARAMS) -> float:
    """SocNavGym's name for :func:`distance_travelled`: world-frame ``Σ_t ‖p_t − p_{t−1}‖`` (m).

    Kept as a separate entry so that tables using SocNavGym's metric names read naturally; the
    value is always identical to ``distance_travelled``.
    """
    return distance_travelled(traj, params)


def spl(traj: Trajectory, params: MetricParams = DEFAULT_PARAMS) -> float:
    """Success weighted by (normalised inverse) Path Length, in [0, 1].

    ``success × ℓ / max(path, ℓ)`` with ``ℓ = max(0, ‖p_0 − goal‖ − goal_threshold)``, the length
    of the shortest path that ends inside the goal region (obstacles ignored). Failures score 0.
    A successful episode that needed no motion at all (``ℓ = path = 0``) scores 1, the limit of
    a perfectly efficient path.
    """
    if not traj.success:
        return 0.0
    shortest = max(
        0.0, float(np.linalg.norm(traj.robot_xy[0] - traj.goal_xy)) - params.goal_threshold
    )
    path = distance_travelled(traj, params)
    denominator = max(path, shortest)
    if denominator == 0.0:
        return 1.0
    return shortest / denominator


def personal_space_compliance_code(
    traj: Trajectory, params: MetricParams = DEFAULT_PARAMS
) -> float:
    """The original code's personal-space compliance, for comparison with its numbers.

    Fraction of the post-step states ``t = 1..T`` in which every human *centre* is at least
    ``code_psc_radius`` (2.02 m) from the robot centre, i.e. ``(t − #violations) / t`` as in the
    DQN test scripts, computed here in the world frame.
    """
    centre = np.linalg.norm(traj.human_xy[1:] - traj.robot_xy[1:, None, :], axis=2)  # (T, H)
    clear = centre >= params.code_psc_radius
    return float(np.all(clear, axis=1).mean())


# --------------------------------------------------------------------------------------------
# Registry
# --------------------------------------------------------------------------------------------

PAPER_METRICS: tuple[str, ...] = (
    "discomfort",
    "distance_travelled",
    "simulation_time",
    "human_collision",
    "max_steps",
    "reward",
    "success",
    "idle_time",
    "personal_space_compliance",
)
"""The paper's nine test metrics, in the paper's order."""

EXTRA_METRICS: tuple[str, ...] = (
    "wall_collision",
    "obstacle_collision",
    "group_crossings",
    "minimum_distance_to_human",
    "time_to_reach_goal",
    "path_length",
    "spl",
    "personal_space_compliance_code",
)
"""Metrics this project adds to the paper's nine."""

ALL_METRICS: tuple[str, ...] = PAPER_METRICS + EXTRA_METRICS

METRIC_FUNCTIONS: dict[str, Callable[[Trajectory, MetricParams], float]] = {
    "discomfort": discomfort,
    "distance_travelled": distance_travelled,
    "simulation_time": simulation_time,
    "human_collision": human_collision,
    "max_steps": max_steps,
    "reward": reward,
    "success": success,
    "idle_time": idle_time,
    "personal_space_compliance": personal_space_compliance,
    "wall_collision": wall_collision,
    "obstacle_collision": obstacle_collision,
    "group_crossings": group_crossings,
    "minimum_distance_to_human": minimum_distance_to_human,
    "time_to_reach_goal": time_to_reach_goal,
    "path_length": path_length,
    "spl": spl,
    "personal_space_compliance_code": personal_space_compliance_code,
}

METRIC_DIRECTIONS: dict[str, str] = {
    # The single place where "better" is declared: "max" = higher is better, "min" = lower is.
    "discomfort": "min",
    # Shorter paths to the same goal are better (an idle robot also travels little, but that is
    # penalised through success / simulation time, not here).
    "distance_travelled": "min",
    "simulation_time": "min",
    "human_collision": "min",
    "max_steps": "min",
    "reward": "max",
    "success": "max",
    "idle_time": "min",
    "personal_space_compliance": "max",
    "wall_collision": "min",
    "obstacle_collision": "min",
    "group_crossings": "min",
    "minimum_distance_to_human": "max",
    "time_to_reach_goal": "min",
    "path_length": "min",
    "spl": "max",
    "personal_space_compliance_code": "max",
}

METRIC_UNITS: dict[str, str] = {
    "discomfort": "steps",
    "distance_travelled": "m",
    "simulation_time": "s",
    "human_collision": "0/1",
    "max_steps": "0/1",
    "reward": "reward",
    "success": "0/1",
    "idle_time": "s",
    "personal_space_compliance": "fraction",
    "wall_collision": "0/1",
    "obstacle_collision": "0/1",
    "group_crossings": "steps",
    "minimum_distance_to_human": "m",
    "time_to_reach_goal": "s",
    "path_length": "m",
    "spl": "fraction",
    "personal_space_compliance_code": "fraction",
}


def episode_metrics(traj: Trajectory, params: MetricParams = DEFAULT_PARAMS) -> dict[str, float]:
    """Every metric of one episode, keyed by name in :data:`ALL_METRICS` order.

    Args:
        traj: the episode (validated when it was constructed).
        params: the metric constants.

    Returns:
        ``{name: value}`` with plain floats; ``time_to_reach_goal`` is NaN for failed episodes
        and ``minimum_distance_to_human`` is ``+inf`` for episodes without humans.
    """
    if not isinstance(traj, Trajectory):
        raise TypeError(f"episode_metrics expects a Trajectory, got {type(traj).__name__}")
    return {name: METRIC_FUNCTIONS[name](traj, params) for name in ALL_METRICS}


def episodes_to_solve(success: Sequence[bool] | np.ndarray, window: int, rate: float) -> int | None:
    """First episode (1-based) at which the mean success of the last ``window`` episodes
    reaches ``rate``; None if it never does. Needs ``window`` complete episodes.

    The paper's "solved in about 3200 episodes" is never defined (paper_spec §8.18); this is the
    project's definition.
    """
    s = np.asarray(success, dtype=np.float64)
    if s.size < window:
        return None
    rolling = np.convolve(s, np.ones(window), mode="valid") / window  # rolling[i] ends at i+window
    hits = np.flatnonzero(rolling >= rate - 1e-12)
    return int(hits[0] + window) if hits.size else None
