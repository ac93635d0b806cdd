"""A trained agent as one torch module, the form MLflow serves: observations in, greedy actions
out (``mlflow.pyfunc.load_model(uri).predict(observations)``)."""

from __future__ import annotations

import torch
from torch import nn

from socnav_wm.agents.agent_file import Agent
from socnav_wm.agents.features import STOP, make_variant
from socnav_wm.agents.params import AgentParams


class ServedPolicy(nn.Module):
    """An agent's greedy policy: observations (episodes, steps, obs_dim), each row one
    episode's observations from its start, → the greedy action at every step (episodes, steps),
    int64. A (episodes, obs_dim) batch is read as the first step of each.

    The world-model variants' features depend on the episode so far (the LSTM state, the
    action just taken), so an episode is given whole: each step's action is the one the agent
    took greedily at the step before (``stop`` before the first), exactly
    :meth:`socnav_wm.agents.agent_file.Agent.policy`'s. ``.q_network``, ``.vae`` and ``.lstm``
    are the agent's networks (no VAE and LSTM for ``dueling-dqn``).
    """

    def __init__(self, agent: Agent) -> None:
        super().__init__()
        self.q_network = agent.q_network
        self.vae = agent.variant.vae
        self.lstm = agent.variant.lstm
        self.variant = agent.variant.name
        self.obs_dim = agent.variant.obs_dim
        self.options = agent.params.to_dict()

    @torch.no_grad()
    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        obs = observations[:, None] if observations.dim() == 2 else observations
        features_of = make_variant(
            self.variant,
            self.vae,
            self.lstm,
            AgentParams.from_dict(self.options),
            obs_dim=self.obs_dim,
            device=obs.device,
        )
        episodes, steps = obs.shape[:2]
        state = features_of.zero_state(episodes)
        action = torch.full((episodes,), STOP, dtype=torch.int64, device=obs.device)
        actions = []
        for t in range(steps):
            features, state = features_of.features(obs[:, t], action, state)
            action = self.q_network(features).argmax(dim=1)
            actions.append(action)
        chosen = torch.stack(actions, dim=1)
        return chosen[:, 0] if observations.dim() == 2 else chosen
