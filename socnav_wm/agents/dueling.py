"""The Dueling Q-network of every agent variant (paper_spec §5).

``Q(s, ·) = V(s) + A(s, ·) − mean_a A(s, a)``: a shared trunk (the paper's 512 → 128), then a
value stream ``128 → 128 → 1`` and an advantage stream ``128 → 128 → num_actions``.

An ordinary ``nn.Module``: :meth:`DuelingQNetwork.forward` runs the three ``nn.Sequential``
blocks it holds, so a module added to them (a ``LayerNorm``, a dropout) is applied and trained
like any other, and the gradient is autograd's.

One deliberate difference from the paper's code (paper_spec §8.16): the original trunk ended in a
bare ``Linear(512, 128)`` that fed the streams' first ``Linear(128, 128)`` directly, so the two
layers collapse into one linear map and the 128-unit layer adds parameters but no capacity. Here
every hidden layer, the last trunk layer included, is followed by the activation (LeakyReLU, the
paper's choice), which is the usual dueling architecture.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

LEAKY_SLOPE = 0.01
"""Negative slope of the LeakyReLU activations (PyTorch's default, as in the paper)."""


def _mlp(sizes: Sequence[int], final_activation: bool) -> nn.Sequential:
    """Linear layers ``sizes[0] → sizes[1] → …`` with LeakyReLU between them."""
    layers: list[nn.Module] = []
    for i, (n_in, n_out) in enumerate(zip(sizes[:-1], sizes[1:], strict=True)):
        layers.append(nn.Linear(n_in, n_out))
        if final_activation or i < len(sizes) - 2:
            layers.append(nn.LeakyReLU(LEAKY_SLOPE))
    return nn.Sequential(*layers)


class DuelingQNetwork(nn.Module):
    """Dueling DQN head over a feature vector.

    Args:
        input_dim: size of the variant's feature vector (23 for ``dueling-dqn``, 272, 80, …).
        num_actions: number of discrete actions (4).
        trunk_sizes: widths of the shared hidden layers (the paper: 512, 128).
        stream_size: width of the hidden layer of the value and advantage streams (128).
    """

    def __init__(
        self,
        input_dim: int,
        num_actions: int = 4,
        trunk_sizes: Sequence[int] = (512, 128),
        stream_size: int = 128,
    ) -> None:
        super().__init__()
        if not trunk_sizes:
            raise ValueError("trunk_sizes: need at least one hidden layer")
        self.input_dim = int(input_dim)
        self.num_actions = int(num_actions)
        self.trunk_sizes = tuple(int(size) for size in trunk_sizes)
        self.stream_size = int(stream_size)
        self.trunk = _mlp((self.input_dim, *self.trunk_sizes), final_activation=True)
        width = self.trunk_sizes[-1]
        self.value = _mlp((width, self.stream_size, 1), final_activation=False)
        self.advantage = _mlp((width, self.stream_size, self.num_actions), final_activation=False)
        self._init_weights()

    def _init_weights(self) -> None:
        # Xavier-uniform as in the paper; layers followed by a LeakyReLU get its gain, the two
        # output layers gain 1. Biases start at 0 so the initial Q-values are centred.
        hidden_gain = nn.init.calculate_gain("leaky_relu", LEAKY_SLOPE)
        outputs = {id(self.value[-1]), id(self.advantage[-1])}
        for module in self.modules():
            if isinstance(module, nn.Linear):
                gain = 1.0 if id(module) in outputs else hidden_gain
                nn.init.xavier_uniform_(module.weight, gain=gain)
                nn.init.zeros_(module.bias)

    def hyperparameters(self) -> dict[str, object]:
        """Constructor arguments, as saved in agent files."""
        return {
            "input_dim": self.input_dim,
            "num_actions": self.num_actions,
            "trunk_sizes": list(self.trunk_sizes),
            "stream_size": self.stream_size,
        }

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        """Features (batch, input_dim) → Q-values (batch, num_actions)."""
        hidden = self.trunk(features)
        return dueling_q_values(self.value(hidden), self.advantage(hidden))

    def greedy_actions(self, features: torch.Tensor) -> torch.Tensor:
        """``argmax_a Q(s, a)`` (batch,) without the value stream.

        ``V(s)`` and ``mean_a A(s, a)`` are the same for every action, so the action with the
        largest Q-value is the one with the largest advantage: the trunk and the advantage
        stream decide it (the learner's Double-DQN target and acting use this; ties aside,
        floating-point rounding is all that can make it differ from ``forward(…).argmax``).
        """
        return self.advantage(self.trunk(features)).argmax(dim=1)


def dueling_q_values(value: torch.Tensor, advantage: torch.Tensor) -> torch.Tensor:
    """``Q = V + A − mean(A)``: value (batch, 1), advantage (batch, actions) → (batch, actions).

    Subtracting the mean advantage makes the split identifiable (V is the mean Q over actions).
    """
    return value + advantage - advantage.mean(dim=-1, keepdim=True)
