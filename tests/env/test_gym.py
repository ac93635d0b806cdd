"""The gymnasium front-ends: registration, check_env, the vector env and option validation."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import socnav_wm  # noqa: F401  (registers SocNav-v0)
from socnav_wm.env.gym import SocNavEnv, SocNavVectorEnv


def test_make_passes_gymnasiums_env_checker() -> None:
    env = gym.make("SocNav-v0")
    check_env(env.unwrapped, skip_render_check=True)
    obs, info = env.reset(seed=0)
    assert obs.shape == (23,) and obs.dtype == np.float32
    assert env.action_space == gym.spaces.Discrete(4)
    assert {"robot_xy", "human_xy", "scenario_id"} <= set(info)


def test_continuous_action_type_passes_the_checker() -> None:
    env = gym.make("SocNav-v0", action_type="continuous")
    check_env(env.unwrapped, skip_render_check=True)
    np.testing.assert_allclose(env.action_space.high, [0.14, 0.387596899])


def test_step_info_carries_what_metrics_need() -> None:
    env = gym.make("SocNav-v0")
    env.reset(seed=3)
    _, reward, terminated, truncated, info = env.step(1)
    assert isinstance(reward, float) and isinstance(terminated, bool)
    assert info["robot_xy"].shape == (2,) and info["human_xy"].shape == (3, 2)
    assert info["collision"] in ("none", "human", "wall")
    assert isinstance(info["dmin"], float) and isinstance(info["success"], bool)


def test_single_env_resets_walk_through_the_seeds_scenarios() -> None:
    env = SocNavEnv()
    first, _ = env.reset(seed=5)
    second, info = env.reset()
    assert info["scenario_id"] == 1
    again, _ = env.reset(seed=5)
    np.testing.assert_array_equal(first, again)
    picked, info = env.reset(options={"scenario_id": 1})
    np.testing.assert_array_equal(picked, second)


def test_make_vec_returns_the_batched_env() -> None:
    envs = gym.make_vec("SocNav-v0", num_envs=8, human_policy="sfm")
    assert isinstance(envs.unwrapped, SocNavVectorEnv)
    obs, info = envs.reset(seed=0)
    assert obs.shape == (8, 23) and info["robot_xy"].shape == (8, 2)
    obs, reward, terminated, truncated, info = envs.step(np.ones(8, dtype=np.int64))
    assert reward.shape == (8,) and terminated.dtype == bool


def test_vector_env_autoresets_in_the_same_step() -> None:
    envs = SocNavVectorEnv(num_envs=4)
    envs.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(300):
        obs, reward, terminated, truncated, info = envs.step(rng.integers(0, 4, 4))
        ended = terminated | truncated
        if ended.any():
            break
    assert ended.any()
    assert info["_final_obs"].tolist() == ended.tolist()
    e = int(np.flatnonzero(ended)[0])
    assert not np.array_equal(info["final_obs"][e], obs[e])  # obs is the new episode's first
    assert info["step"][e] == 0 and info["scenario_id"][e] >= 4
    assert info["final_info"]["step"][e] > 0


def test_vector_env_matches_the_single_env_for_the_same_scenario() -> None:
    single = SocNavEnv()
    batch = SocNavVectorEnv(num_envs=3)
    obs_single, _ = single.reset(seed=9, options={"scenario_id": 2})
    obs_batch, _ = batch.reset(seed=9)
    np.testing.assert_array_equal(obs_single, obs_batch[2])


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"human_policy": "bogus"}, "env.human_policy: must be one of mixed, sfm, orca"),
        ({"reward": "sparse"}, "env.reward: must be one of paper, dense"),
        ({"num_humans": -1}, "env.num_humans: must be >= 0"),
        ({"num_humans": 2.5}, "env.num_humans: expected an integer"),
        ({"room_size": 0}, "env.room_size: must be > 0"),
        ({"human_max_speed": "fast"}, "env.human_max_speed: expected a number"),
        ({"swept_collision": "yes"}, "env.swept_collision: expected true or false"),
        ({"colour": "red"}, "env: unknown option"),
        ({"action_type": "joystick"}, "action_type: must be one of discrete, continuous"),
    ],
)
def test_bad_options_are_rejected_with_a_clear_message(options: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        gym.make("SocNav-v0", **options)


def test_scenario_parameters_are_options_of_make() -> None:
    env = gym.make("SocNav-v0", num_humans=5, room_size=12.0, human_policy="orca", reward="dense")
    obs, _ = env.reset(seed=0)
    assert obs.shape == (2 + 7 * 5,)
    assert env.unwrapped.params.room_size == 12.0


def test_render_returns_an_rgb_frame() -> None:
    env = gym.make("SocNav-v0", render_mode="rgb_array")
    env.reset(seed=0)
    env.step(1)
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.shape[2] == 3


@pytest.mark.parametrize("action", [1.5, True, np.float64(1.0), np.bool_(True), 4, -1, 2**70])
def test_single_env_refuses_non_integer_or_out_of_range_actions(action) -> None:
    env = SocNavEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"action: expected integers in 0\.\.3"):
        env.step(action)


def test_single_env_accepts_python_and_numpy_integers() -> None:
    env = SocNavEnv()
    env.reset(seed=0)
    for action in (1, np.int64(2), np.uint8(3), np.int32(0)):
        env.step(action)


@pytest.mark.parametrize(
    "actions",
    [np.ones(4, dtype=bool), np.ones(4) * 1.5, np.array([0, 1, 2, 4]), np.array([0, -1, 1, 2])],
)
def test_vector_env_refuses_non_integer_or_out_of_range_actions(actions) -> None:
    envs = SocNavVectorEnv(num_envs=4)
    envs.reset(seed=0)
    with pytest.raises(ValueError, match=r"action: expected integers in 0\.\.3"):
        envs.step(actions)


def test_huge_seeds_are_reduced_and_in_range_seeds_unchanged() -> None:
    env = SocNavEnv()
    small, _ = env.reset(seed=7)
    from socnav_wm.env import Simulator

    sim = Simulator(1)
    np.testing.assert_array_equal(sim.reset(seed=7)[0][0], small)
    a, _ = env.reset(seed=2**63)
    b, _ = env.reset(seed=2**63 + 2**64)
    np.testing.assert_array_equal(a, b)
    env.reset(seed=2**64)
    env.reset(seed=2**70)
    env.step(env.action_space.sample())
    envs = SocNavVectorEnv(num_envs=2)
    envs.reset(seed=2**64 - 1)
    envs.step(np.array([1, 1]))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"seed": -1}, "seed: expected a non-negative integer"),
        ({"options": {"scenario_id": 2**70}}, "scenario_id: expected an integer in"),
        ({"options": {"scenario_id": 2**62}}, "scenario_id: expected an integer in"),
    ],
)
def test_bad_seeds_and_scenario_ids_are_one_line_value_errors(kwargs, message) -> None:
    env = SocNavEnv()
    with pytest.raises(ValueError, match=message) as info:
        env.reset(**kwargs)
    assert "\n" not in str(info.value)


def test_vector_env_refuses_huge_scenario_ids() -> None:
    envs = SocNavVectorEnv(num_envs=1)
    with pytest.raises(ValueError, match="scenario_ids: expected integers in"):
        envs.reset(seed=0, options={"scenario_ids": np.array([2**70])})
    with pytest.raises(ValueError, match="seed: expected a non-negative integer"):
        envs.reset(seed=-3)


@pytest.mark.parametrize("max_steps", [201, 230])
def test_the_episode_truncates_once_at_its_own_max_steps(max_steps: int) -> None:
    """No TimeLimit is registered: the env's own truncation ends the episode, also at a
    `max_steps` above the default."""
    env = gym.make("SocNav-v0", num_humans=0, max_steps=max_steps)
    assert env.spec.max_episode_steps is None
    env.reset(seed=0)
    ends = []
    for step in range(1, max_steps + 1):
        _, _, terminated, truncated, _ = env.step(0)  # stop: the robot never leaves its spot
        if terminated or truncated:
            ends.append((step, terminated, truncated))
    assert ends == [(max_steps, False, True)]
    envs = gym.make_vec("SocNav-v0", num_envs=2)
    assert envs.unwrapped.params.max_steps == 201


def test_the_core_install_is_enough_for_the_environment() -> None:
    """The simulator and its gymnasium env need only the core dependencies: making and
    stepping the env imports none of the pipeline's (torch, MLflow, DVC, pyarrow, the CLI)."""
    import subprocess
    import sys

    code = (
        "import sys, gymnasium as gym\n"
        "env = gym.make('socnav_wm:SocNav-v0')\n"
        "env.reset(seed=0); env.step(1)\n"
        "heavy = ('torch', 'mlflow', 'dvc', 'pyarrow', 'typer', 'matplotlib', 'rich')\n"
        "print(sorted(m for m in heavy if m in sys.modules))\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"
