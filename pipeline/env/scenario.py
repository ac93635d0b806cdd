"""Scenarios: seeded spawning of robot, goal and humans, and the random draws of an episode.

Every random number of the simulator is a pure function of ``(seed, scenario_id, stream, i, j)``
(a counter-based generator: SplitMix64 hashing, no hidden state). So scenario ``i`` of a seed is
the same whatever the batch size, whatever slot it runs in and whatever the policy does: the
evaluation pairs methods on identical scenarios, and that holds by construction rather than by
careful ordering of calls to a stateful generator.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from pipeline.env.geometry import norm

# Streams: which quantity a draw is for. Changing these values changes every scenario.
STREAM_ROBOT = 1  # robot position (i = attempt) and heading
STREAM_ROBOT_GOAL = 2  # robot goal (i = attempt)
STREAM_HUMAN = 3  # human position (i = human, j = attempt), speed, heading
STREAM_HUMAN_GOAL = 4  # human goal (i = human, j = goal index)
STREAM_HUMAN_POLICY = 5  # SFM or ORCA per human (i = human)
STREAM_AVOID_ROBOT = 6  # SFM human sees the robot this step (i = human, j = step)

POLICY_SFM = 0
POLICY_ORCA = 1
POLICY_CODES = {"sfm": POLICY_SFM, "orca": POLICY_ORCA}

MAX_SPAWN_ATTEMPTS = 10_000
_KINEMATICS = MAX_SPAWN_ATTEMPTS  # j index of a human's initial speed/heading draws

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
def draw_human_goal(
    seed: int, scenario: int, human: int, goal_index: int, half: float
) -> tuple[float, float]:
    """The `goal_index`-th goal of a human: uniform in the spawn square of half-side `half`."""
    gx = (2.0 * uniform(seed, scenario, STREAM_HUMAN_GOAL, human, goal_index, 0) - 1.0) * half
    gy = (2.0 * uniform(seed, scenario, STREAM_HUMAN_GOAL, human, goal_index, 1) - 1.0) * half
    return gx, gy


@numba.njit(cache=True, error_model="numpy")
def spawn(
    envs: np.ndarray,
    seed: int,
    scenario_ids: np.ndarray,
    policy_mode: int,
    half: float,
    robot_radius: float,
    human_radius: float,
    human_max_speed: float,
    min_goal_distance: float,
    robot_xy: np.ndarray,
    robot_theta: np.ndarray,
    goal_xy: np.ndarray,
    human_xy: np.ndarray,
    human_heading: np.ndarray,
    human_speed: np.ndarray,
    human_goal: np.ndarray,
    human_goal_index: np.ndarray,
    human_policy: np.ndarray,
) -> int:
    """Draw the initial state of scenario ``scenario_ids[n]`` into slot ``envs[n]``.

    Positions are uniform in ``[-half, half]²`` (m) and redrawn on overlap, as in the paper's
    environment: the goal is farther than ``min_goal_distance`` from the robot (the caller
    passes at least the success distance, so no episode starts solved), and humans overlap
    neither the robot nor each other.
    ``policy_mode`` is -1 for a 50/50 SFM/ORCA draw per human, else the policy code for all.
    Returns the number of slots whose spawning ran out of attempts (0 unless the room is full).
    """
    num_humans = human_xy.shape[1]
    failures = 0
    for n in range(envs.shape[0]):
        e = envs[n]
        s = scenario_ids[n]
        robot_xy[e, 0] = (2.0 * uniform(seed, s, STREAM_ROBOT, 0, 0, 0) - 1.0) * half
        robot_xy[e, 1] = (2.0 * uniform(seed, s, STREAM_ROBOT, 0, 0, 1) - 1.0) * half
        robot_theta[e] = (2.0 * uniform(seed, s, STREAM_ROBOT, 1, 0, 0) - 1.0) * math.pi
        placed = False
        for attempt in range(MAX_SPAWN_ATTEMPTS):
            gx = (2.0 * uniform(seed, s, STREAM_ROBOT_GOAL, attempt, 0, 0) - 1.0) * half
            gy = (2.0 * uniform(seed, s, STREAM_ROBOT_GOAL, attempt, 0, 1) - 1.0) * half
            if norm(gx - robot_xy[e, 0], gy - robot_xy[e, 1]) > min_goal_distance:
                goal_xy[e, 0] = gx
                goal_xy[e, 1] = gy
                placed = True
                break
        if not placed:
            failures += 1
        for h in range(num_humans):
            placed = False
            for attempt in range(MAX_SPAWN_ATTEMPTS):
                hx = (2.0 * uniform(seed, s, STREAM_HUMAN, h, attempt, 0) - 1.0) * half
                hy = (2.0 * uniform(seed, s, STREAM_HUMAN, h, attempt, 1) - 1.0) * half
                ok = norm(hx - robot_xy[e, 0], hy - robot_xy[e, 1]) > (robot_radius + human_radius)
                for other in range(h):
                    if ok and norm(hx - human_xy[e, other, 0], hy - human_xy[e, other, 1]) <= (
                        2.0 * human_radius
                    ):
                        ok = False
                if ok:
                    human_xy[e, h, 0] = hx
                    human_xy[e, h, 1] = hy
                    placed = True
                    break
            if not placed:
                failures += 1
            human_speed[e, h] = uniform(seed, s, STREAM_HUMAN, h, _KINEMATICS, 0) * human_max_speed
            heading = (2.0 * uniform(seed, s, STREAM_HUMAN, h, _KINEMATICS, 1) - 1.0) * math.pi
            human_heading[e, h, 0] = math.cos(heading)
            human_heading[e, h, 1] = math.sin(heading)
            gx, gy = draw_human_goal(seed, s, h, 0, half)
            human_goal[e, h, 0] = gx
            human_goal[e, h, 1] = gy
            human_goal_index[e, h] = 0
            if policy_mode < 0:
                coin = uniform(seed, s, STREAM_HUMAN_POLICY, h, 0, 0)
                human_policy[e, h] = POLICY_ORCA if coin < 0.5 else POLICY_SFM
            else:
                human_policy[e, h] = policy_mode
    return failures
