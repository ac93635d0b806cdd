"""Human motion: SFM behaviour on simple scenes, and invariants over random episodes."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from socnav_wm.env import EnvParams, Simulator
from socnav_wm.env.humans import move_humans
from socnav_wm.env.scenario import draw_human_goal

STOP = 0


def _one_human(policy: str, xy, goal, **params) -> Simulator:
    sim = Simulator(
        1, EnvParams(num_humans=1, human_policy=policy, humans_see_robot=False, **params)
    )
    sim.reset(seed=0)
    s = sim.state
    s.robot_xy[0] = (-4.0, -4.0)
    s.goal_xy[0] = (4.0, 4.0)
    s.human_xy[0, 0] = xy
    s.human_goal[0, 0] = goal
    s.human_speed[0, 0] = 0.0
    return sim


def test_lone_sfm_human_walks_straight_to_its_goal_at_a_weighted_speed() -> None:
    sim = _one_human("sfm", (0.0, 0.0), (3.0, 0.0))
    sim.step(np.array([STOP]))
    np.testing.assert_allclose(sim.state.human_xy[0, 0], [0.14 / np.sqrt(3), 0.0], atol=1e-12)
    # The SFM desired force is weighted by 1/√3 and m = 1, dt = 1: speed 0.14/√3 ≈ 0.081 m/s.
    assert sim.state.human_speed[0, 0] == pytest.approx(0.14 / np.sqrt(3), rel=1e-12)


def test_lone_orca_human_walks_straight_to_its_goal_at_full_speed() -> None:
    sim = _one_human("orca", (0.0, 0.0), (3.0, 0.0))
    sim.step(np.array([STOP]))
    np.testing.assert_allclose(sim.state.human_xy[0, 0], [0.14, 0.0], atol=1e-6)


def test_sfm_walls_push_a_human_back_inside() -> None:
    # 0.02 m from the right wall, walking along it: the wall force pushes it inwards.
    sim = _one_human("sfm", (4.8 - 0.36 - 0.02, 0.0), (4.4, 3.0))
    sim.step(np.array([STOP]))
    assert sim.state.human_xy[0, 0, 0] < 4.8 - 0.36 - 0.02


def test_sfm_humans_facing_each_other_deflect() -> None:
    sim = Simulator(1, EnvParams(num_humans=2, human_policy="sfm", humans_see_robot=False))
    sim.reset(seed=0)
    s = sim.state
    s.robot_xy[0] = (-4.0, -4.0)
    s.human_xy[0] = [(-0.5, 0.0), (0.5, 0.0)]
    s.human_goal[0] = [(4.0, 0.0), (-4.0, 0.0)]
    s.human_speed[0] = 0.1
    s.human_heading[0] = [(1.0, 0.0), (-1.0, 0.0)]
    sim.step(np.array([STOP]))
    # Head-on, the interaction force has a sideways (normal) part: both leave the x axis.
    assert abs(s.human_xy[0, 0, 1]) > 1e-3 and abs(s.human_xy[0, 1, 1]) > 1e-3


def test_a_pair_force_computed_once_is_what_either_human_would_compute() -> None:
    """The kernel computes each SFM pair from the lower index's side and gives the other human
    the negation: with two humans, swapping their slots must give each the same velocity, bit
    for bit (the pair term is the last one summed, so the order of the sums is unchanged)."""
    sim = Simulator(16, EnvParams(num_humans=2, human_policy="sfm", humans_see_robot=False))
    sim.reset(seed=3)
    for _ in range(5):  # moving humans: the velocity difference enters the force
        sim.step(np.ones(16, dtype=np.int64))
    dynamics = sim._humans
    before = dynamics.velocities(0, sim.state).copy()
    swapped = sim.state.copy()
    for name in ("human_xy", "human_heading", "human_speed", "human_goal", "human_policy",
                 "human_max_speed", "human_sees_robot"):  # fmt: skip
        getattr(swapped, name)[:] = getattr(sim.state, name)[:, ::-1]
    after = dynamics.velocities(0, swapped)
    assert np.any(before != 0.0)
    assert np.array_equal(after[:, ::-1], before)


def test_a_human_at_its_goal_draws_the_next_goal_of_its_sequence() -> None:
    sim = _one_human("orca", (1.0, 1.0), (1.05, 1.0))
    sim.step(np.array([STOP]))
    s = sim.state
    assert s.human_goal_index[0, 0] == 1
    p = sim.params
    old_goal = np.array([1.05, 1.0])
    for attempt in range(100):  # the first attempt whose disc touches nothing
        g = np.array(draw_human_goal(sim.seed, int(s.scenario_id[0]), 0, 1, attempt, 4.5))
        free = (
            np.abs(g).max() + p.human_goal_radius < p.wall_half_size
            and np.linalg.norm(g - s.robot_xy[0]) > p.robot_radius + p.human_goal_radius
            and np.linalg.norm(g - s.human_xy[0, 0]) > p.human_radius + p.human_goal_radius
            and np.linalg.norm(g - old_goal) > 2 * p.human_goal_radius
            and np.linalg.norm(g - s.goal_xy[0]) > p.goal_radius + p.human_goal_radius
        )
        if free:
            break
    np.testing.assert_array_equal(s.human_goal[0, 0], g)


def test_speeds_below_the_threshold_stop_the_human() -> None:
    xy = np.array([[[0.0, 0.0]]])
    heading = np.array([[[1.0, 0.0]]])
    speed = np.zeros((1, 1))
    goal = np.array([[[3.0, 0.0]]])
    move_humans(
        0, np.array([0]), np.array([True]), np.array([[[0.0, 0.04]]]), xy, heading, speed, goal,
        np.zeros((1, 1), dtype=np.int64), np.array([[-4.0, -4.0]]), np.array([[4.0, 4.0]]),
        np.zeros((1, 0), dtype=np.int8), np.zeros((1, 0, 2)), np.zeros((1, 0, 2)),
        np.full((1, 1), -1), np.zeros((1, 0), dtype=np.int64), np.zeros((1, 0), dtype=bool), False,
        0.05, 4.8, 4.5, 0.36, 0.3, 0.25, 0.5, 1.0,
    )  # fmt: skip
    assert speed[0, 0] == 0.0
    np.testing.assert_array_equal(xy[0, 0], [0.0, 0.0])
    np.testing.assert_allclose(heading[0, 0], [0.0, 1.0])  # the heading still follows v


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    policy=st.sampled_from(["mixed", "sfm", "orca"]),
    num_humans=st.integers(1, 5),
    action_seed=st.integers(0, 1000),
)
def test_random_episodes_keep_every_invariant(
    seed: int, policy: str, num_humans: int, action_seed: int
) -> None:
    params = EnvParams(num_humans=num_humans, human_policy=policy)
    sim = Simulator(8, params)
    sim.reset(seed=seed)
    rng = np.random.default_rng(action_seed)
    limit = params.wall_half_size - params.human_radius
    for _ in range(60):
        actions = rng.integers(0, 4, size=8)
        result = sim.step(actions)
        s = sim.state
        assert np.all(np.isfinite(s.robot_xy)) and np.all(np.isfinite(s.human_xy))
        assert np.all(np.isfinite(result.obs)) and np.all(np.isfinite(result.reward))
        assert np.all(np.abs(s.human_xy) <= limit + 1e-12)
        assert np.all(np.abs(s.robot_xy) < params.room_size / 2)
        assert np.all((s.human_speed >= 0) & (s.human_speed <= params.human_max_speed + 1e-9))
        np.testing.assert_allclose(np.linalg.norm(s.human_heading, axis=-1), 1.0, atol=1e-9)
        assert np.all(np.abs(s.robot_theta) <= np.pi)
        sim.reset_envs(result.terminated | result.truncated)


def test_no_human_moves_more_than_max_speed_dt_over_1000_random_episodes() -> None:
    params = EnvParams(human_policy="mixed")
    sim = Simulator(1000, params)
    sim.reset(seed=0)
    rng = np.random.default_rng(0)
    worst = 0.0
    while not sim.state.done.all():
        active = ~sim.state.done
        before = sim.state.human_xy.copy()
        sim.step(rng.integers(0, 4, size=1000))
        step = np.linalg.norm(sim.state.human_xy - before, axis=-1)[active]
        worst = max(worst, float(step.max()))
    assert worst <= params.human_max_speed * params.dt + 1e-9


def test_velocities_are_capped_at_max_speed_whatever_the_policy_returns(monkeypatch) -> None:
    from socnav_wm.env import humans

    params = EnvParams(human_policy="orca")
    sim = Simulator(1, params)
    sim.reset(seed=0)
    too_fast = np.full((1, params.num_humans, 2), 0.2)
    monkeypatch.setattr(humans.HumanDynamics, "_orca", lambda self, state, still: too_fast)
    before = sim.state.human_xy.copy()
    sim.step(np.array([0]))
    step = np.linalg.norm(sim.state.human_xy - before, axis=-1)
    assert step.max() <= params.human_max_speed * params.dt + 1e-9
