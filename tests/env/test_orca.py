"""Tests of the batched ORCA port against the RVO2 library and on hand-checkable scenes."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pytest

from socnav_wm.env.orca import (
    Obstacles,
    OrcaParams,
    make_obstacles,
    orca_velocities,
    room_obstacles,
)

rvo2 = pytest.importorskip("rvo2")

HALF_SIZE = 4.8
RADIUS = 0.36
MAX_SPEED = 0.14
TOL = 1e-3  # m/s
MIN_AGREEMENT = 0.99


def _room_polygon(h: float) -> np.ndarray:
    # Clockwise: the free space is inside, as in room_obstacles.
    return np.array([[-h, -h], [-h, h], [h, h], [h, -h]])


# Interior obstacles that make RVO2 split edges while building its obstacle tree: a box, a
# free-standing segment, a non-convex L and a triangle (all counter-clockwise = solid).
INTERIOR_POLYGONS = [
    np.array([[-1.0, -0.5], [1.0, -0.5], [1.0, 0.5], [-1.0, 0.5]]),
    np.array([[-3.0, 2.0], [3.0, 2.5]]),
    np.array([[1.5, -3.0], [3.5, -3.0], [3.5, -1.0], [2.5, -1.0], [2.5, -2.0], [1.5, -2.0]]),
    np.array([[-3.5, -3.5], [-2.0, -1.0], [-3.8, -1.5]]),
]


def _rvo2_velocities(
    position: np.ndarray,
    velocity: np.ndarray,
    pref_velocity: np.ndarray,
    radius: np.ndarray,
    max_speed: np.ndarray,
    compute: np.ndarray,
    polygons: Sequence[np.ndarray],
    params: OrcaParams,
) -> np.ndarray:
    """Reference: one RVO2 simulator per scene, one doStep each."""
    num_envs, num_agents = position.shape[:2]
    out = velocity.copy()
    p = params
    for e in range(num_envs):
        sim = rvo2.PyRVOSimulator(
            p.time_step, p.neighbor_dist, p.max_neighbors, p.time_horizon,
            p.time_horizon_obst, RADIUS, MAX_SPEED,
        )  # fmt: skip
        for a in range(num_agents):
            sim.addAgent(
                tuple(position[e, a]), p.neighbor_dist, p.max_neighbors, p.time_horizon,
                p.time_horizon_obst, float(radius[e, a]), float(max_speed[e, a]),
                tuple(velocity[e, a]),
            )  # fmt: skip
            sim.setAgentPrefVelocity(a, tuple(pref_velocity[e, a]))
        for poly in polygons:
            sim.addObstacle([tuple(v) for v in poly.tolist()])
        sim.processObstacles()
        sim.doStep()
        for a in range(num_agents):
            if compute[e, a]:
                out[e, a] = sim.getAgentVelocity(a)
    return out


def _random_velocity(rng: np.random.Generator, max_speed: np.ndarray) -> np.ndarray:
    speed = max_speed * np.sqrt(rng.uniform(0.0, 1.0, max_speed.shape))
    angle = rng.uniform(0.0, 2.0 * np.pi, max_speed.shape)
    return np.stack([speed * np.cos(angle), speed * np.sin(angle)], axis=-1)


def _to_float32(*arrays: np.ndarray) -> list[np.ndarray]:
    # RVO2 stores float32: feed both implementations the same representable numbers.
    return [np.asarray(x, dtype=np.float32).astype(np.float64) for x in arrays]


def _compare(ours: np.ndarray, ref: np.ndarray, compute: np.ndarray, label: str) -> None:
    dev = np.linalg.norm(ours - ref, axis=-1)[compute]
    n_bad = int(np.sum(dev > TOL))
    msg = (
        f"{label}: {n_bad} of {dev.size} agents disagree with RVO2 by more than {TOL} m/s; "
        f"max deviation {dev.max():.3g} m/s, 99.9th percentile {np.percentile(dev, 99.9):.3g} m/s"
    )
    print(msg)
    assert n_bad <= (1.0 - MIN_AGREEMENT) * dev.size, msg


def test_agreement_with_rvo2_paper_parameters() -> None:
    """Scenes like the simulator's: 3 or 4 agents, radius 0.36, max speed 0.14, room walls."""
    rng = np.random.default_rng(1234)
    num_envs, num_agents = 3000, 4
    position = rng.uniform(-4.5, 4.5, (num_envs, num_agents, 2))

    # Overlapping pairs exercise the collision (1 / time_step) branch.
    overlap = rng.uniform(size=num_envs) < 0.25
    dist = rng.uniform(0.02, 2 * RADIUS, overlap.sum())
    ang = rng.uniform(0.0, 2.0 * np.pi, overlap.sum())
    position[overlap, 1] = position[overlap, 0] + np.stack(
        [dist * np.cos(ang), dist * np.sin(ang)], axis=-1
    )
    # Agents within ~1 m of a wall (some overlapping it, some in corners) exercise the
    # obstacle lines.
    near_wall = rng.uniform(size=(num_envs, num_agents, 2)) < 0.2
    position[near_wall] = rng.choice([-1.0, 1.0], near_wall.sum()) * rng.uniform(
        3.8, 4.6, near_wall.sum()
    )

    radius = np.full((num_envs, num_agents), RADIUS)
    max_speed = np.full((num_envs, num_agents), MAX_SPEED)
    velocity = _random_velocity(rng, max_speed)
    to_goal = rng.uniform(-4.5, 4.5, (num_envs, num_agents, 2)) - position
    pref_velocity = MAX_SPEED * to_goal / np.linalg.norm(to_goal, axis=-1, keepdims=True)
    position, velocity, pref_velocity = _to_float32(position, velocity, pref_velocity)

    # One batch for all scenes: 4/5 of them have 3 agents, whose 4th slot is parked far outside
    # the room (beyond everyone's neighbour distance) and not computed.
    compute = np.ones((num_envs, num_agents), dtype=bool)
    three = rng.uniform(size=num_envs) < 0.8
    compute[three, 3] = False
    position[three, 3] = 1000.0

    params = OrcaParams()
    ours = orca_velocities(
        position, velocity, pref_velocity, radius, max_speed, compute,
        room_obstacles(HALF_SIZE), params,
    )  # fmt: skip
    ref = _rvo2_velocities(
        position, velocity, pref_velocity, radius, max_speed, compute,
        [_room_polygon(HALF_SIZE)], params,
    )  # fmt: skip
    np.testing.assert_array_equal(ours[~compute], velocity[~compute])
    _compare(ours, ref, compute, "paper parameters")


