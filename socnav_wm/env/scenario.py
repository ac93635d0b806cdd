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

from socnav_wm.env.draws import (
    MAX_GOAL_ATTEMPTS,
    MAX_SPAWN_ATTEMPTS,
    STREAM_HUMAN,
    STREAM_HUMAN_GOAL,
    STREAM_HUMAN_POLICY,
    STREAM_HUMAN_TRAITS,
    STREAM_OBSTACLE,
    STREAM_ROBOT,
    STREAM_ROBOT_GOAL,
    count_in_range,
    discs_touch,
    touches_wall,
    uniform,
)
from socnav_wm.env.groups import assign_groups, place_group_member
from socnav_wm.env.obstacles import disc_clearance
from socnav_wm.env.state import OBSTACLE_NONE, OBSTACLE_PLANT, OBSTACLE_TABLE

FAMILY_CODES = {"room": 0, "circle_crossing": 1, "square_crossing": 2}
SEES_PAPER = 0  # humans_see_robot: paper
SEES_NEVER = 1  # false
SEES_ALWAYS = 2  # true
SEES_CODES = {"paper": SEES_PAPER, False: SEES_NEVER, True: SEES_ALWAYS}

POLICY_SFM = 0
POLICY_ORCA = 1
POLICY_CODES = {"sfm": POLICY_SFM, "orca": POLICY_ORCA}

OBSTACLE_GAP = 2.0  # obstacles keep this many human radii from each other and from the walls
_KINEMATICS = MAX_SPAWN_ATTEMPTS  # j index of a human's initial speed/heading draws


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
    obstacle_kind: np.ndarray,
    obstacle_xy: np.ndarray,
    obstacle_half: np.ndarray,
) -> bool:
    """Whether a human-goal disc at (gx, gy) of env ``e`` touches nothing (the paper env's
    ``sample_goal``): no wall, not the robot, no human, none of the first ``num_goals`` human
    goals, and, if ``with_robot_goal``, not the robot's goal. Positions are the current ones."""
    if touches_wall(gx, gy, goal_radius, wall_half):
        return False
    if disc_clearance(e, gx, gy, goal_radius, obstacle_kind, obstacle_xy, obstacle_half) <= 0.0:
        return False
    if discs_touch(gx, gy, robot_xy[e, 0], robot_xy[e, 1], goal_radius + robot_radius):
        return False
    for h in range(human_xy.shape[1]):
        if discs_touch(gx, gy, human_xy[e, h, 0], human_xy[e, h, 1], goal_radius + human_radius):
            return False
    for j in range(num_goals):
        if discs_touch(gx, gy, human_goal[e, j, 0], human_goal[e, j, 1], 2.0 * goal_radius):
            return False
    robot_goal_gap = goal_radius + robot_goal_radius
    return not with_robot_goal or not discs_touch(
        gx, gy, robot_goal_xy[e, 0], robot_goal_xy[e, 1], robot_goal_gap
    )


@numba.njit(cache=True, error_model="numpy")
def spawn_obstacles(
    e: int,
    seed: int,
    s: int,
    counts: np.ndarray,
    table_half: np.ndarray,
    plant_radius: float,
    wall_half: float,
    gap: float,
    kind: np.ndarray,
    xy: np.ndarray,
    half: np.ndarray,
) -> int:
    """Place scenario ``s``'s tables, then its plants, in slot ``e``: each uniform where it keeps
    ``gap`` from the walls and (enclosing circles) from the obstacles placed before; ``counts``
    is [low, high] of tables then of plants. Returns the obstacles that found no place."""
    failures = 0
    kind[e, :] = OBSTACLE_NONE
    slot = 0
    for which in range(2):
        code = OBSTACLE_TABLE if which == 0 else OBSTACLE_PLANT
        hx = table_half[0] if which == 0 else plant_radius
        hy = table_half[1] if which == 0 else plant_radius
        reach = math.sqrt(hx * hx + hy * hy) if which == 0 else plant_radius
        span_x = wall_half - gap - hx
        span_y = wall_half - gap - hy
        for _ in range(
            count_in_range(
                seed, s, STREAM_OBSTACLE, which, counts[2 * which], counts[2 * which + 1]
            )
        ):
            placed = False
            for attempt in range(MAX_SPAWN_ATTEMPTS):
                cx = (2.0 * uniform(seed, s, STREAM_OBSTACLE, slot + 1, attempt, 0) - 1.0) * span_x
                cy = (2.0 * uniform(seed, s, STREAM_OBSTACLE, slot + 1, attempt, 1) - 1.0) * span_y
                ok = span_x > 0.0 and span_y > 0.0
                for other in range(slot):
                    other_reach = math.sqrt(half[e, other, 0] ** 2 + half[e, other, 1] ** 2)
                    if kind[e, other] == OBSTACLE_PLANT:
                        other_reach = half[e, other, 0]
                    if ok and discs_touch(cx, cy, xy[e, other, 0], xy[e, other, 1],
                                           reach + other_reach + gap):  # fmt: skip
                        ok = False
                if ok:
                    placed = True
                    break
            if not placed:
                failures += 1
                continue
            kind[e, slot] = code
            xy[e, slot, 0] = cx
            xy[e, slot, 1] = cy
            half[e, slot, 0] = hx
            half[e, slot, 1] = hy
            slot += 1
    return failures


