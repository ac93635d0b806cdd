"""The DQN learner: online and target Q-networks, the optimiser and one gradient update.

The update is the textbook one, written the way the field writes it (cleanrl's ``dqn.py``):
the Double-DQN target under ``no_grad``, the loss, ``loss.backward()``, the global-norm clip,
``optimizer.step()``, then the Polyak step of the target network. Autograd computes every
gradient, so any change to the network (:mod:`socnav_wm.agents.dueling`) or to the loss needs no
other change.
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from socnav_wm.agents.dueling import DuelingQNetwork
from socnav_wm.agents.params import AgentParams
from socnav_wm.agents.replay import Batch
from socnav_wm.env.core import NUM_ACTIONS


def double_dqn_targets(
    rewards: torch.Tensor,
    terminals: torch.Tensor,
    next_q_online: torch.Tensor,
    next_q_target: torch.Tensor,
    discounts: torch.Tensor | float,
) -> torch.Tensor:
    """``y = r + γᵏ·Q_target(s′, argmax_a Q_online(s′, a))·(1 − terminal)``.

    Args:
        rewards, terminals: (batch,); terminals is 1 where nothing is bootstrapped.
        next_q_online, next_q_target: (batch, actions), the two networks' Q-values at s′.
        discounts: γᵏ, (batch,) or one number (γ for one-step transitions).

    Returns:
        (batch,) TD targets. The online network picks the action, the target network values it,
        which removes most of DQN's over-estimation (van Hasselt et al., 2016).
    """
    best = next_q_online.argmax(dim=1, keepdim=True)
    next_value = next_q_target.gather(1, best).squeeze(1)
    return rewards + discounts * next_value * (1.0 - terminals)


class DQNLearner:
    """Online and target Q-networks, the optimiser and one gradient update.

    Args:
        feature_dim: size of the variant's feature vector.
        params: the agent's hyper-parameters (network sizes, optimiser, loss, clip, Polyak).
        device: where the networks live.
        network: the online network to train (default: a :class:`DuelingQNetwork` of
            ``params``' sizes); the target network starts as its copy.
    """

    def __init__(
        self,
        feature_dim: int,
        params: AgentParams,
        device: torch.device,
        network: torch.nn.Module | None = None,
    ) -> None:
        self.params = params
        self.device = device
        if network is None:
            network = DuelingQNetwork(
                feature_dim, NUM_ACTIONS, params.trunk_sizes, params.stream_size
            )
        self.q_network = network.to(device)
        self.target_network = copy.deepcopy(self.q_network).requires_grad_(False)
        self._online = list(self.q_network.parameters())
        self._target = list(self.target_network.parameters())
        optimizer_type = torch.optim.AdamW if params.optimizer == "adamw" else torch.optim.Adam
        self.optimizer = optimizer_type(
            self._online,
            lr=params.learning_rate,
            amsgrad=params.amsgrad,
            weight_decay=params.weight_decay,
            # One fused kernel over all parameters instead of one loop per tensor.
            fused=device.type in ("cpu", "cuda"),
        )

    @torch.no_grad()
    def act(self, features: torch.Tensor, epsilon: float, rng: np.random.Generator) -> np.ndarray:
        """ε-greedy actions (N,) for features (N, feature_dim).

        Both random draws are made every step whatever ε is, so the generator's stream (and a
        resumed run) does not depend on the outcomes.
        """
        n = features.shape[0]
        explore = rng.random(n) < epsilon
        random_actions = rng.integers(0, NUM_ACTIONS, size=n)
        greedy = self.q_network(features).argmax(dim=1).cpu().numpy()
        return np.where(explore, random_actions, greedy)

    def loss(self, batch: Batch) -> torch.Tensor:
        """The TD loss of a batch (differentiable in the online network's parameters)."""
        with torch.no_grad():
            targets = double_dqn_targets(
                batch.rewards,
                batch.terminals,
                self.q_network(batch.next_features),
                self.target_network(batch.next_features),
                batch.discounts,
            )
        q_taken = self.q_network(batch.features).gather(1, batch.actions.unsqueeze(1)).squeeze(1)
        if self.params.huber:
            return F.smooth_l1_loss(q_taken, targets)
        return F.mse_loss(q_taken, targets)

    def update(self, batch: Batch) -> torch.Tensor:
        """One gradient step on a batch, then the Polyak target update; returns the loss."""
        loss = self.loss(batch)
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        if self.params.grad_clip > 0:
            torch.nn.utils.clip_grad_norm_(self._online, self.params.grad_clip, foreach=True)
        self.optimizer.step()
        with torch.no_grad():
            # θ′ ← polyak·θ′ + (1 − polyak)·θ, every tensor in one call.
            torch._foreach_lerp_(self._target, self._online, 1.0 - self.params.polyak)
        return loss.detach()

    def weights(self) -> dict[str, torch.Tensor]:
        """A copy of the online network's weights."""
        return {k: v.detach().clone() for k, v in self.q_network.state_dict().items()}

    def load_weights(self, weights: dict[str, torch.Tensor]) -> None:
        """Give the online network the weights of :meth:`weights` (target and optimiser stay)."""
        self.q_network.load_state_dict(weights)

    def state_dict(self) -> dict[str, Any]:
        return {
            "q_network": self.q_network.state_dict(),
            "target_network": self.target_network.state_dict(),
            "optimizer": self.optimizer.state_dict(),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.q_network.load_state_dict(state["q_network"])
        self.target_network.load_state_dict(state["target_network"])
        self.optimizer.load_state_dict(state["optimizer"])