@pytest.mark.parametrize(
    ("params", "num_agents"),
    [
        (OrcaParams(10.0, 10, 2.0, 1.5, 0.25), 6),
        (OrcaParams(3.0, 2, 8.0, 3.0, 0.5), 7),
    ],
)
def test_agreement_with_rvo2_other_parameters(params: OrcaParams, num_agents: int) -> None:
    """Per-agent radii and speeds, interior obstacles (with split edges), other horizons."""
    rng = np.random.default_rng(num_agents)
    num_envs = 300
    position = rng.uniform(-4.5, 4.5, (num_envs, num_agents, 2))
    radius = rng.uniform(0.15, 0.5, (num_envs, num_agents))
    max_speed = rng.uniform(0.1, 1.5, (num_envs, num_agents))
    velocity = _random_velocity(rng, max_speed)
    # Preferred speeds up to 1.3x the maximum exercise the clipping to the speed disc.
    to_goal = rng.uniform(-4.5, 4.5, (num_envs, num_agents, 2)) - position
    pref_speed = max_speed * rng.uniform(0.0, 1.3, (num_envs, num_agents))
    pref_velocity = to_goal / np.linalg.norm(to_goal, axis=-1, keepdims=True)
    pref_velocity *= pref_speed[..., None]
    position, velocity, pref_velocity, radius, max_speed = _to_float32(
        position, velocity, pref_velocity, radius, max_speed
    )
    compute = rng.uniform(size=(num_envs, num_agents)) < 0.9

    polygons = [_room_polygon(HALF_SIZE), *INTERIOR_POLYGONS]
    ours = orca_velocities(
        position, velocity, pref_velocity, radius, max_speed, compute,
        make_obstacles(polygons), params,
    )  # fmt: skip
    ref = _rvo2_velocities(
        position, velocity, pref_velocity, radius, max_speed, compute, polygons, params
    )
    np.testing.assert_array_equal(ours[~compute], velocity[~compute])
    _compare(ours, ref, compute, f"{params}, {num_agents} agents")


def test_obstacle_structure_matches_rvo2() -> None:
    polygons = [_room_polygon(HALF_SIZE), *INTERIOR_POLYGONS]
    obstacles = make_obstacles(polygons)
    sim = rvo2.PyRVOSimulator(1.0, 1.44, 3, 5.0, 5.0, RADIUS, MAX_SPEED)
    for poly in polygons:
        sim.addObstacle([tuple(v) for v in poly.tolist()])
    sim.processObstacles()
    n = sim.getNumObstacleVertices()
    assert obstacles.num_vertices == n > sum(len(p) for p in polygons)  # some edges were split
    points = np.array([sim.getObstacleVertex(i) for i in range(n)])
    np.testing.assert_allclose(obstacles.point, points, atol=1e-6)
    assert [sim.getNextObstacleVertexNo(i) for i in range(n)] == obstacles.next_index.tolist()
    assert [sim.getPrevObstacleVertexNo(i) for i in range(n)] == obstacles.prev_index.tolist()
    np.testing.assert_allclose(np.linalg.norm(obstacles.unit_dir, axis=1), 1.0)

    room = room_obstacles(HALF_SIZE)
    assert room.num_vertices == 4
    # A "negative" (clockwise) polygon is non-convex at every corner.
    assert not room.is_convex.any()


