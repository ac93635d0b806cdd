"""The robot-frame observation vector of paper_spec §2 (23 values for 3 humans).

Layout: ``[goal_x, goal_y]`` then, for each of K human slots (``env.observed_humans``; every
human in spawn order by default),
``[x, y, sin(θ_h − θ_r), cos(θ_h − θ_r), radius, ‖v_h − v_r‖, −ω_r]``, then for each of M
obstacle slots (``env.observed_obstacles``, 0 by default) ``[x, y, size, present]``; positions
in metres in the robot frame (x forward, y to the left), speeds in m/s, ω in rad/s. Nothing is
normalised.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from socnav_wm.env.geometry import norm
from socnav_wm.env.obstacles import slot_nearest_point
from socnav_wm.env.state import OBSTACLE_NONE, OBSTACLE_TABLE


@numba.njit(cache=True, error_model="numpy")
def _nearest_first(dx: np.ndarray, dy: np.ndarray, count: int, order: np.ndarray) -> None:
    """``order[:count]``: indices of the entries sorted by distance (stable insertion sort)."""
    for i in range(count):
        d = dx[i] * dx[i] + dy[i] * dy[i]
        j = i
        while j > 0:
            k = order[j - 1]
            if dx[k] * dx[k] + dy[k] * dy[k] <= d:
                break
            order[j] = k
            j -= 1
        order[j] = i


@numba.njit(cache=True, error_model="numpy")
def observe(
    robot_xy: np.ndarray,
    robot_theta: np.ndarray,
    robot_v: np.ndarray,
    robot_omega: np.ndarray,
    robot_vy: np.ndarray,
    goal_xy: np.ndarray,
    human_xy: np.ndarray,
    human_heading: np.ndarray,
    human_speed: np.ndarray,
    human_radius: float,
    slots: int,
    obstacle_kind: np.ndarray,
    obstacle_xy: np.ndarray,
    obstacle_half: np.ndarray,
    obstacle_slots: int,
    envs: np.ndarray,
    out: np.ndarray,
) -> None:
    """Write the observations of slots ``envs`` into the rows ``out[envs]`` (float32).

    ``slots`` (K) human slots: every human in spawn order when K equals the number of humans,
    the K nearest (nearest first) when fewer, padding (all zeros, radius 0) past the humans when
    more; then ``obstacle_slots`` (M) obstacles, nearest first: the nearest point of the
    outline in the robot's frame, the enclosing radius, and 1 (empty slots: zeros)."""
    num_humans = human_speed.shape[1]
    num_obstacles = obstacle_kind.shape[1]
    sort = slots < num_humans
    hdx = np.empty(num_humans)
    hdy = np.empty(num_humans)
    order = np.arange(max(num_humans, num_obstacles))
    odx = np.empty(num_obstacles)
    ody = np.empty(num_obstacles)
    for n in range(envs.shape[0]):
        e = envs[n]
        theta = robot_theta[e]
        c = math.cos(theta)
        s = math.sin(theta)
        rx = robot_xy[e, 0]
        ry = robot_xy[e, 1]
        # World → robot frame: rotate the offset by −θ.
        dx = goal_xy[e, 0] - rx
        dy = goal_xy[e, 1] - ry
        out[e, 0] = c * dx + s * dy
        out[e, 1] = -s * dx + c * dy
        # A holonomic robot's sideways command (robot_vy; 0 for the unicycle) joins in.
        rvx = robot_v[e] * c - robot_vy[e] * s
        rvy = robot_v[e] * s + robot_vy[e] * c
        if sort:
            for h in range(num_humans):
                hdx[h] = human_xy[e, h, 0] - rx
                hdy[h] = human_xy[e, h, 1] - ry
            _nearest_first(hdx, hdy, num_humans, order)
        for slot in range(slots):
            base = 2 + 7 * slot
            if slot >= num_humans:
                for f in range(7):
                    out[e, base + f] = 0.0
                continue
            h = order[slot] if sort else slot
            dx = human_xy[e, h, 0] - rx
            dy = human_xy[e, h, 1] - ry
            out[e, base] = c * dx + s * dy
            out[e, base + 1] = -s * dx + c * dy
            hc = human_heading[e, h, 0]
            hs = human_heading[e, h, 1]
            # sin and cos of θ_h − θ_r by the angle-difference identities.
            out[e, base + 2] = hs * c - hc * s
            out[e, base + 3] = hc * c + hs * s
            out[e, base + 4] = human_radius
            hvx = human_speed[e, h] * hc
            hvy = human_speed[e, h] * hs
            out[e, base + 5] = norm(hvx - rvx, hvy - rvy)
            out[e, base + 6] = -robot_omega[e]
        if obstacle_slots == 0:
            continue
        present = 0
        for o in range(num_obstacles):
            if obstacle_kind[e, o] == OBSTACLE_NONE:
                continue
            qx, qy, _ = slot_nearest_point(rx, ry, e, o, obstacle_kind, obstacle_xy, obstacle_half)
            odx[present] = qx - rx
            ody[present] = qy - ry
            order[present] = o  # the slot of the present-th obstacle
            present += 1
        # Sort the present obstacles by distance; keep their slot numbers alongside.
        slots_of = order[:present].copy()
        _nearest_first(odx, ody, present, order)
        base0 = 2 + 7 * slots
        for m in range(obstacle_slots):
            base = base0 + 4 * m
            if m >= present:
                for f in range(4):
                    out[e, base + f] = 0.0
                continue
            k = order[m]
            o = slots_of[k]
            out[e, base] = c * odx[k] + s * ody[k]
            out[e, base + 1] = -s * odx[k] + c * ody[k]
            hx = obstacle_half[e, o, 0]
            hy = obstacle_half[e, o, 1]
            out[e, base + 2] = (
                math.sqrt(hx * hx + hy * hy) if obstacle_kind[e, o] == OBSTACLE_TABLE else hx
            )
            out[e, base + 3] = 1.0