@numba.njit(cache=True, error_model="numpy")
def human_traits(
    e: int,
    seed: int,
    s: int,
    h: int,
    policy_mode: int,
    max_speed: float,
    speed_range: np.ndarray,
    sees_mode: int,
    ignore_prob: float,
    human_max_speed: np.ndarray,
    human_policy: np.ndarray,
    human_sees_robot: np.ndarray,
) -> None:
    """A human's policy, preferred speed and whether it sees the robot this episode."""
    if policy_mode < 0:
        coin = uniform(seed, s, STREAM_HUMAN_POLICY, h, 0, 0)
        human_policy[e, h] = POLICY_ORCA if coin < 0.5 else POLICY_SFM
    else:
        human_policy[e, h] = policy_mode
    if speed_range[1] > 0.0:
        u = uniform(seed, s, STREAM_HUMAN_TRAITS, h, 0, 0)
        human_max_speed[e, h] = speed_range[0] + u * (speed_range[1] - speed_range[0])
    else:
        human_max_speed[e, h] = max_speed
    if sees_mode == SEES_ALWAYS:
        human_sees_robot[e, h] = uniform(seed, s, STREAM_HUMAN_TRAITS, h, 1, 0) >= ignore_prob
    else:
        human_sees_robot[e, h] = False


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
    speed_range: np.ndarray,
    sees_mode: int,
    ignore_prob: float,
    obstacle_counts: np.ndarray,
    table_half: np.ndarray,
    plant_radius: float,
    group_counts: np.ndarray,
    group_sizes: np.ndarray,
    robot_xy: np.ndarray,
    robot_theta: np.ndarray,
    goal_xy: np.ndarray,
    human_xy: np.ndarray,
    human_heading: np.ndarray,
    human_speed: np.ndarray,
    human_goal: np.ndarray,
    human_goal_index: np.ndarray,
    human_policy: np.ndarray,
    human_max_speeds: np.ndarray,
    human_sees_robot: np.ndarray,
    obstacle_kind: np.ndarray,
    obstacle_xy: np.ndarray,
    obstacle_half: np.ndarray,
    human_group: np.ndarray,
    group_leader: np.ndarray,
    group_standing: np.ndarray,
) -> int:
    """Draw the initial state of scenario ``scenario_ids[n]`` (the ``room`` family) into slot
    ``envs[n]``.

    The paper environment's ``reset()`` (see the module docstring): positions uniform in
    ``[-half, half]²`` (m), each disc redrawn while it touches a wall (inner faces at
    ``±wall_half``), an obstacle or anything placed before it, in the order obstacles, robot,
    humans, human goals, robot goal. The robot goal is also kept farther than
    ``min_goal_distance`` from the robot. ``policy_mode`` is -1 for a 50/50 SFM/ORCA draw per
    human, else the policy code for all; ``speed_range`` [low, high] of the humans' preferred
    speeds ([0, 0]: all ``human_max_speed``). Returns the number of discs that ran out of
    attempts (0 unless the room is full).
    """
    num_humans = human_xy.shape[1]
    failures = 0
    gap = OBSTACLE_GAP * human_radius
    for n in range(envs.shape[0]):
        e = envs[n]
        s = scenario_ids[n]
        if obstacle_kind.shape[1]:
            failures += spawn_obstacles(
                e, seed, s, obstacle_counts, table_half, plant_radius, wall_half, gap,
                obstacle_kind, obstacle_xy, obstacle_half,
            )  # fmt: skip
        # 1. Robot: off the walls and the obstacles.
        placed = False
        for attempt in range(MAX_SPAWN_ATTEMPTS):
            rx = (2.0 * uniform(seed, s, STREAM_ROBOT, 0, attempt, 0) - 1.0) * half
            ry = (2.0 * uniform(seed, s, STREAM_ROBOT, 0, attempt, 1) - 1.0) * half
            robot_xy[e, 0] = rx
            robot_xy[e, 1] = ry
            if (
                not touches_wall(rx, ry, robot_radius, wall_half)
                and disc_clearance(
                    e, rx, ry, robot_radius, obstacle_kind, obstacle_xy, obstacle_half
                )
                > 0.0
            ):
                placed = True
                break
        if not placed:
            failures += 1
        robot_theta[e] = (2.0 * uniform(seed, s, STREAM_ROBOT, 1, 0, 0) - 1.0) * math.pi
        # 2. Humans: off the walls, the obstacles, the robot and the humans placed before; a
        # group's members beside their leader or on their circle.
        if group_leader.shape[1]:
            assign_groups(e, seed, s, num_humans, group_counts, group_sizes, human_group,
                          group_leader, group_standing)  # fmt: skip
        for h in range(num_humans):
            human_traits(
                e, seed, s, h, policy_mode, human_max_speed, speed_range, sees_mode, ignore_prob,
                human_max_speeds, human_policy, human_sees_robot,
            )  # fmt: skip
            heading = (2.0 * uniform(seed, s, STREAM_HUMAN, h, _KINEMATICS, 1) - 1.0) * math.pi
            group = human_group[e, h]
            if group >= 0 and (group_standing[e, group] or group_leader[e, group] != h):
                if not place_group_member(
                    e, seed, s, h, half, wall_half, robot_xy, robot_radius, human_xy,
                    human_radius, human_group, group_leader, group_standing, human_heading,
                    obstacle_kind, obstacle_xy, obstacle_half,
                ):  # fmt: skip
                    failures += 1
                standing = group_standing[e, group]
                human_speed[e, h] = 0.0 if standing else (
                    uniform(seed, s, STREAM_HUMAN, h, _KINEMATICS, 0) * human_max_speeds[e, h]
                )  # fmt: skip
                continue
            placed = False
            for attempt in range(MAX_SPAWN_ATTEMPTS):
                hx = (2.0 * uniform(seed, s, STREAM_HUMAN, h, attempt, 0) - 1.0) * half
                hy = (2.0 * uniform(seed, s, STREAM_HUMAN, h, attempt, 1) - 1.0) * half
                ok = not touches_wall(hx, hy, human_radius, wall_half) and not discs_touch(
                    hx, hy, robot_xy[e, 0], robot_xy[e, 1], robot_radius + human_radius
                )
                ok = (
                    ok
                    and disc_clearance(
                        e, hx, hy, human_radius, obstacle_kind, obstacle_xy, obstacle_half
                    )
                    > 0.0
                )
                for other in range(h):
                    if ok and discs_touch(
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
            human_speed[e, h] = (
                uniform(seed, s, STREAM_HUMAN, h, _KINEMATICS, 0) * human_max_speeds[e, h]
            )
            human_heading[e, h, 0] = math.cos(heading)
            human_heading[e, h, 1] = math.sin(heading)
        # 3. Human goals: off the walls, the obstacles, the robot, every human and the goals
        # drawn before.
        for h in range(num_humans):
            human_goal_index[e, h] = 0
            group = human_group[e, h]
            if group >= 0 and group_standing[e, group]:  # a conversation: where it stands
                human_goal[e, h, 0] = human_xy[e, h, 0]
                human_goal[e, h, 1] = human_xy[e, h, 1]
                continue
            if group >= 0 and group_leader[e, group] != h:  # the group's shared goal
                human_goal[e, h, 0] = human_goal[e, group_leader[e, group], 0]
                human_goal[e, h, 1] = human_goal[e, group_leader[e, group], 1]
                continue
            placed = False
            for attempt in range(MAX_SPAWN_ATTEMPTS):
                gx, gy = draw_human_goal(seed, s, h, 0, attempt, half)
                if human_goal_is_free(
                    e, gx, gy, human_goal_radius, wall_half, robot_xy, robot_radius, human_xy,
                    human_radius, human_goal, h, goal_xy, goal_radius, False, obstacle_kind,
                    obstacle_xy, obstacle_half,
                ):  # fmt: skip
                    placed = True
                    break
            if not placed:
                failures += 1
            human_goal[e, h, 0] = gx
            human_goal[e, h, 1] = gy
        # 4. Robot goal: off the walls, the obstacles, the robot, every human and human goal.
        robot_gap = max(min_goal_distance, goal_radius + robot_radius)
        placed = False
        for attempt in range(MAX_SPAWN_ATTEMPTS):
            gx = (2.0 * uniform(seed, s, STREAM_ROBOT_GOAL, attempt, 0, 0) - 1.0) * half
            gy = (2.0 * uniform(seed, s, STREAM_ROBOT_GOAL, attempt, 0, 1) - 1.0) * half
            ok = not touches_wall(gx, gy, goal_radius, wall_half) and not discs_touch(
                gx, gy, robot_xy[e, 0], robot_xy[e, 1], robot_gap
            )
            ok = (
                ok
                and disc_clearance(
                    e, gx, gy, goal_radius, obstacle_kind, obstacle_xy, obstacle_half
                )
                > 0.0
            )
            human_gap = goal_radius + human_radius
            goal_gap = goal_radius + human_goal_radius
            for h in range(num_humans):
                if ok and (
                    discs_touch(gx, gy, human_xy[e, h, 0], human_xy[e, h, 1], human_gap)
                    or discs_touch(gx, gy, human_goal[e, h, 0], human_goal[e, h, 1], goal_gap)
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
    obstacle_kind: np.ndarray,
    obstacle_xy: np.ndarray,
    obstacle_half: np.ndarray,
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
            obstacle_kind, obstacle_xy, obstacle_half,
        ):  # fmt: skip
            human_goal[e, h, 0] = gx
            human_goal[e, h, 1] = gy
            return True
    return False