def _single(
    position: Sequence[Sequence[float]],
    velocity: Sequence[Sequence[float]],
    pref_velocity: Sequence[Sequence[float]],
    obstacles: Obstacles | None,
    max_speed: float = MAX_SPEED,
) -> np.ndarray:
    pos = np.asarray(position, dtype=np.float64)[None]
    n = pos.shape[1]
    return orca_velocities(
        pos,
        np.asarray(velocity, dtype=np.float64)[None],
        np.asarray(pref_velocity, dtype=np.float64)[None],
        np.full((1, n), RADIUS),
        np.full((1, n), max_speed),
        np.ones((1, n), dtype=bool),
        obstacles,
    )[0]


@pytest.mark.parametrize("obstacles", [None, room_obstacles(HALF_SIZE)])
def test_lone_agent_gets_preferred_velocity(obstacles: Obstacles | None) -> None:
    out = _single([[0.3, -0.2]], [[0.05, 0.1]], [[0.1, -0.06]], obstacles)
    np.testing.assert_array_equal(out[0], [0.1, -0.06])
    # Too fast: clipped onto the max-speed circle, same direction.
    out = _single([[0.3, -0.2]], [[0.05, 0.1]], [[0.3, 0.4]], obstacles)
    np.testing.assert_allclose(out[0], [0.6 * MAX_SPEED, 0.8 * MAX_SPEED], rtol=1e-12)


def _min_distance(p: np.ndarray, v: np.ndarray, horizon: float) -> float:
    """Closest approach within [0, horizon] of two points moving at constant velocity."""
    dp = p[1] - p[0]
    dv = v[1] - v[0]
    t = np.clip(-(dp @ dv) / max(dv @ dv, 1e-300), 0.0, horizon)
    return float(np.linalg.norm(dp + t * dv))


def test_head_on_agents_avoid_each_other() -> None:
    p = np.array([[-0.7, 0.0], [0.7, 0.0]])
    v = np.array([[MAX_SPEED, 0.0], [-MAX_SPEED, 0.0]])
    horizon = OrcaParams().time_horizon
    assert _min_distance(p, v, horizon) < 2 * RADIUS  # they would collide
    new_v = _single(p, v, v, None)
    assert np.all(np.linalg.norm(new_v, axis=1) <= MAX_SPEED + 1e-12)
    assert _min_distance(p, new_v, horizon) >= 2 * RADIUS - 1e-9
    # Reciprocity: each takes half of the avoidance, so the answer is symmetric.
    np.testing.assert_allclose(new_v[0], -new_v[1], atol=1e-12)


@pytest.mark.parametrize("max_speed", [MAX_SPEED, 1.0])
def test_agent_does_not_cross_wall(max_speed: float) -> None:
    obstacles = room_obstacles(HALF_SIZE)
    pos = np.array([[4.0, 0.3]])
    vel = np.array([[max_speed, 0.0]])
    pref = np.array([[max_speed, 0.02]])
    for _ in range(60):
        vel = _single(pos, vel, pref, obstacles, max_speed)
        pos = pos + vel * OrcaParams().time_step
        assert pos[0, 0] + RADIUS <= HALF_SIZE + 1e-9
    assert pos[0, 0] > HALF_SIZE - RADIUS - 0.05  # it did get close, sliding along


def test_compute_false_rows_and_batch_independence() -> None:
    rng = np.random.default_rng(7)
    num_envs, num_agents = 64, 4
    position = rng.uniform(-2.0, 2.0, (num_envs, num_agents, 2))
    velocity = rng.uniform(-0.1, 0.1, (num_envs, num_agents, 2))
    pref = rng.uniform(-0.1, 0.1, (num_envs, num_agents, 2))
    radius = np.full((num_envs, num_agents), RADIUS)
    max_speed = np.full((num_envs, num_agents), MAX_SPEED)
    compute = rng.uniform(size=(num_envs, num_agents)) < 0.7
    room = room_obstacles(HALF_SIZE)

    out = orca_velocities(position, velocity, pref, radius, max_speed, compute, room)
    np.testing.assert_array_equal(out[~compute], velocity[~compute])
    assert not np.array_equal(out[compute], velocity[compute])
    for e in (0, 17, 63):
        alone = orca_velocities(
            position[e : e + 1], velocity[e : e + 1], pref[e : e + 1], radius[e : e + 1],
            max_speed[e : e + 1], compute[e : e + 1], room,
        )  # fmt: skip
        np.testing.assert_array_equal(alone[0], out[e])

    # A non-computed agent is still a neighbour: removing it changes the others' answers.
    crowd = np.array([[[0.0, 0.0], [0.8, 0.0]]])
    vel = np.array([[[MAX_SPEED, 0.0], [0.0, 0.0]]])
    ones = np.ones((1, 2))
    with_neighbor = orca_velocities(
        crowd, vel, vel, RADIUS * ones, MAX_SPEED * ones, np.array([[True, False]]), None
    )
    alone = orca_velocities(
        crowd[:, :1], vel[:, :1], vel[:, :1], RADIUS * ones[:, :1], MAX_SPEED * ones[:, :1],
        np.array([[True]]), None,
    )  # fmt: skip
    assert not np.allclose(with_neighbor[0, 0], alone[0, 0])
    np.testing.assert_array_equal(with_neighbor[0, 1], vel[0, 1])
