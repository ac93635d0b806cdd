"""The paper's reward (paper_spec §3.1), its dense variant, and ``dmin``.

``dmin`` is the environment's approximate surface-to-surface distance between the robot and the
nearest human over the coming step; a step is uncomfortable when ``dmin < discomfort_distance``.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from socnav_wm.env.geometry import norm

REWARD_PAPER = 0
REWARD_DENSE = 1
REWARD_CODES = {"paper": REWARD_PAPER, "dense": REWARD_DENSE}


@numba.njit(cache=True, inline="always")
def point_to_segment_distance(ax: float, ay: float, bx: float, by: float) -> float:
    """Distance from the origin to the segment a→b (m)."""
    dx = bx - ax
    dy = by - ay
    length_sq = dx * dx + dy * dy
    if length_sq == 0.0:
        return norm(ax, ay)
    u = -(ax * dx + ay * dy) / length_sq
    u = min(1.0, max(0.0, u))
    return norm(ax + u * dx, ay + u * dy)


@numba.njit(cache=True, error_model="numpy")
def compute_dmin(
    robot_xy: np.ndarray,
    robot_theta: np.ndarray,
    robot_v: np.ndarray,
    robot_omega: np.ndarray,
    robot_vy: np.ndarray,
    human_xy: np.ndarray,
    human_heading: np.ndarray,
    human_speed: np.ndarray,
    robot_radius: float,
    human_radius: float,
    dt: float,
    out: np.ndarray,
) -> None:
    """``dmin`` (N,) in metres, computed after the move exactly as the paper's environment does.

    For each human: the relative position p = p_h − p_r, the relative velocity
    u = v_h − v·(cos(θ_r + ω·dt), sin(θ_r + ω·dt)), and the distance from the robot to the
    segment p → p + u·dt, minus both radii. The ``θ_r + ω·dt`` (with θ_r already updated) is the
    original code's: it adds ω as a heading offset (paper_spec §8.10); we keep it because the
    reward must be the paper's, and it changes dmin by millimetres.
    """
    num_envs, num_humans = human_speed.shape
    for e in range(num_envs):
        heading = robot_theta[e] + robot_omega[e] * dt
        c = math.cos(heading)
        s = math.sin(heading)
        # A holonomic robot's sideways command (robot_vy; 0 for the unicycle) joins in.
        rvx = robot_v[e] * c - robot_vy[e] * s
        rvy = robot_v[e] * s + robot_vy[e] * c
        best = math.inf
        for h in range(num_humans):
            px = human_xy[e, h, 0] - robot_xy[e, 0]
            py = human_xy[e, h, 1] - robot_xy[e, 1]
            ux = human_speed[e, h] * human_heading[e, h, 0] - rvx
            uy = human_speed[e, h] * human_heading[e, h, 1] - rvy
            d = point_to_segment_distance(px, py, px + ux * dt, py + uy * dt)
            d -= robot_radius + human_radius
            best = min(best, d)
        out[e] = best


@numba.njit(cache=True, error_model="numpy")
def compute_reward(
    kind: int,
    active: np.ndarray,
    dmin: np.ndarray,
    success: np.ndarray,
    failure: np.ndarray,
    alive_sum: np.ndarray,
    discomfort_sum: np.ndarray,
    reach_reward: float,
    failure_reward: float,
    alive_penalty: float,
    discomfort_distance: float,
    discomfort_factor: float,
    out: np.ndarray,
) -> None:
    """Per-step reward (N,) of the active envs; updates the paper reward's accumulators.

    ``paper`` (paper_spec §3.1): a non-terminal step pays ``F·(dmin − D)`` when ``dmin < D``
    and adds the alive penalty to ``alive_sum`` (A) and its own penalty to ``discomfort_sum``
    (S); reaching the goal pays ``reach + A``; any failure (collision, timeout) pays
    ``failure − S``, refunding the discomfort, so every failed episode returns exactly −1.
    ``dense``: a non-terminal step pays ``F·min(0, dmin − D) + alive``; terminals pay ±1 alone.
    """
    for e in range(out.shape[0]):
        if not active[e]:
            out[e] = 0.0
            continue
        discomfort = 0.0
        if dmin[e] < discomfort_distance:
            discomfort = discomfort_factor * (dmin[e] - discomfort_distance)
        if kind == REWARD_PAPER:
            if success[e]:
                out[e] = reach_reward + alive_sum[e]
            elif failure[e]:
                out[e] = failure_reward - discomfort_sum[e]
            else:
                out[e] = discomfort
                alive_sum[e] += alive_penalty
                discomfort_sum[e] += discomfort
        else:
            if success[e]:
                out[e] = reach_reward
            elif failure[e]:
                out[e] = failure_reward
            else:
                out[e] = discomfort + alive_penalty
