"""Static obstacles: tables (axis-aligned rectangles) and plants (discs), per scenario.

An obstacle is a slot of the state's ``obstacle_kind`` / ``obstacle_xy`` / ``obstacle_half``
arrays (``OBSTACLE_NONE`` marks an empty slot). This module holds their geometry, once, for
every consumer: spawning (nothing starts or aims inside one), the SFM humans' repulsion, the
hard boundary that keeps every human out of them, the robot's collision test, the observation's
nearest points, the planners' map, and the ORCA polygons (a plant is its circumscribed octagon:
ORCA keeps the humans out of the polygon and so out of the disc).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from socnav_wm.env.geometry import norm
from socnav_wm.env.state import OBSTACLE_NONE, OBSTACLE_PLANT, OBSTACLE_TABLE

PLANT_SIDES = 8
"""A plant's ORCA polygon: a regular octagon around its disc."""
POLYGON_VERTICES = PLANT_SIDES
"""The most vertices of one obstacle's polygon (a table has 4)."""


@numba.njit(cache=True, inline="always")
def nearest_point(
    x: float, y: float, kind: int, cx: float, cy: float, hx: float, hy: float
) -> tuple[float, float, float]:
    """The point of an obstacle's outline nearest to (x, y) and the signed distance to it (m):
    positive outside, negative inside (then the point is where (x, y) leaves it fastest)."""
    dx = x - cx
    dy = y - cy
    if kind == OBSTACLE_PLANT:
        d = norm(dx, dy)
        if d == 0.0:
            return cx + hx, cy, -hx
        return cx + dx * hx / d, cy + dy * hx / d, d - hx
    # A table: clamp to the rectangle; inside, the nearest side.
    qx = min(hx, max(-hx, dx))
    qy = min(hy, max(-hy, dy))
    if qx != dx or qy != dy:
        return cx + qx, cy + qy, norm(dx - qx, dy - qy)
    to_x = hx - abs(dx)
    to_y = hy - abs(dy)
    if to_x < to_y:
        return cx + math.copysign(hx, dx), y, -to_x
    return x, cy + math.copysign(hy, dy), -to_y


@numba.njit(cache=True, inline="always")
def slot_nearest_point(
    x: float, y: float, e: int, o: int, kind: np.ndarray, xy: np.ndarray, half: np.ndarray
) -> tuple[float, float, float]:
    """:func:`nearest_point` of obstacle slot ``o`` of env ``e`` (the state's arrays)."""
    return nearest_point(x, y, kind[e, o], xy[e, o, 0], xy[e, o, 1], half[e, o, 0], half[e, o, 1])


@numba.njit(cache=True)
def disc_clearance(
    e: int, x: float, y: float, radius: float, kind: np.ndarray, xy: np.ndarray, half: np.ndarray
) -> float:
    """The smallest gap (m) between a disc at (x, y) and the obstacles of env ``e``: negative
    when it overlaps one; +inf when there are none."""
    best = np.inf
    for o in range(kind.shape[1]):
        if kind[e, o] == OBSTACLE_NONE:
            continue
        _, _, d = slot_nearest_point(x, y, e, o, kind, xy, half)
        best = min(best, d - radius)
    return best


@numba.njit(cache=True)
def push_out(
    e: int, i: int, points: np.ndarray, radius: float, kind: np.ndarray, xy: np.ndarray,
    half: np.ndarray,
) -> None:  # fmt: skip
    """Move disc ``points[e, i]`` out of every obstacle it overlaps, to touch its outline:
    obstacles are hard boundaries for the humans, as walls are."""
    for o in range(kind.shape[1]):
        if kind[e, o] == OBSTACLE_NONE:
            continue
        x = points[e, i, 0]
        y = points[e, i, 1]
        px, py, d = slot_nearest_point(x, y, e, o, kind, xy, half)
        if d >= radius:
            continue
        if d > 0.0:  # outside, too close: along the normal
            nx = (x - px) / d
            ny = (y - py) / d
        else:  # inside: out through the nearest side
            dist = norm(px - x, py - y)
            if dist == 0.0:
                nx, ny = 1.0, 0.0
            else:
                nx = (px - x) / dist
                ny = (py - y) / dist
        points[e, i, 0] = px + nx * radius
        points[e, i, 1] = py + ny * radius


