"""Batched port of the ORCA velocity solver of the RVO2 library (agents + static polygons).

This follows RVO2 2.0 (``Agent::computeNewVelocity``, ``KdTree``, ``RVOSimulator``) step by
step so that, for the same inputs, the new velocities match what ``rvo2.PyRVOSimulator.doStep``
computes, up to floating-point rounding: RVO2 works in float32, this port in float64, so a few
agents whose situation sits exactly on a branch boundary (e.g. a leg versus the cut-off circle)
may take the other branch.

Units: positions and radii in metres, velocities and speeds in m/s, times in seconds.

Design notes:

* Obstacles are preprocessed once, in plain Python, exactly as ``addObstacle`` and
  ``processObstacles`` do, including the obstacle k-d tree: building that tree can split
  edges and so add vertices, and RVO2's neighbour query visits edges in tree order, which decides
  the order of the obstacle ORCA lines when two edges are at the same distance.
* Agent neighbours are found by brute force in agent-index order. RVO2's agent k-d tree keeps up
  to 10 agents in one leaf and scans it in insertion order, so for at most 10 agents per
  environment the neighbour lists are identical (beyond that only ties may be ordered
  differently).
* One ``numba.njit`` kernel loops over environments and agents serially; all scratch space is
  allocated once per call.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numba
import numpy as np

__all__ = [
    "RVO_EPSILON",
    "EnvObstacles",
    "Obstacles",
    "OrcaParams",
    "make_obstacles",
    "orca_velocities",
    "room_obstacles",
]

RVO_EPSILON = 1e-5
"""RVO2's tolerance for parallel lines and the obstacle "already covered" test."""


@dataclass(frozen=True)
class OrcaParams:
    """ORCA parameters shared by all agents (defaults: the paper's environment).

    Attributes:
        neighbor_dist: Only agents closer than this (centre to centre, metres) are considered.
        max_neighbors: At most this many of the closest agents are considered.
        time_horizon: Horizon (seconds) within which collisions with agents are avoided.
        time_horizon_obst: Horizon (seconds) within which collisions with obstacles are avoided.
        time_step: Simulation step (seconds); sets how fast overlapping agents are pushed apart.
    """

    neighbor_dist: float = 1.44
    max_neighbors: int = 3
    time_horizon: float = 5.0
    time_horizon_obst: float = 5.0
    time_step: float = 1.0


@dataclass(frozen=True)
class Obstacles:
    """Processed obstacle vertices, as RVO2 stores them after ``processObstacles``.

    Vertex ``i`` and vertex ``next_index[i]`` bound one obstacle edge; the solid side of an edge
    is on its right. M counts the vertices, including those added by splitting edges while
    building the k-d tree; K is the number of tree nodes (one per edge).

    Attributes:
        point: (M, 2) vertex positions, metres.
        next_index: (M,) index of the next vertex along the polygon.
        prev_index: (M,) index of the previous vertex along the polygon.
        unit_dir: (M, 2) unit vector from the vertex to the next one.
        is_convex: (M,) whether the polygon is convex at the vertex.
        tree_vertex: (K,) first vertex of the edge stored at each k-d tree node; node 0 is root.
        tree_left: (K,) left child node of each node (-1: none).
        tree_right: (K,) right child node of each node (-1: none).
    """

    point: np.ndarray
    next_index: np.ndarray
    prev_index: np.ndarray
    unit_dir: np.ndarray
    is_convex: np.ndarray
    tree_vertex: np.ndarray
    tree_left: np.ndarray
    tree_right: np.ndarray

    @property
    def num_vertices(self) -> int:
        return int(self.point.shape[0])


@dataclass(frozen=True)
class EnvObstacles:
    """Each environment's own convex polygons (counter-clockwise), vertices packed per env.

    Attributes:
        point: (N, V, 2) vertices, metres; only the first ``count[e]`` of env ``e`` are used.
        next_index: (N, V) the next vertex of the same polygon (an index within the env; −1:
            an unused vertex).
        unit_dir: (N, V, 2) unit vector from each vertex to the next.
        is_convex: (N, V) always True for these polygons.
        count: (N,) vertices in use per env.
    """

    point: np.ndarray
    next_index: np.ndarray
    unit_dir: np.ndarray
    is_convex: np.ndarray
    count: np.ndarray

    @classmethod
    def empty(cls, num_envs: int) -> EnvObstacles:
        return cls(
            point=np.zeros((num_envs, 0, 2)),
            next_index=np.zeros((num_envs, 0), dtype=np.int64),
            unit_dir=np.zeros((num_envs, 0, 2)),
            is_convex=np.zeros((num_envs, 0), dtype=np.bool_),
            count=np.zeros(num_envs, dtype=np.int64),
        )

    @classmethod
    def from_polygons(cls, polygons: np.ndarray, sizes: np.ndarray) -> EnvObstacles:
        """From (N, P, K, 2) counter-clockwise polygons of which the first ``sizes[n, p]``
        vertices are used (0: no polygon in that slot). Slot ``p``'s vertices are the env's
        ``p·K … p·K + K − 1``; unused ones have ``next_index`` −1."""
        n, p, k, _ = polygons.shape
        local = np.arange(k)
        used = local[None, None, :] < sizes[..., None]  # (N, P, K)
        following = (local[None, None, :] + 1) % np.maximum(sizes[..., None], 1)
        next_index = np.where(used, np.arange(p)[None, :, None] * k + following, -1)
        point = polygons.reshape(n, p * k, 2)
        next_index = next_index.reshape(n, p * k).astype(np.int64)
        target = np.take_along_axis(point, np.maximum(next_index, 0)[..., None], axis=1)
        step = target - point
        length = np.hypot(step[..., 0], step[..., 1])
        unit = np.divide(step, length[..., None], out=np.zeros_like(step),
                         where=length[..., None] > 0)  # fmt: skip
        convex = np.ones((n, p * k), dtype=np.bool_)
        count = np.full(n, p * k, dtype=np.int64)
        return cls(np.ascontiguousarray(point), next_index, unit, convex, count)


