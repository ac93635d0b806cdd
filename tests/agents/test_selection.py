"""The model selection's greedy run: the same success rate as the episode runner, cheaper."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from socnav_wm.agents.agent_file import Agent, greedy_episodes, load_world_model, variant_for
from socnav_wm.agents.dueling import DuelingQNetwork
from socnav_wm.agents.params import AgentParams
from socnav_wm.agents.training import greedy_success_rate, success_rate
from socnav_wm.env import EnvParams

ENV = EnvParams(room_size=6.0, max_steps=30)
PARAMS = AgentParams(trunk_sizes=(32,), stream_size=16, device="cpu")


@pytest.mark.parametrize("variant", ["dueling-dqn", "2stepahead-maspm"])
@pytest.mark.parametrize("batch_size", [500, 7])
def test_greedy_success_rate_is_the_episode_runners(
    variant: str, batch_size: int, world_model_files: tuple[Path, Path]
) -> None:
    vae, lstm = load_world_model(variant, *world_model_files, "cpu")
    features = variant_for(variant, vae, lstm, PARAMS, obs_dim=23, device="cpu")
    rates = set()
    for seed in range(4):  # a few random networks: some succeed, some collide, some time out
        torch.manual_seed(seed)
        q_network = DuelingQNetwork(features.feature_dim, trunk_sizes=(32,), stream_size=16)
        agent = Agent(q_network, features, PARAMS, ENV)
        episodes = greedy_episodes(agent, ENV, seed=seed, scenario_ids=range(20), batch_size=7)
        expected = success_rate(episodes)
        fresh = agent.fresh_variant()
        rate = greedy_success_rate(
            q_network, fresh, ENV, seed=seed, episodes=20, batch_size=batch_size
        )
        assert rate == expected
        rates.add(rate)
    assert len(rates) > 1  # the networks differ in what they achieve: the check is not vacuous
