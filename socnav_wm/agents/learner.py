"""The DQN learner: online and target Q-networks, the optimiser and one gradient update.

The update is the textbook one, written the way the field writes it (cleanrl's ``dqn.py``):
the Double-DQN target under ``no_grad``, the loss, ``loss.backward()``, the global-norm clip,
``optimizer.step()``, then the Polyak step of the target network. Autograd computes every
gradient, so any change to the network (:mod:`socnav_wm.agents.dueling`) or to the loss needs no
other change.

What makes it fast on a CPU core (``socnav-wm bench train``; docs/performance.md) is the layout of
the tensors and one stream left out where it cannot change the result, never the update's
mathematics (only the order of some floating-point sums differs):

* **One flat tensor per network.** Every parameter of the online network is a view into one
  contiguous tensor, and its gradient a view into one gradient tensor, so that the optimiser
  step (Adam's fused kernel), the global-norm clip, zeroing the gradients and the Polyak step
  of the target network (a second flat tensor) are each one operation over all parameters,
  instead of a loop of small ones per tensor with Python between them.
* **Widening layers' weights stored transposed** (the first layer's ``(512, features)``
  weight lies in memory as ``(features, 512)``): autograd then computes its gradient as
  ``Xᵀ·dY``, the faster of the two orientations of that product on a CPU core.
* **The greedy action from the advantage stream** (:meth:`DuelingQNetwork.greedy_actions`):
  ``V(s′)`` does not change which action is best, so the online network's pass over ``s′``
  skips the value stream.
* No ``.item()`` in the update: the loss comes back as a tensor, and the training loop checks
  the losses of a vector step at once.
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
    return bootstrapped_targets(
        rewards, terminals, next_q_online.argmax(dim=1), next_q_target, discounts
    )


def bootstrapped_targets(
    rewards: torch.Tensor,
    terminals: torch.Tensor,
    next_actions: torch.Tensor,
    next_q_target: torch.Tensor,
    discounts: torch.Tensor | float,
) -> torch.Tensor:
    """``y = r + γᵏ·Q_target(s′, a′)·(1 − terminal)`` for the actions ``a′`` (batch,) int64 that
    the online network picked at s′ (:func:`double_dqn_targets` with the argmax done)."""
    next_value = next_q_target.gather(1, next_actions.unsqueeze(1)).squeeze(1)
    return rewards + discounts * next_value * (1.0 - terminals)


def greedy_actions(network: torch.nn.Module, features: torch.Tensor) -> torch.Tensor:
    """``argmax_a Q(features, a)`` (batch,): the network's own ``greedy_actions`` where it has
    one (:class:`DuelingQNetwork` skips its value stream), else the argmax of its output."""
    own = getattr(network, "greedy_actions", None)
    if own is not None:
        return own(features)
    return network(features).argmax(dim=1)


def _stored_transposed(module: torch.nn.Module) -> set[int]:
    """The weights kept as ``(in, out)`` in memory: those of the ``nn.Linear`` layers that widen
    (``in_features < out_features``, e.g. the first layer). Autograd computes a weight's
    gradient in the weight's own memory order, and for a widening layer ``Xᵀ·dY`` (in × out)
    runs at about twice the speed of ``dYᵀ·X`` (out × in) on a CPU core; the values, the
    shapes and every result are the same either way."""
    return {
        id(layer.weight)
        for layer in module.modules()
        if isinstance(layer, torch.nn.Linear) and layer.in_features < layer.out_features
    }


def flatten_parameters(
    module: torch.nn.Module, with_grad: bool
) -> tuple[torch.Tensor, torch.Tensor | None, list[torch.Tensor]]:
    """Put every parameter of ``module`` into one contiguous tensor, in place.

    Each parameter keeps its value, name and shape but becomes a view into the returned tensor
    (``state_dict``, ``load_state_dict`` and the forward pass see no difference; a widening
    layer's weight is laid out transposed, :func:`_stored_transposed`); with ``with_grad``, each
    parameter's ``.grad`` becomes a view of the same layout into one zeroed gradient tensor,
    into which ``backward()`` accumulates. Two modules of the same structure get the same
    layout. Returns ``(flat, flat_grad or None, the gradient views)``.

    Raises:
        ValueError: the parameters do not share one dtype and device (nothing is changed).
    """
    params = list(module.parameters())
    if not params:
        raise ValueError("the Q-network has no parameters")
    kinds = {(p.dtype, p.device) for p in params}
    if len(kinds) != 1:
        raise ValueError(f"the Q-network's parameters must share one dtype and device: {kinds}")
    transposed = _stored_transposed(module)

    def in_memory(tensor: torch.Tensor, p: torch.Tensor) -> torch.Tensor:
        """``tensor`` (flat, p's size) seen as p: ``(in, out)`` memory read as ``(out, in)``."""
        if id(p) in transposed:
            return tensor.view(p.shape[1], p.shape[0]).t()
        return tensor.view_as(p)

    flat = torch.cat(
        [(p.detach().t() if id(p) in transposed else p.detach()).reshape(-1) for p in params]
    )
    flat_grad = torch.zeros_like(flat) if with_grad else None
    views: list[torch.Tensor] = []
    offset = 0
    for p in params:
        size = p.numel()
        p.data = in_memory(flat[offset : offset + size], p)
        if flat_grad is not None:
            p.grad = in_memory(flat_grad[offset : offset + size], p)
            views.append(p.grad)
        offset += size
    return flat, flat_grad, views


class DQNLearner:
    """Online and target Q-networks, the optimiser and one gradient update.

    Args:
        feature_dim: size of the variant's feature vector.
        params: the agent's hyper-parameters (network sizes, optimiser, loss, clip, Polyak).
        device: where the networks live.
        network: the online network to train (default: a :class:`DuelingQNetwork` of
            ``params``' sizes); the target network starts as its copy. Its parameters become
            views into one flat tensor (:func:`flatten_parameters`): move it to another device
            only before handing it over.
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
        flat, flat_grad, self._grad_views = flatten_parameters(self.q_network, with_grad=True)
        self._target, _, _ = flatten_parameters(self.target_network, with_grad=False)
        # The optimiser's one parameter: the flat tensor the network's parameters are views of.
        self._flat = torch.nn.Parameter(flat)
        self._flat.grad = flat_grad
        optimizer_type = torch.optim.AdamW if params.optimizer == "adamw" else torch.optim.Adam
        self.optimizer = optimizer_type(
            [self._flat],
            lr=params.learning_rate,
            amsgrad=params.amsgrad,
            weight_decay=params.weight_decay,
            # One fused kernel over the flat tensor: the whole step is one operation.
            fused=device.type in ("cpu", "cuda"),
        )

    def act(self, features: torch.Tensor, epsilon: float, rng: np.random.Generator) -> np.ndarray:
        """ε-greedy actions (N,) for features (N, feature_dim).

        Both random draws are made every step whatever ε is, so the generator's stream (and a
        resumed run) does not depend on the outcomes.
        """
        n = features.shape[0]
        explore = rng.random(n) < epsilon
        random_actions = rng.integers(0, NUM_ACTIONS, size=n)
        with torch.inference_mode():
            greedy = greedy_actions(self.q_network, features).cpu().numpy()
        return np.where(explore, random_actions, greedy)

    def loss(self, batch: Batch) -> torch.Tensor:
        """The TD loss of a batch (differentiable in the online network's parameters)."""
        with torch.no_grad():
            targets = bootstrapped_targets(
                batch.rewards,
                batch.terminals,
                greedy_actions(self.q_network, batch.next_features),
                self.target_network(batch.next_features),
                batch.discounts,
            )
        q_taken = self.q_network(batch.features).gather(1, batch.actions.unsqueeze(1)).squeeze(1)
        if self.params.huber:
            return F.smooth_l1_loss(q_taken, targets)
        return F.mse_loss(q_taken, targets)

    def update(self, batch: Batch) -> torch.Tensor:
        """One gradient step on a batch, then the Polyak target update; returns the loss (a
        0-d tensor: reading it is the caller's choice)."""
        loss = self.loss(batch)
        self._zero_grad()
        loss.backward()
        if self.params.grad_clip > 0:  # the global norm: one gradient tensor holds them all
            torch.nn.utils.clip_grad_norm_([self._flat], self.params.grad_clip)
        self.optimizer.step()
        with torch.no_grad():
            # θ′ ← polyak·θ′ + (1 − polyak)·θ, every parameter in one call.
            self._target.lerp_(self._flat, 1.0 - self.params.polyak)
        return loss.detach()

    def _zero_grad(self) -> None:
        """Zero the one gradient tensor, first re-attaching its views to any parameter whose
        ``.grad`` was replaced (``q_network.zero_grad()`` sets them to None)."""
        for param, view in zip(self._online, self._grad_views, strict=True):
            if param.grad is not view:
                param.grad = view
        self._flat.grad.zero_()

    def weights_finite(self) -> bool:
        """Whether every weight of the online network is finite (one check over all of them)."""
        return bool(torch.isfinite(self._flat).all())

    def first_nonfinite_weight(self) -> str | None:
        """The name of the first online parameter holding a NaN or an infinity (None if all are
        finite)."""
        for name, param in self.q_network.named_parameters():
            if not bool(torch.isfinite(param).all()):
                return name
        return None

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
