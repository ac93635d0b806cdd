"""The gymnasium wrappers give a library agent what the project's trainer adds: the same
shaped rewards and the same nearest-first observations, step for step."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch

import socnav_wm  # noqa: F401 - registers SocNav-v0
from socnav_wm.agents.features import sort_humans_by_distance
from socnav_wm.env import EnvParams, Simulator
from socnav_wm.env.wrappers import (
    NearestHumansFirst,
    ProgressReward,
    goal_distance,
    nearest_first,
    progress_shaping,
)


def test_the_wrappers_reproduce_the_trainers_shaping_and_ordering() -> None:
    """One scenario through the wrapped gymnasium env and through the batched simulator with
    the trainer's own functions: identical rewards and observations at every step."""
    weight, scenario, seed = 1.0, 7, 123
    env = NearestHumansFirst(ProgressReward(gym.make("SocNav-v0"), weight=weight))
    obs, _ = env.reset(seed=seed, options={"scenario_id": scenario})
    sim = Simulator(1, EnvParams())
    raw, _ = sim.reset(seed=seed, scenario_ids=np.array([scenario]))
    before = goal_distance(raw)
    rng = np.random.default_rng(0)
    steps = 0
    while True:
        expected_obs = sort_humans_by_distance(torch.as_tensor(raw)).numpy()[0]
        np.testing.assert_array_equal(obs, expected_obs)  # the trainer's ordering
        action = int(rng.integers(0, 4))
        obs, reward, terminated, truncated, info = env.step(action)
        result = sim.step(np.array([action]))
        raw, after = result.obs, goal_distance(result.obs)
        expected = progress_shaping(result.reward, before, after, weight)[0]
        assert reward == pytest.approx(expected, abs=1e-12)
        assert info["env_reward"] == pytest.approx(result.reward[0], abs=1e-12)
        before, steps = after, steps + 1
        if terminated or truncated:
            break
    assert steps > 1


def test_nearest_first_equals_the_trainers_sort_on_a_batch() -> None:
    sim = Simulator(256, EnvParams(num_humans=5))
    obs, _ = sim.reset(seed=3)
    np.testing.assert_array_equal(nearest_first(obs), sort_humans_by_distance(torch.as_tensor(obs)))
    distances = np.hypot(nearest_first(obs)[:, 2::7], nearest_first(obs)[:, 3::7])
    assert np.all(np.diff(distances, axis=1) >= 0)


def test_progress_reward_needs_reset_and_a_valid_weight() -> None:
    with pytest.raises(ValueError, match="weight"):
        ProgressReward(gym.make("SocNav-v0"), weight=-1.0)
    env = ProgressReward(gym.make("SocNav-v0"))
    with pytest.raises(RuntimeError, match="reset"):
        env.step(0)
