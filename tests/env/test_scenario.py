"""Seeds and scenarios: determinism, batch-size and policy invariance, spawn constraints."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.env import EnvParams, Simulator
from pipeline.env.scenario import POLICY_ORCA, POLICY_SFM, uniform_array


def _initial_state(sim: Simulator, slot: int) -> dict[str, np.ndarray]:
    s = sim.state
    return {
        "robot_xy": s.robot_xy[slot].copy(),
        "robot_theta": s.robot_theta[slot].copy(),
        "goal_xy": s.goal_xy[slot].copy(),
        "human_xy": s.human_xy[slot].copy(),
        "human_heading": s.human_heading[slot].copy(),
        "human_speed": s.human_speed[slot].copy(),
        "human_goal": s.human_goal[slot].copy(),
        "human_policy": s.human_policy[slot].copy(),
    }


def _rollout(sim: Simulator, actions: np.ndarray) -> list[np.ndarray]:
    observations = []
    for a in actions:
        observations.append(sim.step(a).obs.copy())
    return observations


def test_same_seed_same_trajectories() -> None:
    actions = np.random.default_rng(0).integers(0, 4, size=(60, 8))
    runs = []
    for _ in range(2):
        sim = Simulator(8, EnvParams())
        sim.reset(seed=42)
        runs.append(_rollout(sim, actions))
    for a, b in zip(*runs, strict=True):
        np.testing.assert_array_equal(a, b)


def test_different_seeds_differ() -> None:
    a = Simulator(4, EnvParams())
    b = Simulator(4, EnvParams())
    obs_a, _ = a.reset(seed=1)
    obs_b, _ = b.reset(seed=2)
    assert not np.allclose(obs_a, obs_b)


@pytest.mark.parametrize("batch", [1, 3, 16])
def test_scenario_i_is_the_same_whatever_the_batch_size_and_slot(batch: int) -> None:
    reference = Simulator(1, EnvParams())
    reference.reset(seed=5, scenario_ids=np.array([7]))
    sim = Simulator(batch, EnvParams())
    ids = np.arange(batch) + 100
    ids[batch // 2] = 7
    sim.reset(seed=5, scenario_ids=ids)
    expected = _initial_state(reference, 0)
    got = _initial_state(sim, batch // 2)
    for key in expected:
        np.testing.assert_array_equal(got[key], expected[key], err_msg=key)


def test_autoreset_hands_out_the_same_scenarios_as_a_fresh_reset() -> None:
    sim = Simulator(2, EnvParams())
    sim.reset(seed=3)
    sim.reset_envs(np.array([1]))  # slot 1 gets scenario 2 (0 and 1 were handed out)
    fresh = Simulator(3, EnvParams())
    fresh.reset(seed=3)
    assert sim.state.scenario_id.tolist() == [0, 2]
    for key, value in _initial_state(fresh, 2).items():
        np.testing.assert_array_equal(_initial_state(sim, 1)[key], value, err_msg=key)


def test_scenario_initial_state_does_not_depend_on_the_policy() -> None:
    """Two policies, same scenarios: identical starts, and ORCA humans (who ignore the robot)
    walk identical paths whatever the robot does."""
    params = EnvParams(human_policy="orca")
    runs = []
    for policy_seed in (0, 1):
        sim = Simulator(6, params)
        sim.reset(seed=11)
        start = [_initial_state(sim, e) for e in range(6)]
        actions = np.random.default_rng(policy_seed).integers(0, 4, size=(30, 6))
        humans = []
        for a in actions:
            sim.step(a)
            humans.append(sim.state.human_xy.copy())
        runs.append((start, humans, sim.state.done.copy()))
    (start_a, humans_a, done_a), (start_b, humans_b, done_b) = runs
    for a, b in zip(start_a, start_b, strict=True):
        for key in a:
            np.testing.assert_array_equal(a[key], b[key])
    running = ~(done_a | done_b)  # finished slots stop updating; compare the others
    np.testing.assert_array_equal(humans_a[-1][running], humans_b[-1][running])


def test_spawned_scenes_respect_the_constraints() -> None:
    params = EnvParams()
    sim = Simulator(2000, params)
    sim.reset(seed=0)
    s = sim.state
    half = params.spawn_half_size
    assert np.all(np.abs(s.robot_xy) <= half) and np.all(np.abs(s.human_xy) <= half)
    assert np.all(np.abs(s.goal_xy) <= half) and np.all(np.abs(s.human_goal) <= half)
    assert np.all(np.linalg.norm(s.goal_xy - s.robot_xy, axis=1) > params.success_distance)
    robot_human = np.linalg.norm(s.human_xy - s.robot_xy[:, None], axis=-1)
    assert np.all(robot_human > params.robot_radius + params.human_radius)
    for i in range(3):
        for j in range(i):
            gap = np.linalg.norm(s.human_xy[:, i] - s.human_xy[:, j], axis=-1)
            assert np.all(gap > 2 * params.human_radius)
    assert np.all((s.human_speed >= 0) & (s.human_speed <= params.human_max_speed))
    np.testing.assert_allclose(np.linalg.norm(s.human_heading, axis=-1), 1.0)


def test_mixed_policy_draws_both_kinds_about_evenly() -> None:
    sim = Simulator(1000, EnvParams(human_policy="mixed"))
    sim.reset(seed=0)
    orca_share = np.mean(sim.state.human_policy == POLICY_ORCA)
    assert 0.45 < orca_share < 0.55
    sfm = Simulator(10, EnvParams(human_policy="sfm"))
    sfm.reset(seed=0)
    assert np.all(sfm.state.human_policy == POLICY_SFM)


def test_counter_based_draws_are_uniform_and_keyed() -> None:
    ids = np.arange(100_000, dtype=np.int64)
    u = uniform_array(9, ids, 1, 0, 0, 0)
    assert u.min() >= 0.0 and u.max() < 1.0
    assert abs(u.mean() - 0.5) < 0.005
    counts, _ = np.histogram(u, bins=10, range=(0, 1))
    assert counts.min() > 9_500 and counts.max() < 10_500
    np.testing.assert_array_equal(u, uniform_array(9, ids, 1, 0, 0, 0))
    assert not np.array_equal(u, uniform_array(9, ids, 1, 0, 0, 1))


def test_impossible_room_gives_a_clear_error() -> None:
    sim = Simulator(1, EnvParams(num_humans=60, room_size=3.0, spawn_margin=0.3))
    with pytest.raises(RuntimeError, match="could not place 60 humans"):
        sim.reset(seed=0)
