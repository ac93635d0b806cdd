"""CrowdNav's crossing scenarios: ``circle_crossing`` and ``square_crossing``."""

from __future__ import annotations

import math

import numba
import numpy as np

from socnav_wm.env.draws import MAX_SPAWN_ATTEMPTS, STREAM_CROSSING, uniform
from socnav_wm.env.geometry import norm
from socnav_wm.env.scenario import human_traits


@numba.njit(cache=True, error_model="numpy")
def spawn_crossing(
    envs: np.ndarray,
    seed: int,
    scenario_ids: np.ndarray,
    policy_mode: int,
    family: int,
    radius: float,
    noise: float,
    robot_radius: float,
    human_radius: float,
    human_max_speed: float,
    discomfort: float,
    speed_range: np.ndarray,
    sees_mode: int,
    ignore_prob: float,
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
) -> int:
    """CrowdNav's crossing scenarios (``circle_crossing``: family 1, ``square_crossing``: 2).

    The robot starts at (0, −R) facing +y, its goal at (0, R). Each human in turn:

    - circle: at angle U·2π on the circle of radius R, moved by up to ±``noise`` in x and y;
      its goal is the opposite point (the start mirrored through the centre);
    - square: on a random side x = ±U·R, y uniform in ±R; its goal on the other side, drawn
      the same way;

    redrawn while its start is within ``2·human_radius + discomfort`` (robot: its radius
    instead of one human radius) of the robot's start, an earlier human's start or goal, or
    (circle) its goal is as close to theirs. Humans start at rest, facing their goal.
    """
    num_humans = human_xy.shape[1]
    failures = 0
    for n in range(envs.shape[0]):
        e = envs[n]
        s = scenario_ids[n]
        robot_xy[e, 0] = 0.0
        robot_xy[e, 1] = -radius
        robot_theta[e] = 0.5 * math.pi
        goal_xy[e, 0] = 0.0
        goal_xy[e, 1] = radius
        for h in range(num_humans):
            human_traits(
                e, seed, s, h, policy_mode, human_max_speed, speed_range, sees_mode, ignore_prob,
                human_max_speeds, human_policy, human_sees_robot,
            )  # fmt: skip
            placed = False
            px = py = gx = gy = 0.0
            for attempt in range(MAX_SPAWN_ATTEMPTS):
                u0 = uniform(seed, s, STREAM_CROSSING, h, attempt, 0)
                u1 = uniform(seed, s, STREAM_CROSSING, h, attempt, 1)
                u2 = uniform(seed, s, STREAM_CROSSING, h, attempt, 2)
                if family == 1:
                    angle = u0 * 2.0 * math.pi
                    px = radius * math.cos(angle) + (2.0 * u1 - 1.0) * noise
                    py = radius * math.sin(angle) + (2.0 * u2 - 1.0) * noise
                    gx = -px
                    gy = -py
                else:
                    side = 1.0 if u0 > 0.5 else -1.0
                    px = u1 * radius * side
                    py = (2.0 * u2 - 1.0) * radius
                    gx = uniform(seed, s, STREAM_CROSSING, h, attempt, 3) * radius * -side
                    gy = (2.0 * uniform(seed, s, STREAM_CROSSING, h, attempt, 4) - 1.0) * radius
                gap = human_radius + robot_radius + discomfort
                ok = norm(px - robot_xy[e, 0], py - robot_xy[e, 1]) >= gap
                ok = ok and norm(gx - goal_xy[e, 0], gy - goal_xy[e, 1]) >= gap
                gap = 2.0 * human_radius + discomfort
                for other in range(h):
                    if not ok:
                        break
                    ox = human_xy[e, other, 0]
                    oy = human_xy[e, other, 1]
                    qx = human_goal[e, other, 0]
                    qy = human_goal[e, other, 1]
                    ok = norm(px - ox, py - oy) >= gap and norm(px - qx, py - qy) >= gap
                    ok = ok and norm(gx - qx, gy - qy) >= gap and norm(gx - ox, gy - oy) >= gap
                if ok:
                    placed = True
                    break
            if not placed:
                failures += 1
            human_xy[e, h, 0] = px
            human_xy[e, h, 1] = py
            human_goal[e, h, 0] = gx
            human_goal[e, h, 1] = gy
            human_goal_index[e, h] = 0
            human_speed[e, h] = 0.0
            d = norm(gx - px, gy - py)
            human_heading[e, h, 0] = (gx - px) / d if d > 0.0 else 1.0
            human_heading[e, h, 1] = (gy - py) / d if d > 0.0 else 0.0
    return failures
