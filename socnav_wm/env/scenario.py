"""Scenarios: seeded spawning of robot, goal and humans, and the random draws of an episode.

Every random number of the simulator is a pure function of ``(seed, scenario_id, stream, i, j,
k)`` (a counter-based generator: SplitMix64 hashing, no hidden state). So scenario ``i`` of a seed
is the same whatever the batch size and whatever slot it runs in: the evaluation pairs methods on
identical scenarios, and that holds by construction rather than by careful ordering of calls to
a stateful generator.

Spawn rules (the paper env's ``reset()`` and ``sample_goal``, paper_spec §1). Every position is
uniform in ``±spawn_half_size`` and every object is a disc: robot ``robot_radius``, human
``human_radius``, robot goal ``goal_radius``, human goal ``human_goal_radius``. A disc is redrawn
(attempt 0, 1, … of its own counter key) while it *touches* a wall (``|x| + r ≥ wall_half_size``
or the same in y) or anything placed before it (centre distance ≤ sum of radii), in the paper
env's order:

1. robot: walls only; its heading is one draw;
2. humans, in order: walls, robot, earlier humans;
3. human goals, in order: walls, robot, every human, earlier human goals;
4. robot goal: walls, robot (and at least ``min_goal_distance`` away), every human, every human
   goal; so no episode starts solved and no goal starts under a human.

At reset each disc has ``MAX_SPAWN_ATTEMPTS`` attempts; running out is an error (the room is too
full). During an episode, a human that reaches its goal draws the next one
(``redraw_human_goal``) under the rule of the paper env's ``update_goal``: walls, the robot's
and every human's *current* position, every human goal (its own old one included) and the robot
goal. That takes at most ``MAX_GOAL_ATTEMPTS`` attempts; if all fail the human keeps its goal and,
still being at it, tries again at the next step with the next goal index.

Differences that remain from the paper env:

- shapely tests polygons (a circle is a 64-gon inscribed in it, so discs are up to 0.1 % of a
  radius smaller there); these tests use exact circles;
- the paper env retries until a 30 s timeout and then restarts the whole reset (or, during an
  episode, keeps the old goal and removes it from its goal list); here the bounds are attempt
  counts, and a human that keeps its goal still blocks other goals;
- the paper env draws the robot heading and each human's speed, heading and policy once per
  attempt; here they are one draw each, independent of the positions;
- humans move one after the other there; here all move, then goals are redrawn in human order
  (so a redraw sees every human's new position);
- because redrawn goals avoid the robot, a human's goal sequence (and so its path) can depend on
  the robot's trajectory: scenarios are identical at reset whatever the policy, and human paths
  stay identical only while no redraw attempt is rejected because of the robot's disc.
"""

from __future__ import annotations

import math

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

POLICY_SFM = 0
POLICY_ORCA = 1
POLICY_CODES = {"sfm": POLICY_SFM, "orca": POLICY_ORCA}

MAX_SPAWN_ATTEMPTS = 10_000  # attempts per disc at reset (then the reset is an error)
MAX_GOAL_ATTEMPTS = 1_000  # attempts per human-goal redraw during an episode (then: keep the goal)
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
    seed: int, scenario: int, human: int, goal_index: int, attempt: int, half: float
) -> tuple[float, float]:
    """Attempt ``attempt`` at the ``goal_index``-th goal of a human: uniform in ``[-half, half]²``.

    ``k = 2·attempt + coordinate`` keys the draw, so attempt 0 is the draw of earlier versions.
    """
    ux = uniform(seed, scenario, STREAM_HUMAN_GOAL, human, goal_index, 2 * attempt)
    uy = uniform(seed, scenario, STREAM_HUMAN_GOAL, human, goal_index, 2 * attempt + 1)
    return (2.0 * ux - 1.0) * half, (2.0 * uy - 1.0) * half


@numba.njit(cache=True, inline="always")
def touches_wall(x: float, y: float, radius: float, wall_half: float) -> bool:
    """Whether a disc touches a wall: the walls' inner faces are at ``±wall_half``."""
    return abs(x) + radius >= wall_half or abs(y) + radius >= wall_half


