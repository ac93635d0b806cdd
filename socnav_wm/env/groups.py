"""Groups of humans: who belongs to which (drawn per scenario), where members start, and the
cohesion that keeps a walking group together (Moussaïd et al. 2010).

A walking group's members start beside their leader (its first member) and share its goal; a
standing group stands on a circle facing its centre and never moves.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from socnav_wm.env.draws import (
    MAX_SPAWN_ATTEMPTS,
    STREAM_GROUPS,
    count_in_range,
    discs_touch,
    touches_wall,
    uniform,
)
from socnav_wm.env.geometry import norm
from socnav_wm.env.obstacles import disc_clearance

STANDING_GAP = 0.15  # m between neighbours of a standing group, surface to surface


@numba.njit(cache=True, error_model="numpy")
def assign_groups(
    e: int,
    seed: int,
    s: int,
    num_humans: int,
    counts: np.ndarray,
    sizes: np.ndarray,
    human_group: np.ndarray,
    group_leader: np.ndarray,
    group_standing: np.ndarray,
) -> None:
    """Scenario ``s``'s groups in slot ``e``: a count of walking then of standing groups
    (``counts``: [low, high] of each), each of a size drawn in ``sizes``; members take the
    humans in index order (the first leads), the humans left over walk alone."""
    human_group[e, :] = -1
    group_leader[e, :] = -1
    group_standing[e, :] = False
    taken = 0
    slot = 0
    for kind in range(2):
        low = counts[2 * kind]
        high = counts[2 * kind + 1]
        for _ in range(count_in_range(seed, s, STREAM_GROUPS, kind, low, high)):
            u = uniform(seed, s, STREAM_GROUPS, slot + 1, 0, 0)
            size = sizes[0] + min(sizes[1] - sizes[0], int(u * (sizes[1] - sizes[0] + 1)))
            size = min(size, num_humans - taken)
            if size < 2:
                return
            group_leader[e, slot] = taken
            group_standing[e, slot] = kind == 1
            for m in range(size):
                human_group[e, taken + m] = slot
            taken += size
            slot += 1


@numba.njit(cache=True, error_model="numpy")
def disc_is_free(
    e: int,
    h: int,
    x: float,
    y: float,
    wall_half: float,
    robot_xy: np.ndarray,
    robot_radius: float,
    human_xy: np.ndarray,
    human_radius: float,
    obstacle_kind: np.ndarray,
    obstacle_xy: np.ndarray,
    obstacle_half: np.ndarray,
) -> bool:
    """Whether human ``h`` fits at (x, y): off the walls, the obstacles, the robot and the
    humans placed before it (indices below ``h``)."""
    if touches_wall(x, y, human_radius, wall_half):
        return False
    if discs_touch(x, y, robot_xy[e, 0], robot_xy[e, 1], robot_radius + human_radius):
        return False
    if disc_clearance(e, x, y, human_radius, obstacle_kind, obstacle_xy, obstacle_half) <= 0.0:
        return False
    for other in range(h):
        if discs_touch(x, y, human_xy[e, other, 0], human_xy[e, other, 1], 2.0 * human_radius):
            return False
    return True


@numba.njit(cache=True, error_model="numpy")
def place_group_member(
    e: int, seed: int, s: int, h: int, half: float, wall_half: float, robot_xy: np.ndarray,
    robot_radius: float, human_xy: np.ndarray, human_radius: float, human_group: np.ndarray,
    group_leader: np.ndarray, group_standing: np.ndarray, human_heading: np.ndarray,
    obstacle_kind: np.ndarray, obstacle_xy: np.ndarray, obstacle_half: np.ndarray,
) -> bool:  # fmt: skip
    """Place human ``h`` of a group: a walking member beside its leader (0–0.5 m apart,
    farther only when that is full; facing the leader's way); a standing group's leader places
    the whole circle (members facing its centre), its other members are then already placed.
    False: no place found."""
    g = human_group[e, h]
    leader = group_leader[e, g]
    if group_standing[e, g]:
        if h != leader:
            return True
        size = 0
        for j in range(human_group.shape[1]):
            if human_group[e, j] == g:
                size += 1
        ring = (human_radius + 0.5 * STANDING_GAP) / math.sin(math.pi / size)
        for attempt in range(MAX_SPAWN_ATTEMPTS):
            cx = (2.0 * uniform(seed, s, STREAM_GROUPS, h, attempt, 0) - 1.0) * half
            cy = (2.0 * uniform(seed, s, STREAM_GROUPS, h, attempt, 1) - 1.0) * half
            turn = uniform(seed, s, STREAM_GROUPS, h, attempt, 2) * 2.0 * math.pi
            ok = True
            for m in range(size):
                angle = turn + 2.0 * math.pi * m / size
                x = cx + ring * math.cos(angle)
                y = cy + ring * math.sin(angle)
                if not disc_is_free(e, h + m, x, y, wall_half, robot_xy, robot_radius,
                                     human_xy, human_radius, obstacle_kind, obstacle_xy,
                                     obstacle_half):  # fmt: skip
                    ok = False
                    break
                human_xy[e, h + m, 0] = x
                human_xy[e, h + m, 1] = y
                human_heading[e, h + m, 0] = -math.cos(angle)
                human_heading[e, h + m, 1] = -math.sin(angle)
            if ok:
                return True
        return False
    for attempt in range(MAX_SPAWN_ATTEMPTS):
        angle = uniform(seed, s, STREAM_GROUPS, h, attempt, 0) * 2.0 * math.pi
        # Within 0.5 m of the leader first; farther as attempts fail (a leader near a corner).
        reach = min(0.5 + 0.01 * attempt, 4.0 * half)
        gap = 2.0 * human_radius + reach * uniform(seed, s, STREAM_GROUPS, h, attempt, 1)
        x = human_xy[e, leader, 0] + gap * math.cos(angle)
        y = human_xy[e, leader, 1] + gap * math.sin(angle)
        if disc_is_free(e, h, x, y, wall_half, robot_xy, robot_radius, human_xy, human_radius,
                         obstacle_kind, obstacle_xy, obstacle_half):  # fmt: skip
            human_xy[e, h, 0] = x
            human_xy[e, h, 1] = y
            human_heading[e, h, 0] = human_heading[e, leader, 0]
            human_heading[e, h, 1] = human_heading[e, leader, 1]
            return True
    return False


@numba.njit(cache=True, error_model="numpy")
def group_pull(
    human_xy: np.ndarray,
    human_group: np.ndarray,
    group_leader: np.ndarray,
    group_standing: np.ndarray,
    out: np.ndarray,
) -> None:
    """(N, H, 2) unit vectors drawing each walking-group member back to its group's centre
    when farther than (n − 1)/2 m from it (Moussaïd et al. 2010's cohesion threshold for a
    group of n); zero otherwise and for everyone else."""
    num_envs, num_humans = human_group.shape
    out[:] = 0.0
    for e in range(num_envs):
        for g in range(group_leader.shape[1]):
            if group_leader[e, g] < 0 or group_standing[e, g]:
                continue
            cx = 0.0
            cy = 0.0
            n = 0
            for h in range(num_humans):
                if human_group[e, h] == g:
                    cx += human_xy[e, h, 0]
                    cy += human_xy[e, h, 1]
                    n += 1
            cx /= n
            cy /= n
            threshold = 0.5 * (n - 1)
            for h in range(num_humans):
                if human_group[e, h] != g:
                    continue
                dx = cx - human_xy[e, h, 0]
                dy = cy - human_xy[e, h, 1]
                d = norm(dx, dy)
                if d > threshold:
                    out[e, h, 0] = dx / d
                    out[e, h, 1] = dy / d
