"""The robot-frame observation vector of paper_spec §2 (23 values for 3 humans).

Layout: ``[goal_x, goal_y]`` then, for each human in spawn order,
``[x, y, sin(θ_h − θ_r), cos(θ_h − θ_r), radius, ‖v_h − v_r‖, −ω_r]``; positions in metres in
the robot frame (x forward, y to the left), speeds in m/s, ω in rad/s. Nothing is normalised.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from socnav_wm.env.geometry import norm

GOAL_FIELDS = ("goal_x", "goal_y")
HUMAN_FIELDS = ("x", "y", "sin_rel_heading", "cos_rel_heading", "radius", "rel_speed", "neg_omega")


def observation_size(num_humans: int) -> int:
    return len(GOAL_FIELDS) + len(HUMAN_FIELDS) * num_humans


def observation_names(num_humans: int) -> list[str]:
    """Names of the observation's entries, in order (``human0_x``, …)."""
    return list(GOAL_FIELDS) + [
        f"human{i}_{name}" for i in range(num_humans) for name in HUMAN_FIELDS
    ]


@numba.njit(cache=True, error_model="numpy")
def observe(
    robot_xy: np.ndarray,
    robot_theta: np.ndarray,
    robot_v: np.ndarray,
    robot_omega: np.ndarray,
    goal_xy: np.ndarray,
    human_xy: np.ndarray,
    human_heading: np.ndarray,
    human_speed: np.ndarray,
    human_radius: float,
    envs: np.ndarray,
    out: np.ndarray,
) -> None:
    """Write the observations of slots ``envs`` into the rows ``out[envs]`` (float32)."""
    num_humans = human_speed.shape[1]
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
        rvx = robot_v[e] * c
        rvy = robot_v[e] * s
        for h in range(num_humans):
            base = 2 + 7 * h
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