def _left_of(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
    """Positive when ``c`` lies to the left of the directed line ``a -> b``."""
    ax, ay = a[0] - c[0], a[1] - c[1]
    bx, by = b[0] - a[0], b[1] - a[1]
    return float(ax * by - ay * bx)


def make_obstacles(polygons: Sequence[np.ndarray]) -> Obstacles:
    """Build the obstacle structure from polygons, as RVO2's addObstacle + processObstacles.

    Args:
        polygons: Each an (n, 2) array of vertices in metres, n >= 2. Counter-clockwise for a
            solid obstacle, clockwise for a "negative" one (e.g. the inside of a room); a
            polygon with 2 vertices is a two-sided segment.

    Returns:
        The processed vertices and the obstacle k-d tree.
    """
    points: list[np.ndarray] = []
    nxt: list[int] = []
    prv: list[int] = []
    unit: list[np.ndarray] = []
    convex: list[bool] = []
    for poly in polygons:
        v = np.asarray(poly, dtype=np.float64).reshape(-1, 2)
        n = v.shape[0]
        if n < 2:
            raise ValueError("an obstacle needs at least 2 vertices")
        base = len(points)
        for i in range(n):
            d = v[(i + 1) % n] - v[i]
            points.append(v[i].copy())
            nxt.append(base + (i + 1) % n)
            prv.append(base + (i - 1) % n)
            unit.append(d / np.sqrt(d @ d))
            # A segment is convex at both ends: an agent can pass around either tip.
            convex.append(True if n == 2 else _left_of(v[i - 1], v[i], v[(i + 1) % n]) >= 0.0)

    tree_vertex: list[int] = []
    tree_left: list[int] = []
    tree_right: list[int] = []

    def side_counts(i1: int, obs: list[int], best: tuple[int, int]) -> tuple[int, int]:
        # Mirrors RVO2's split search including its early exit, which can change the chosen
        # split when several candidates tie.
        i2 = nxt[i1]
        left = right = 0
        for j1 in obs:
            if j1 == i1:
                continue
            a = _left_of(points[i1], points[i2], points[j1])
            b = _left_of(points[i1], points[i2], points[nxt[j1]])
            if a >= -RVO_EPSILON and b >= -RVO_EPSILON:
                left += 1
            elif a <= RVO_EPSILON and b <= RVO_EPSILON:
                right += 1
            else:
                left += 1
                right += 1
            if (max(left, right), min(left, right)) >= best:
                break
        return left, right

    def build(obs: list[int]) -> int:
        if not obs:
            return -1
        node = len(tree_vertex)
        tree_vertex.append(-1)
        tree_left.append(-1)
        tree_right.append(-1)

        optimal = 0
        best = (len(obs), len(obs))
        for i, i1 in enumerate(obs):
            left, right = side_counts(i1, obs, best)
            key = (max(left, right), min(left, right))
            if key < best:
                best = key
                optimal = i

        i1 = obs[optimal]
        i2 = nxt[i1]
        left_obs: list[int] = []
        right_obs: list[int] = []
        for j, j1 in enumerate(obs):
            if j == optimal:
                continue
            j2 = nxt[j1]
            a = _left_of(points[i1], points[i2], points[j1])
            b = _left_of(points[i1], points[i2], points[j2])
            if a >= -RVO_EPSILON and b >= -RVO_EPSILON:
                left_obs.append(j1)
            elif a <= RVO_EPSILON and b <= RVO_EPSILON:
                right_obs.append(j1)
            else:
                # Edge j crosses the splitting line: cut it in two so each half lies on one side.
                e = points[i2] - points[i1]
                f1 = points[j1] - points[i1]
                f2 = points[j1] - points[j2]
                t = (e[0] * f1[1] - e[1] * f1[0]) / (e[0] * f2[1] - e[1] * f2[0])
                new = len(points)
                points.append(points[j1] + t * (points[j2] - points[j1]))
                prv.append(j1)
                nxt.append(j2)
                convex.append(True)
                unit.append(unit[j1].copy())
                nxt[j1] = new
                prv[j2] = new
                if a > 0.0:
                    left_obs.append(j1)
                    right_obs.append(new)
                else:
                    right_obs.append(j1)
                    left_obs.append(new)

        tree_vertex[node] = i1
        left_child = build(left_obs)
        right_child = build(right_obs)
        tree_left[node] = left_child
        tree_right[node] = right_child
        return node

    build(list(range(len(points))))

    return Obstacles(
        point=np.array(points, dtype=np.float64).reshape(-1, 2),
        next_index=np.array(nxt, dtype=np.int64),
        prev_index=np.array(prv, dtype=np.int64),
        unit_dir=np.array(unit, dtype=np.float64).reshape(-1, 2),
        is_convex=np.array(convex, dtype=np.bool_),
        tree_vertex=np.array(tree_vertex, dtype=np.int64),
        tree_left=np.array(tree_left, dtype=np.int64),
        tree_right=np.array(tree_right, dtype=np.int64),
    )


def room_obstacles(half_size: float) -> Obstacles:
    """Walls of a square room centred at the origin, inner faces at +-half_size metres.

    One clockwise polygon, i.e. a "negative" obstacle whose free side is the inside.
    """
    h = float(half_size)
    return make_obstacles([np.array([[-h, -h], [-h, h], [h, h], [h, -h]])])


# --------------------------------------------------------------------------------------------
# Kernel
# --------------------------------------------------------------------------------------------

_JIT = {"cache": True, "nogil": True, "error_model": "numpy"}


@numba.njit(**_JIT)
def _lp1(lp, ld, line_no, radius, optx, opty, direction_opt, rx, ry):
    """Optimise on line ``line_no`` subject to the earlier lines and the speed disc."""
    pdx = lp[line_no, 0]
    pdy = lp[line_no, 1]
    dx = ld[line_no, 0]
    dy = ld[line_no, 1]
    dot = pdx * dx + pdy * dy
    disc = dot * dot + radius * radius - (pdx * pdx + pdy * pdy)
    if disc < 0.0:
        return False, rx, ry
    sq = np.sqrt(disc)
    t_left = -dot - sq
    t_right = -dot + sq
    for i in range(line_no):
        denom = dx * ld[i, 1] - dy * ld[i, 0]
        numer = ld[i, 0] * (pdy - lp[i, 1]) - ld[i, 1] * (pdx - lp[i, 0])
        if abs(denom) <= RVO_EPSILON:
            if numer < 0.0:
                return False, rx, ry
            continue
        t = numer / denom
        if denom >= 0.0:
            t_right = min(t_right, t)
        else:
            t_left = max(t_left, t)
        if t_left > t_right:
            return False, rx, ry
    if direction_opt:
        if optx * dx + opty * dy > 0.0:
            return True, pdx + t_right * dx, pdy + t_right * dy
        return True, pdx + t_left * dx, pdy + t_left * dy
    t = dx * (optx - pdx) + dy * (opty - pdy)
    if t < t_left:
        t = t_left
    elif t > t_right:
        t = t_right
    return True, pdx + t * dx, pdy + t * dy


@numba.njit(**_JIT)
def _lp2(lp, ld, n_lines, radius, optx, opty, direction_opt):
    """Closest point to opt (or furthest along it) in the speed disc and all half-planes.

    Returns (index of the first line that made it infeasible or n_lines, rx, ry).
    """
    if direction_opt:
        rx = optx * radius
        ry = opty * radius
    elif optx * optx + opty * opty > radius * radius:
        norm = np.sqrt(optx * optx + opty * opty)
        rx = optx / norm * radius
        ry = opty / norm * radius
    else:
        rx = optx
        ry = opty
    for i in range(n_lines):
        if ld[i, 0] * (lp[i, 1] - ry) - ld[i, 1] * (lp[i, 0] - rx) > 0.0:
            ok, nx, ny = _lp1(lp, ld, i, radius, optx, opty, direction_opt, rx, ry)
            if not ok:
                return i, rx, ry
            rx = nx
            ry = ny
    return n_lines, rx, ry


@numba.njit(**_JIT)
def _lp3(lp, ld, n_lines, n_obst_lines, begin_line, radius, rx, ry, plp, pld):
    """Minimise the largest violation of the agent lines; obstacle lines stay hard."""
    distance = 0.0
    for i in range(begin_line, n_lines):
        if ld[i, 0] * (lp[i, 1] - ry) - ld[i, 1] * (lp[i, 0] - rx) > distance:
            for k in range(n_obst_lines):
                plp[k, 0] = lp[k, 0]
                plp[k, 1] = lp[k, 1]
                pld[k, 0] = ld[k, 0]
                pld[k, 1] = ld[k, 1]
            m = n_obst_lines
            for j in range(n_obst_lines, i):
                det_ij = ld[i, 0] * ld[j, 1] - ld[i, 1] * ld[j, 0]
                if abs(det_ij) <= RVO_EPSILON:
                    if ld[i, 0] * ld[j, 0] + ld[i, 1] * ld[j, 1] > 0.0:
                        continue
                    px = 0.5 * (lp[i, 0] + lp[j, 0])
                    py = 0.5 * (lp[i, 1] + lp[j, 1])
                else:
                    s = (
                        ld[j, 0] * (lp[i, 1] - lp[j, 1]) - ld[j, 1] * (lp[i, 0] - lp[j, 0])
                    ) / det_ij
                    px = lp[i, 0] + s * ld[i, 0]
                    py = lp[i, 1] + s * ld[i, 1]
                ddx = ld[j, 0] - ld[i, 0]
                ddy = ld[j, 1] - ld[i, 1]
                norm = np.sqrt(ddx * ddx + ddy * ddy)
                plp[m, 0] = px
                plp[m, 1] = py
                pld[m, 0] = ddx / norm
                pld[m, 1] = ddy / norm
                m += 1
            fail, nx, ny = _lp2(plp, pld, m, radius, -ld[i, 1], ld[i, 0], True)
            # Failure can only come from rounding (the previous result is feasible): keep it.
            if fail >= m:
                rx = nx
                ry = ny
            distance = ld[i, 0] * (lp[i, 1] - ry) - ld[i, 1] * (lp[i, 0] - rx)
    return rx, ry


@numba.njit(**_JIT)
def _dist_sq_point_segment(ax, ay, bx, by, cx, cy):
    ex = bx - ax
    ey = by - ay
    r = ((cx - ax) * ex + (cy - ay) * ey) / (ex * ex + ey * ey)
    if r < 0.0:
        return (cx - ax) ** 2 + (cy - ay) ** 2
    if r > 1.0:
        return (cx - bx) ** 2 + (cy - by) ** 2
    return (cx - ax - r * ex) ** 2 + (cy - ay - r * ey) ** 2


@numba.njit(**_JIT, inline="always")
def _insert_by_distance(nb_dist, nb_idx, count, d, index):
    """Insert ``index`` at distance ``d`` into the first ``count`` entries, kept sorted (after
    equal distances, as RVO2's insertion does); returns the new count."""
    i = count
    while i != 0 and d < nb_dist[i - 1]:
        nb_dist[i] = nb_dist[i - 1]
        nb_idx[i] = nb_idx[i - 1]
        i -= 1
    nb_dist[i] = d
    nb_idx[i] = index
    return count + 1


@numba.njit(**_JIT)
def _obstacle_neighbors(
    px,
    py,
    range_sq,
    ob_point,
    ob_next,
    tree_vertex,
    tree_left,
    tree_right,
    st_node,
    st_phase,
    nb_dist,
    nb_idx,
):
    """RVO2's obstacle tree query; fills nb_idx sorted by distance and returns the count.

    The recursion is unrolled on a stack; phase 0 descends to the agent's side of the node's
    line, phase 1 considers the node's own edge and then the far side.
    """
    count = 0
    if tree_vertex.shape[0] == 0:
        return 0
    sp = 1
    st_node[0] = 0
    st_phase[0] = 0
    while sp > 0:
        sp -= 1
        node = st_node[sp]
        phase = st_phase[sp]
        v1 = tree_vertex[node]
        v2 = ob_next[v1]
        ax = ob_point[v1, 0]
        ay = ob_point[v1, 1]
        ex = ob_point[v2, 0] - ax
        ey = ob_point[v2, 1] - ay
        left_of = (ax - px) * ey - (ay - py) * ex
        if phase == 0:
            st_node[sp] = node
            st_phase[sp] = 1
            sp += 1
            near = tree_left[node] if left_of >= 0.0 else tree_right[node]
            if near >= 0:
                st_node[sp] = near
                st_phase[sp] = 0
                sp += 1
        elif left_of * left_of / (ex * ex + ey * ey) < range_sq:
            # Only edges that face the agent (agent on their right) can constrain it.
            if left_of < 0.0:
                d = _dist_sq_point_segment(ax, ay, ob_point[v2, 0], ob_point[v2, 1], px, py)
                if d < range_sq:
                    count = _insert_by_distance(nb_dist, nb_idx, count, d, v1)
            far = tree_right[node] if left_of >= 0.0 else tree_left[node]
            if far >= 0:
                st_node[sp] = far
                st_phase[sp] = 0
                sp += 1
    return count


@numba.njit(**_JIT)
def _orca_kernel(
    position,
    velocity,
    pref_velocity,
    radius,
    max_speed,
    compute,
    ob_point,
    ob_next,
    ob_prev,
    ob_dir,
    ob_convex,
    tree_vertex,
    tree_left,
    tree_right,
    env_point,
    env_next,
    env_dir,
    env_convex,
    env_count,
    blind_last,
    last_unreciprocated,
    neighbor_dist,
    max_neighbors,
    time_horizon,
    time_horizon_obst,
    time_step,
    out,
):
    num_envs, num_agents = position.shape[0], position.shape[1]
    shared = ob_point.shape[0]
    num_vertices = shared + env_point.shape[1]
    cap_nb = max(1, min(max_neighbors, num_agents))
    max_lines = num_vertices + cap_nb

    lp = np.empty((max_lines, 2))
    ld = np.empty((max_lines, 2))
    plp = np.empty((max_lines, 2))
    pld = np.empty((max_lines, 2))
    ob_nb_dist = np.empty(max(1, num_vertices))
    ob_nb_idx = np.empty(max(1, num_vertices), dtype=np.int64)
    # The shared obstacles (the walls, with their k-d tree) and, after them, each env's own
    # (tables, plants: convex polygons, searched by brute force): one vertex table per env.
    all_point = np.empty((max(1, num_vertices), 2))
    all_next = np.empty(max(1, num_vertices), dtype=np.int64)
    all_prev = np.empty(max(1, num_vertices), dtype=np.int64)
    all_dir = np.empty((max(1, num_vertices), 2))
    all_convex = np.empty(max(1, num_vertices), dtype=np.bool_)
    for v in range(shared):
        all_point[v, 0] = ob_point[v, 0]
        all_point[v, 1] = ob_point[v, 1]
        all_next[v] = ob_next[v]
        all_prev[v] = ob_prev[v]
        all_dir[v, 0] = ob_dir[v, 0]
        all_dir[v, 1] = ob_dir[v, 1]
        all_convex[v] = ob_convex[v]
    ob_point = all_point
    ob_next = all_next
    ob_prev = all_prev
    ob_dir = all_dir
    ob_convex = all_convex
    st_node = np.empty(tree_vertex.shape[0] + 1, dtype=np.int64)
    st_phase = np.empty(tree_vertex.shape[0] + 1, dtype=np.int64)
    ag_nb_dist = np.empty(cap_nb)
    ag_nb_idx = np.empty(cap_nb, dtype=np.int64)

    inv_th_obst = 1.0 / time_horizon_obst
    inv_th = 1.0 / time_horizon
    inv_dt = 1.0 / time_step
    inf = np.inf

    for e in range(num_envs):
        own = env_count[e]
        for v in range(own):
            w = shared + v
            all_point[w, 0] = env_point[e, v, 0]
            all_point[w, 1] = env_point[e, v, 1]
            all_next[w] = shared + env_next[e, v] if env_next[e, v] >= 0 else -1
            all_dir[w, 0] = env_dir[e, v, 0]
            all_dir[w, 1] = env_dir[e, v, 1]
            all_convex[w] = env_convex[e, v]
        for v in range(own):
            if all_next[shared + v] >= 0:
                all_prev[all_next[shared + v]] = shared + v
        for a in range(num_agents):
            vx = velocity[e, a, 0]
            vy = velocity[e, a, 1]
            if not compute[e, a]:
                out[e, a, 0] = vx
                out[e, a, 1] = vy
                continue
            px = position[e, a, 0]
            py = position[e, a, 1]
            rad = radius[e, a]
            vmax = max_speed[e, a]

            # ---- neighbours ----
            obst_range = time_horizon_obst * vmax + rad
            n_ob = _obstacle_neighbors(
                px,
                py,
                obst_range * obst_range,
                ob_point,
                ob_next,
                tree_vertex,
                tree_left,
                tree_right,
                st_node,
                st_phase,
                ob_nb_dist,
                ob_nb_idx,
            )
            # The env's own edges, as the tree query would take them: facing the agent and
            # within range, inserted by distance after equal ones.
            range_ob = obst_range * obst_range
            for v in range(shared, shared + own):
                v2 = all_next[v]
                if v2 < 0:
                    continue
                ax = all_point[v, 0]
                ay = all_point[v, 1]
                ex = all_point[v2, 0] - ax
                ey = all_point[v2, 1] - ay
                left_of = (ax - px) * ey - (ay - py) * ex
                if left_of < 0.0 and left_of * left_of / (ex * ex + ey * ey) < range_ob:
                    d = _dist_sq_point_segment(ax, ay, all_point[v2, 0], all_point[v2, 1], px, py)
                    if d < range_ob:
                        n_ob = _insert_by_distance(ob_nb_dist, ob_nb_idx, n_ob, d, v)

            n_ag = 0
            if max_neighbors > 0:
                range_sq = neighbor_dist * neighbor_dist
                for b in range(num_agents):
                    if b == a or (b == num_agents - 1 and blind_last[e, a]):
                        continue
                    d = (px - position[e, b, 0]) ** 2 + (py - position[e, b, 1]) ** 2
                    if d < range_sq:
                        if n_ag < max_neighbors:
                            n_ag += 1
                        i = n_ag - 1
                        while i != 0 and d < ag_nb_dist[i - 1]:
                            ag_nb_dist[i] = ag_nb_dist[i - 1]
                            ag_nb_idx[i] = ag_nb_idx[i - 1]
                            i -= 1
                        ag_nb_dist[i] = d
                        ag_nb_idx[i] = b
                        # Once full, only closer agents can still enter the list.
                        if n_ag == max_neighbors:
                            range_sq = ag_nb_dist[n_ag - 1]

            # ---- obstacle ORCA lines ----
            n_lines = 0
            r_sq = rad * rad
            for k in range(n_ob):
                o1 = ob_nb_idx[k]
                o2 = ob_next[o1]
                r1x = ob_point[o1, 0] - px
                r1y = ob_point[o1, 1] - py
                r2x = ob_point[o2, 0] - px
                r2y = ob_point[o2, 1] - py

                # Skip the edge if its truncated VO already lies behind an existing line.
                covered = False
                for j in range(n_lines):
                    q1 = (inv_th_obst * r1x - lp[j, 0]) * ld[j, 1] - (
                        inv_th_obst * r1y - lp[j, 1]
                    ) * ld[j, 0]
                    q2 = (inv_th_obst * r2x - lp[j, 0]) * ld[j, 1] - (
                        inv_th_obst * r2y - lp[j, 1]
                    ) * ld[j, 0]
                    if (
                        q1 - inv_th_obst * rad >= -RVO_EPSILON
                        and q2 - inv_th_obst * rad >= -RVO_EPSILON
                    ):
                        covered = True
                        break
                if covered:
                    continue

                dist_sq1 = r1x * r1x + r1y * r1y
                dist_sq2 = r2x * r2x + r2y * r2y
                ovx = ob_point[o2, 0] - ob_point[o1, 0]
                ovy = ob_point[o2, 1] - ob_point[o1, 1]
                s = (-r1x * ovx - r1y * ovy) / (ovx * ovx + ovy * ovy)
                dist_sq_line = (-r1x - s * ovx) ** 2 + (-r1y - s * ovy) ** 2

                # Already overlapping the obstacle: the only constraint is to move away now.
                if s < 0.0 and dist_sq1 <= r_sq:
                    if ob_convex[o1]:
                        nrm = np.sqrt(dist_sq1)
                        lp[n_lines, 0] = 0.0
                        lp[n_lines, 1] = 0.0
                        ld[n_lines, 0] = -r1y / nrm
                        ld[n_lines, 1] = r1x / nrm
                        n_lines += 1
                    continue
                elif s > 1.0 and dist_sq2 <= r_sq:
                    # A non-convex vertex, or one the next edge handles, adds nothing here.
                    if ob_convex[o2] and r2x * ob_dir[o2, 1] - r2y * ob_dir[o2, 0] >= 0.0:
                        nrm = np.sqrt(dist_sq2)
                        lp[n_lines, 0] = 0.0
                        lp[n_lines, 1] = 0.0
                        ld[n_lines, 0] = -r2y / nrm
                        ld[n_lines, 1] = r2x / nrm
                        n_lines += 1
                    continue
                elif s >= 0.0 and s <= 1.0 and dist_sq_line <= r_sq:
                    lp[n_lines, 0] = 0.0
                    lp[n_lines, 1] = 0.0
                    ld[n_lines, 0] = -ob_dir[o1, 0]
                    ld[n_lines, 1] = -ob_dir[o1, 1]
                    n_lines += 1
                    continue

                # No collision: legs of the truncated VO (both from one vertex when seen
                # obliquely; along the cut-off line at a non-convex vertex).
                if s < 0.0 and dist_sq_line <= r_sq:
                    if not ob_convex[o1]:
                        continue
                    o2 = o1
                    leg1 = np.sqrt(dist_sq1 - r_sq)
                    llx = (r1x * leg1 - r1y * rad) / dist_sq1
                    lly = (r1x * rad + r1y * leg1) / dist_sq1
                    rlx = (r1x * leg1 + r1y * rad) / dist_sq1
                    rly = (-r1x * rad + r1y * leg1) / dist_sq1
                elif s > 1.0 and dist_sq_line <= r_sq:
                    if not ob_convex[o2]:
                        continue
                    o1 = o2
                    leg2 = np.sqrt(dist_sq2 - r_sq)
                    llx = (r2x * leg2 - r2y * rad) / dist_sq2
                    lly = (r2x * rad + r2y * leg2) / dist_sq2
                    rlx = (r2x * leg2 + r2y * rad) / dist_sq2
                    rly = (-r2x * rad + r2y * leg2) / dist_sq2
                else:
                    if ob_convex[o1]:
                        leg1 = np.sqrt(dist_sq1 - r_sq)
                        llx = (r1x * leg1 - r1y * rad) / dist_sq1
                        lly = (r1x * rad + r1y * leg1) / dist_sq1
                    else:
                        llx = -ob_dir[o1, 0]
                        lly = -ob_dir[o1, 1]
                    if ob_convex[o2]:
                        leg2 = np.sqrt(dist_sq2 - r_sq)
                        rlx = (r2x * leg2 + r2y * rad) / dist_sq2
                        rly = (-r2x * rad + r2y * leg2) / dist_sq2
                    else:
                        rlx = ob_dir[o1, 0]
                        rly = ob_dir[o1, 1]

                # A leg pointing into the neighbouring edge is replaced by that edge; projecting
                # onto such a "foreign" leg adds no constraint (the neighbour edge does it).
                left_nb = ob_prev[o1]
                left_foreign = False
                right_foreign = False
                if ob_convex[o1] and llx * -ob_dir[left_nb, 1] - lly * -ob_dir[left_nb, 0] >= 0.0:
                    llx = -ob_dir[left_nb, 0]
                    lly = -ob_dir[left_nb, 1]
                    left_foreign = True
                if ob_convex[o2] and rlx * ob_dir[o2, 1] - rly * ob_dir[o2, 0] <= 0.0:
                    rlx = ob_dir[o2, 0]
                    rly = ob_dir[o2, 1]
                    right_foreign = True

                lcx = inv_th_obst * (ob_point[o1, 0] - px)
                lcy = inv_th_obst * (ob_point[o1, 1] - py)
                rcx = inv_th_obst * (ob_point[o2, 0] - px)
                rcy = inv_th_obst * (ob_point[o2, 1] - py)
                cvx = rcx - lcx
                cvy = rcy - lcy
                same = o1 == o2

                t_num = (vx - lcx) * cvx + (vy - lcy) * cvy
                t = 0.5 if same else t_num / (cvx * cvx + cvy * cvy)
                t_left = (vx - lcx) * llx + (vy - lcy) * lly
                t_right = (vx - rcx) * rlx + (vy - rcy) * rly

                if (t < 0.0 and t_left < 0.0) or (same and t_left < 0.0 and t_right < 0.0):
                    wx = vx - lcx
                    wy = vy - lcy
                    nrm = np.sqrt(wx * wx + wy * wy)
                    ux = wx / nrm
                    uy = wy / nrm
                    ld[n_lines, 0] = uy
                    ld[n_lines, 1] = -ux
                    lp[n_lines, 0] = lcx + rad * inv_th_obst * ux
                    lp[n_lines, 1] = lcy + rad * inv_th_obst * uy
                    n_lines += 1
                    continue
                elif t > 1.0 and t_right < 0.0:
                    wx = vx - rcx
                    wy = vy - rcy
                    nrm = np.sqrt(wx * wx + wy * wy)
                    ux = wx / nrm
                    uy = wy / nrm
                    ld[n_lines, 0] = uy
                    ld[n_lines, 1] = -ux
                    lp[n_lines, 0] = rcx + rad * inv_th_obst * ux
                    lp[n_lines, 1] = rcy + rad * inv_th_obst * uy
                    n_lines += 1
                    continue

                if t < 0.0 or t > 1.0 or same:
                    d_cut = inf
                else:
                    d_cut = (vx - lcx - t * cvx) ** 2 + (vy - lcy - t * cvy) ** 2
                if t_left < 0.0:
                    d_left = inf
                else:
                    d_left = (vx - lcx - t_left * llx) ** 2 + (vy - lcy - t_left * lly) ** 2
                if t_right < 0.0:
                    d_right = inf
                else:
                    d_right = (vx - rcx - t_right * rlx) ** 2 + (vy - rcy - t_right * rly) ** 2

                if d_cut <= d_left and d_cut <= d_right:
                    dx = -ob_dir[o1, 0]
                    dy = -ob_dir[o1, 1]
                    ld[n_lines, 0] = dx
                    ld[n_lines, 1] = dy
                    lp[n_lines, 0] = lcx + rad * inv_th_obst * -dy
                    lp[n_lines, 1] = lcy + rad * inv_th_obst * dx
                    n_lines += 1
                elif d_left <= d_right:
                    if left_foreign:
                        continue
                    ld[n_lines, 0] = llx
                    ld[n_lines, 1] = lly
                    lp[n_lines, 0] = lcx + rad * inv_th_obst * -lly
                    lp[n_lines, 1] = lcy + rad * inv_th_obst * llx
                    n_lines += 1
                else:
                    if right_foreign:
                        continue
                    dx = -rlx
                    dy = -rly
                    ld[n_lines, 0] = dx
                    ld[n_lines, 1] = dy
                    lp[n_lines, 0] = rcx + rad * inv_th_obst * -dy
                    lp[n_lines, 1] = rcy + rad * inv_th_obst * dx
                    n_lines += 1

            n_obst_lines = n_lines

            # ---- agent ORCA lines ----
            for k in range(n_ag):
                b = ag_nb_idx[k]
                rpx = position[e, b, 0] - px
                rpy = position[e, b, 1] - py
                rvx = vx - velocity[e, b, 0]
                rvy = vy - velocity[e, b, 1]
                dist_sq = rpx * rpx + rpy * rpy
                comb_r = rad + radius[e, b]
                comb_r_sq = comb_r * comb_r

                if dist_sq > comb_r_sq:
                    # w: from the cut-off centre to the relative velocity.
                    wx = rvx - inv_th * rpx
                    wy = rvy - inv_th * rpy
                    w_len_sq = wx * wx + wy * wy
                    dot1 = wx * rpx + wy * rpy
                    if dot1 < 0.0 and dot1 * dot1 > comb_r_sq * w_len_sq:
                        w_len = np.sqrt(w_len_sq)
                        ux = wx / w_len
                        uy = wy / w_len
                        dx = uy
                        dy = -ux
                        scale = comb_r * inv_th - w_len
                        ux_ = scale * ux
                        uy_ = scale * uy
                    else:
                        leg = np.sqrt(dist_sq - comb_r_sq)
                        if rpx * wy - rpy * wx > 0.0:
                            dx = (rpx * leg - rpy * comb_r) / dist_sq
                            dy = (rpx * comb_r + rpy * leg) / dist_sq
                        else:
                            dx = -(rpx * leg + rpy * comb_r) / dist_sq
                            dy = -(-rpx * comb_r + rpy * leg) / dist_sq
                        dot2 = rvx * dx + rvy * dy
                        ux_ = dot2 * dx - rvx
                        uy_ = dot2 * dy - rvy
                else:
                    # Overlapping: resolve within one time step instead of the horizon.
                    wx = rvx - inv_dt * rpx
                    wy = rvy - inv_dt * rpy
                    w_len = np.sqrt(wx * wx + wy * wy)
                    ux = wx / w_len
                    uy = wy / w_len
                    dx = uy
                    dy = -ux
                    scale = comb_r * inv_dt - w_len
                    ux_ = scale * ux
                    uy_ = scale * uy

                # Each agent takes half of the responsibility for avoiding the collision; all
                # of it against a last agent that does not reciprocate (the robot).
                share = 1.0 if last_unreciprocated and b == num_agents - 1 else 0.5
                ld[n_lines, 0] = dx
                ld[n_lines, 1] = dy
                lp[n_lines, 0] = vx + share * ux_
                lp[n_lines, 1] = vy + share * uy_
                n_lines += 1

            # ---- solve ----
            fail, rx, ry = _lp2(
                lp, ld, n_lines, vmax, pref_velocity[e, a, 0], pref_velocity[e, a, 1], False
            )
            if fail < n_lines:
                rx, ry = _lp3(lp, ld, n_lines, n_obst_lines, fail, vmax, rx, ry, plp, pld)
            out[e, a, 0] = rx
            out[e, a, 1] = ry


def orca_velocities(
    position: np.ndarray,
    velocity: np.ndarray,
    pref_velocity: np.ndarray,
    radius: np.ndarray,
    max_speed: np.ndarray,
    compute: np.ndarray,
    obstacles: Obstacles | None,
    params: OrcaParams = OrcaParams(),  # noqa: B008 (frozen dataclass, safe as a default)
    env_obstacles: EnvObstacles | None = None,
    blind_last: np.ndarray | None = None,
    last_unreciprocated: bool = False,
) -> np.ndarray:
    """New velocities chosen by ORCA for a batch of independent environments.

    Equivalent to one ``RVOSimulator::doStep`` per environment (velocity part only): every
    agent's neighbours are agents of the same environment and the shared static obstacles.

    Args:
        position: (num_envs, num_agents, 2) agent centres, metres.
        velocity: (num_envs, num_agents, 2) current velocities, m/s.
        pref_velocity: (num_envs, num_agents, 2) preferred velocities, m/s.
        radius: (num_envs, num_agents) agent radii, metres.
        max_speed: (num_envs, num_agents) speed limits, m/s.
        compute: (num_envs, num_agents) bool; agents whose new velocity is wanted. Other agents
            still act as neighbours; their output row is their current velocity.
        obstacles: Static obstacles shared by all environments (None: no obstacles).
        params: Neighbour selection and horizons, shared by all agents.
        env_obstacles: Each environment's own convex obstacles (tables, plants), after the
            shared ones (None: none).
        blind_last: (num_envs, num_agents) bool; an agent marked does not see the last agent
            (a human who ignores the robot). None: every agent sees every other.
        last_unreciprocated: the last agent does not reciprocate (the robot among humans):
            the others take all of the avoidance of a collision with it, not half.

    Returns:
        (num_envs, num_agents, 2) float64 new velocities, m/s.
    """
    position = np.ascontiguousarray(position, dtype=np.float64)
    shape = position.shape
    if position.ndim != 3 or shape[2] != 2:
        raise ValueError(f"position must be (num_envs, num_agents, 2), got {shape}")
    velocity = np.ascontiguousarray(velocity, dtype=np.float64)
    pref_velocity = np.ascontiguousarray(pref_velocity, dtype=np.float64)
    radius = np.ascontiguousarray(np.broadcast_to(radius, shape[:2]), dtype=np.float64)
    max_speed = np.ascontiguousarray(np.broadcast_to(max_speed, shape[:2]), dtype=np.float64)
    compute = np.ascontiguousarray(np.broadcast_to(compute, shape[:2]), dtype=np.bool_)
    if velocity.shape != shape or pref_velocity.shape != shape:
        raise ValueError("velocity and pref_velocity must have the shape of position")
    if obstacles is None:
        obstacles = _NO_OBSTACLES
    if env_obstacles is None:
        env_obstacles = EnvObstacles.empty(shape[0])
    if blind_last is None:
        blind_last = np.zeros(shape[:2], dtype=np.bool_)
    blind_last = np.ascontiguousarray(np.broadcast_to(blind_last, shape[:2]), dtype=np.bool_)
    out = np.empty(shape, dtype=np.float64)
    _orca_kernel(
        position,
        velocity,
        pref_velocity,
        radius,
        max_speed,
        compute,
        obstacles.point,
        obstacles.next_index,
        obstacles.prev_index,
        obstacles.unit_dir,
        obstacles.is_convex,
        obstacles.tree_vertex,
        obstacles.tree_left,
        obstacles.tree_right,
        env_obstacles.point,
        env_obstacles.next_index,
        env_obstacles.unit_dir,
        env_obstacles.is_convex,
        env_obstacles.count,
        blind_last,
        bool(last_unreciprocated),
        float(params.neighbor_dist),
        int(params.max_neighbors),
        float(params.time_horizon),
        float(params.time_horizon_obst),
        float(params.time_step),
        out,
    )
    return out


_NO_OBSTACLES = make_obstacles([])
