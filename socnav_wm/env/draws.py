"""The simulator's random numbers and the placement tests every spawner shares.

Every random number of the simulator is a pure function of ``(seed, scenario_id, stream, i, j,
k)`` (a counter-based generator: SplitMix64 hashing, no hidden state), so scenario ``i`` of a
seed is the same whatever the batch size and whatever slot it runs in. The streams below say
which quantity a draw is for (:mod:`socnav_wm.env.scenario` explains the spawn rules).
"""

from __future__ import annotations

import numba
import numpy as np

from socnav_wm.env.geometry import norm

# Streams: which quantity a draw is for. Changing these values changes every scenario.
STREAM_ROBOT = 1  # robot position (i = 0, j = attempt) and heading (i = 1)
STREAM_ROBOT_GOAL = 2  # robot goal (i = attempt)
STREAM_HUMAN = 3  # human position (i = human, j = attempt), speed, heading
STREAM_HUMAN_GOAL = 4  # human goal (i = human, j = goal index, k = 2·attempt + coordinate)
STREAM_HUMAN_POLICY = 5  # SFM or ORCA per human (i = human)
STREAM_AVOID_ROBOT = 6  # SFM human sees the robot this step (i = human, j = step)
STREAM_OBSTACLE = 7  # obstacle counts (i = 0, j = kind) and positions (i = slot, j = attempt)
STREAM_HUMAN_TRAITS = (
    8  # a human's speed (i = human, j = 0) and whether it ignores the robot (j = 1)
)
STREAM_CROSSING = 9  # crossing families: start (i = human, j = attempt) and goal draws
STREAM_GROUPS = 10  # group counts (i = 0, j = kind), sizes (i = slot + 1) and placements

MAX_SPAWN_ATTEMPTS = 10_000  # attempts per disc at reset (then the reset is an error)
MAX_GOAL_ATTEMPTS = 1_000  # attempts per human-goal redraw during an episode (then: keep the goal)

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)


@numba.njit(cache=True, inline="always")
def _splitmix64(x: np.uint64) -> np.uint64:
    z = x + _GOLDEN
    z = (z ^ (z >> np.uint64(30))) * _MIX1
    z = (z ^ (z >> np.uint64(27))) * _MIX2
    return z ^ (z >> np.uint64(31))


@numba.njit(cache=True, inline="always")
def uniform(seed: int, scenario: int, stream: int, i: int, j: int, k: int) -> float:
    """A uniform number in [0, 1) keyed by its coordinates: same key, same number, always."""
    h = _splitmix64(np.uint64(seed))
    h = _splitmix64(h ^ np.uint64(scenario))
    h = _splitmix64(h ^ np.uint64(stream))
    h = _splitmix64(h ^ np.uint64(i))
    h = _splitmix64(h ^ np.uint64(j))
    h = _splitmix64(h ^ np.uint64(k))
    return float(h >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@numba.njit(cache=True, error_model="numpy")
def uniform_array(seed: int, scenario: np.ndarray, stream: int, i: int, j: int, k: int):
    """`uniform` for an array of scenario ids (used by tests and by numpy-side code)."""
    out = np.empty(scenario.shape[0])
    for n in range(scenario.shape[0]):
        out[n] = uniform(seed, scenario[n], stream, i, j, k)
    return out


@numba.njit(cache=True, inline="always")
def touches_wall(x: float, y: float, radius: float, wall_half: float) -> bool:
    """Whether a disc touches a wall: the walls' inner faces are at ``±wall_half``."""
    return abs(x) + radius >= wall_half or abs(y) + radius >= wall_half


@numba.njit(cache=True, inline="always")
def discs_touch(x: float, y: float, ox: float, oy: float, gap: float) -> bool:
    """Whether two discs whose radii add up to ``gap`` touch (shapely's ``intersects``)."""
    return norm(x - ox, y - oy) <= gap


@numba.njit(cache=True)
def count_in_range(seed: int, scenario: int, stream: int, kind: int, low: int, high: int) -> int:
    """A count uniform in [low, high]: draw ``(stream, 0, kind)`` of the scenario."""
    u = uniform(seed, scenario, stream, 0, kind, 0)
    return low + min(high - low, int(u * (high - low + 1)))