@numba.njit(cache=True, inline="always")
def _discs_touch(x: float, y: float, ox: float, oy: float, gap: float) -> bool:
    """Whether two discs whose radii add up to ``gap`` touch (shapely's ``intersects``)."""
    return norm(x - ox, y - oy) <= gap


@numba.njit(cache=True)
def human_goal_is_free(
    e: int,
    gx: float,
    gy: float,
    goal_radius: float,
    wall_half: float,
    robot_xy: np.ndarray,
    robot_radius: float,
    human_xy: np.ndarray,
    human_radius: float,
    human_goal: np.ndarray,
    num_goals: int,
    robot_goal_xy: np.ndarray,
    robot_goal_radius: float,
    with_robot_goal: bool,
) -> bool:
    """Whether a human-goal disc at (gx, gy) of env ``e`` touches nothing (the paper env's
    ``sample_goal``): no wall, not the robot, no human, none of the first ``num_goals`` human
    goals, and, if ``with_robot_goal``, not the robot's goal. Positions are the current ones."""
    if touches_wall(gx, gy, goal_radius, wall_half):
        return False
    if _discs_touch(gx, gy, robot_xy[e, 0], robot_xy[e, 1], goal_radius + robot_radius):
        return False
    for h in range(human_xy.shape[1]):
        if _discs_touch(gx, gy, human_xy[e, h, 0], human_xy[e, h, 1], goal_radius + human_radius):
            return False
    for j in range(num_goals):
        if _discs_touch(gx, gy, human_goal[e, j, 0], human_goal[e, j, 1], 2.0 * goal_radius):
            return False
    robot_goal_gap = goal_radius + robot_goal_radius
    return not with_robot_goal or not _discs_touch(
        gx, gy, robot_goal_xy[e, 0], robot_goal_xy[e, 1], robot_goal_gap
    )