def polygons(kind: np.ndarray, xy: np.ndarray, half: np.ndarray) -> np.ndarray:
    """(N, O, POLYGON_VERTICES, 2) counter-clockwise outlines of every obstacle slot (a table's
    4 corners then copies of the last, unused; see :func:`polygon_sizes`)."""
    n, o = kind.shape
    out = np.zeros((n, o, POLYGON_VERTICES, 2))
    corners = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    angles = 2 * np.pi * (np.arange(PLANT_SIDES) + 0.5) / PLANT_SIDES
    ring = np.stack((np.cos(angles), np.sin(angles)), axis=-1) / math.cos(math.pi / PLANT_SIDES)
    table = kind == OBSTACLE_TABLE
    plant = kind == OBSTACLE_PLANT
    out[table, :4] = xy[table][:, None] + corners[None] * half[table][:, None]
    out[plant] = xy[plant][:, None] + ring[None] * half[plant][:, :1, None]
    return out


def polygon_sizes(kind: np.ndarray) -> np.ndarray:
    """(N, O) vertices of each slot's polygon: 4 a table, 8 a plant, 0 an empty slot."""
    return np.select([kind == OBSTACLE_TABLE, kind == OBSTACLE_PLANT], [4, PLANT_SIDES], 0)


def obstacle_map(state) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The state's obstacles (kind, centres, half sizes) or None when the scenario has none:
    the static map a planner or a robot controller knows, as it knows the walls."""
    if state.obstacle_kind.shape[1] == 0:
        return None
    return state.obstacle_kind, state.obstacle_xy, state.obstacle_half


def enclosing_radius(kind: np.ndarray, half: np.ndarray) -> np.ndarray:
    """(N, O) the radius of each obstacle's enclosing circle (m); 0 for an empty slot."""
    table = np.hypot(half[..., 0], half[..., 1])
    return np.where(kind == OBSTACLE_TABLE, table, np.where(kind == OBSTACLE_PLANT,
                                                              half[..., 0], 0.0))  # fmt: skip


def nearest_points(
    points: np.ndarray, kind: np.ndarray, xy: np.ndarray, half: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`nearest_point` for arrays: ``points`` (B, 2) against each env's obstacles (B, O):
    the nearest outline points (B, O, 2) and the signed distances (B, O), +inf for empty slots
    (m)."""
    offset = points[:, None, :] - xy  # (B, O, 2)
    # Tables: clamp into the rectangle; inside, the nearest side.
    clamped = np.clip(offset, -half, half)
    outside = np.any(clamped != offset, axis=-1)
    to_side = half - np.abs(offset)
    along_x = to_side[..., 0] < to_side[..., 1]
    inner = np.where(
        along_x[..., None],
        np.stack((np.copysign(half[..., 0], offset[..., 0]), offset[..., 1]), axis=-1),
        np.stack((offset[..., 0], np.copysign(half[..., 1], offset[..., 1])), axis=-1),
    )
    table_point = np.where(outside[..., None], clamped, inner)
    table_distance = np.where(
        outside, np.linalg.norm(offset - clamped, axis=-1), -np.min(to_side, axis=-1)
    )
    # Plants: along the ray from the centre.
    length = np.linalg.norm(offset, axis=-1)
    radius = half[..., 0]
    unit = np.divide(offset, length[..., None], out=np.zeros_like(offset),
                     where=length[..., None] > 0)  # fmt: skip
    unit[..., 0] = np.where(length > 0, unit[..., 0], 1.0)
    plant_point = unit * radius[..., None]
    plant = kind == OBSTACLE_PLANT
    point = xy + np.where(plant[..., None], plant_point, table_point)
    distance = np.where(plant, length - radius, table_distance)
    distance = np.where(kind == OBSTACLE_NONE, np.inf, distance)
    return point, distance