@numba.njit(cache=True, error_model="numpy")
def spawn(
    envs: np.ndarray,
    seed: int,
    scenario_ids: np.ndarray,
    policy_mode: int,
    half: float,
    wall_half: float,
    robot_radius: float,
    human_radius: float,
    human_max_speed: float,
    goal_radius: float,
    human_goal_radius: float,
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

    The paper environment's ``reset()`` (see the module docstring): positions uniform in
    ``[-half, half]²`` (m), each disc redrawn while it touches a wall (inner faces at
    ``±wall_half``) or anything placed before it, in the order robot, humans, human goals,
    robot goal. The robot goal is also kept farther than ``min_goal_distance`` from the robot.
    ``policy_mode`` is -1 for a 50/50 SFM/ORCA draw per human, else the policy code for all.
    Returns the number of discs that ran out of attempts (0 unless the room is full).
    """
    num_humans = human_xy.shape[1]
    failures = 0
    for n in range(envs.shape[0]):
        e = envs[n]
        s = scenario_ids[n]
        # 1. Robot: off the walls.
        placed = False
        for attempt in range(MAX_SPAWN_ATTEMPTS):
            rx = (2.0 * uniform(seed, s, STREAM_ROBOT, 0, attempt, 0) - 1.0) * half
            ry = (2.0 * uniform(seed, s, STREAM_ROBOT, 0, attempt, 1) - 1.0) * half
            robot_xy[e, 0] = rx
            robot_xy[e, 1] = ry
            if not touches_wall(rx, ry, robot_radius, wall_half):
                placed = True
                break
        if not placed:
            failures += 1
        robot_theta[e] = (2.0 * uniform(seed, s, STREAM_ROBOT, 1, 0, 0) - 1.0) * math.pi
        # 2. Humans: off the walls, the robot and the humans placed before.
        for h in range(num_humans):
            placed = False
            for attempt in range(MAX_SPAWN_ATTEMPTS):
                hx = (2.0 * uniform(seed, s, STREAM_HUMAN, h, attempt, 0) - 1.0) * half
                hy = (2.0 * uniform(seed, s, STREAM_HUMAN, h, attempt, 1) - 1.0) * half
                ok = not touches_wall(hx, hy, human_radius, wall_half) and not _discs_touch(
                    hx, hy, robot_xy[e, 0], robot_xy[e, 1], robot_radius + human_radius
                )
                for other in range(h):
                    if ok and _discs_touch(
                        hx, hy, human_xy[e, other, 0], human_xy[e, other, 1], 2.0 * human_radius
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
            if policy_mode < 0:
                coin = uniform(seed, s, STREAM_HUMAN_POLICY, h, 0, 0)
                human_policy[e, h] = POLICY_ORCA if coin < 0.5 else POLICY_SFM
            else:
                human_policy[e, h] = policy_mode
        # 3. Human goals: off the walls, the robot, every human and the goals drawn before.
        for h in range(num_humans):
            placed = False
            for attempt in range(MAX_SPAWN_ATTEMPTS):
                gx, gy = draw_human_goal(seed, s, h, 0, attempt, half)
                if human_goal_is_free(
                    e, gx, gy, human_goal_radius, wall_half, robot_xy, robot_radius, human_xy,
                    human_radius, human_goal, h, goal_xy, goal_radius, False,
                ):  # fmt: skip
                    placed = True
                    break
            if not placed:
                failures += 1
            human_goal[e, h, 0] = gx
            human_goal[e, h, 1] = gy
            human_goal_index[e, h] = 0
        # 4. Robot goal: off the walls, the robot, every human and every human goal.
        robot_gap = max(min_goal_distance, goal_radius + robot_radius)
        placed = False
        for attempt in range(MAX_SPAWN_ATTEMPTS):
            gx = (2.0 * uniform(seed, s, STREAM_ROBOT_GOAL, attempt, 0, 0) - 1.0) * half
            gy = (2.0 * uniform(seed, s, STREAM_ROBOT_GOAL, attempt, 0, 1) - 1.0) * half
            ok = not touches_wall(gx, gy, goal_radius, wall_half) and not _discs_touch(
                gx, gy, robot_xy[e, 0], robot_xy[e, 1], robot_gap
            )
            human_gap = goal_radius + human_radius
            goal_gap = goal_radius + human_goal_radius
            for h in range(num_humans):
                if ok and (
                    _discs_touch(gx, gy, human_xy[e, h, 0], human_xy[e, h, 1], human_gap)
                    or _discs_touch(gx, gy, human_goal[e, h, 0], human_goal[e, h, 1], goal_gap)
                ):
                    ok = False
            if ok:
                placed = True
                break
        if not placed:
            failures += 1
        goal_xy[e, 0] = gx
        goal_xy[e, 1] = gy
    return failures


@numba.njit(cache=True, inline="always")
def redraw_human_goal(
    seed: int,
    scenario: int,
    e: int,
    h: int,
    goal_index: int,
    half: float,
    goal_radius: float,
    wall_half: float,
    robot_xy: np.ndarray,
    robot_radius: float,
    human_xy: np.ndarray,
    human_radius: float,
    human_goal: np.ndarray,
    robot_goal_xy: np.ndarray,
    robot_goal_radius: float,
) -> bool:
    """Give human ``h`` of env ``e`` its ``goal_index``-th goal during an episode.

    As the paper env's ``update_goal``: the goal disc is redrawn while it touches a wall, the
    robot or any human at their current positions, any human goal (this human's old one
    included, as it is still in the env's goal list while the new one is drawn) or the robot
    goal. After ``MAX_GOAL_ATTEMPTS`` failed attempts the human keeps its old goal (the paper
    env's ``sample_goal`` timing out) and returns False; it is still at that goal, so it draws
    again at the next step, with the next goal index.
    """
    for attempt in range(MAX_GOAL_ATTEMPTS):
        gx, gy = draw_human_goal(seed, scenario, h, goal_index, attempt, half)
        if human_goal_is_free(
            e, gx, gy, goal_radius, wall_half, robot_xy, robot_radius, human_xy, human_radius,
            human_goal, human_goal.shape[1], robot_goal_xy, robot_goal_radius, True,
        ):  # fmt: skip
            human_goal[e, h, 0] = gx
            human_goal[e, h, 1] = gy
            return True
    return False
