"""The Dueling Q-network of every agent variant (paper_spec §5).

``Q(s, ·) = V(s) + A(s, ·) − mean_a A(s, a)``: a shared trunk (the paper's 512 → 128), then a
value stream ``128 → 128 → 1`` and an advantage stream ``128 → 128 → num_actions``.

One deliberate difference from the paper's code (paper_spec §8.16): the original trunk ended in a
bare ``Linear(512, 128)`` that fed the streams' first ``Linear(128, 128)`` directly, so the two
layers collapse into one linear map and the 128-unit layer adds parameters but no capacity. Here
every hidden layer, the last trunk layer included, is followed by the activation (LeakyReLU, the
paper's choice), which is the usual dueling architecture.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import torch
import torch.nn.functional as F
from torch import nn

LEAKY_SLOPE = 0.01
"""Negative slope of the LeakyReLU activations (PyTorch's default, as in the paper)."""


def _mlp(sizes: Sequence[int], final_activation: bool) -> list[nn.Module]:
    """Linear layers ``sizes[0] → sizes[1] → …`` with LeakyReLU between them."""
    layers: list[nn.Module] = []
    for i, (n_in, n_out) in enumerate(zip(sizes[:-1], sizes[1:], strict=True)):
        layers.append(nn.Linear(n_in, n_out))
        if final_activation or i < len(sizes) - 2:
            layers.append(nn.LeakyReLU(LEAKY_SLOPE))
    return layers


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
        self.trunk = nn.Sequential(*_mlp((self.input_dim, *self.trunk_sizes), True))
        width = self.trunk_sizes[-1]
        self.value = nn.Sequential(*_mlp((width, self.stream_size, 1), False))
        self.advantage = nn.Sequential(*_mlp((width, self.stream_size, self.num_actions), False))
        self._init_weights()
        self._trunk = [m for m in self.trunk if isinstance(m, nn.Linear)]
        self._value = [m for m in self.value if isinstance(m, nn.Linear)]
        self._advantage = [m for m in self.advantage if isinstance(m, nn.Linear)]

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
        hidden = features
        for layer in self._trunk:
            hidden = F.leaky_relu(F.linear(hidden, layer.weight, layer.bias), LEAKY_SLOPE)
        value = _stream_forward(self._value, hidden)[2]
        advantage = _stream_forward(self._advantage, hidden)[2]
        return dueling_q_values(value, advantage)

    # -- the DQN update's hand-written pass ----------------------------------------------------
    #
    # A DQN update on the CPU is dominated by per-operation overhead, not arithmetic: the network
    # is small and the batch is 64. Autograd's engine, the gradient accumulation and the zeroing
    # of gradients added about a third to each update. The network is a fixed stack of linear
    # layers, so its backward pass is a dozen matrix products, written out below and checked
    # against autograd in the tests (tests/agents/test_dueling.py).

    def forward_cached(self, features: torch.Tensor) -> tuple[torch.Tensor, ForwardCache]:
        """Q-values and what :meth:`backward_cached` needs (differentiable too, by autograd).

        :meth:`forward` computes the same Q-values, bit for bit, without keeping activations.
        """
        inputs, pre_activations = [], []
        hidden = features
        for layer in self._trunk:
            inputs.append(hidden)
            pre = F.linear(hidden, layer.weight, layer.bias)
            pre_activations.append(pre)
            hidden = F.leaky_relu(pre, LEAKY_SLOPE)
        value_pre, value_hidden, value = _stream_forward(self._value, hidden)
        advantage_pre, advantage_hidden, advantage = _stream_forward(self._advantage, hidden)
        cache = ForwardCache(
            inputs, pre_activations, hidden, value_pre, value_hidden, advantage_pre,
            advantage_hidden,
        )  # fmt: skip
        return dueling_q_values(value, advantage), cache

    @torch.no_grad()
    def backward_cached(self, cache: ForwardCache, grad_q: torch.Tensor) -> None:
        """Write d(loss)/d(parameter) into every parameter's ``.grad``, given ``grad_q`` =
        d(loss)/dQ (batch, num_actions) at the forward pass that produced ``cache``.

        The gradients overwrite ``.grad`` in place (no zeroing needed); every parameter must
        already have a ``.grad`` tensor of its shape (the learner gives them views of one flat
        buffer).
        """
        # Q = V + A − mean(A): dV = Σ_a dQ, dA = dQ − mean_a dQ.
        grad_value = grad_q.sum(dim=1, keepdim=True)
        grad_advantage = grad_q - grad_q.mean(dim=1, keepdim=True)
        grad_value_pre = _stream_backward(
            self._value, grad_value, cache.value_hidden, cache.value_pre, cache.trunk_output
        )
        grad_advantage_pre = _stream_backward(
            self._advantage, grad_advantage, cache.advantage_hidden, cache.advantage_pre,
            cache.trunk_output,
        )  # fmt: skip
        grad_hidden = torch.addmm(
            grad_value_pre.mm(self._value[0].weight), grad_advantage_pre, self._advantage[0].weight
        )
        for index in range(len(self._trunk) - 1, -1, -1):
            layer = self._trunk[index]
            grad_pre = _leaky_relu_backward(grad_hidden, cache.pre_activations[index])
            _linear_weight_grads(layer, grad_pre, cache.inputs[index])
            if index > 0:  # the input features need no gradient
                grad_hidden = grad_pre.mm(layer.weight)


class ForwardCache(NamedTuple):
    """Activations of :meth:`DuelingQNetwork.forward_cached`, for the hand-written backward."""

    inputs: list[torch.Tensor]  # input of each trunk layer
    pre_activations: list[torch.Tensor]  # each trunk layer's output before the activation
    trunk_output: torch.Tensor
    value_pre: torch.Tensor
    value_hidden: torch.Tensor
    advantage_pre: torch.Tensor
    advantage_hidden: torch.Tensor

    def head(self, rows: int) -> ForwardCache:
        """The cache of the first ``rows`` examples of the batch (views, no copies)."""
        return ForwardCache(
            [x[:rows] for x in self.inputs],
            [x[:rows] for x in self.pre_activations],
            *(x[:rows] for x in self[2:]),
        )


def _leaky_relu_backward(grad: torch.Tensor, pre_activation: torch.Tensor) -> torch.Tensor:
    return torch.ops.aten.leaky_relu_backward(grad, pre_activation, LEAKY_SLOPE, False)


def _linear_weight_grads(layer: nn.Linear, grad_out: torch.Tensor, inputs: torch.Tensor) -> None:
    """``y = x Wᵀ + b``: dW = dyᵀ x, db = Σ_batch dy, written into the existing ``.grad``."""
    torch.mm(grad_out.t(), inputs, out=layer.weight.grad)
    torch.sum(grad_out, dim=0, out=layer.bias.grad)


def _stream_forward(
    layers: list[nn.Linear], stream_input: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Forward through ``Linear → LeakyReLU → Linear``: (pre-activation, hidden, output)."""
    hidden_pre = F.linear(stream_input, layers[0].weight, layers[0].bias)
    hidden = F.leaky_relu(hidden_pre, LEAKY_SLOPE)
    return hidden_pre, hidden, F.linear(hidden, layers[1].weight, layers[1].bias)


def _stream_backward(
    layers: list[nn.Linear],
    grad_out: torch.Tensor,
    hidden: torch.Tensor,
    hidden_pre: torch.Tensor,
    stream_input: torch.Tensor,
) -> torch.Tensor:
    """Backward through ``Linear → LeakyReLU → Linear``; returns d(loss)/d(first pre-activation)."""
    _linear_weight_grads(layers[1], grad_out, hidden)
    grad_pre = _leaky_relu_backward(grad_out.mm(layers[1].weight), hidden_pre)
    _linear_weight_grads(layers[0], grad_pre, stream_input)
    return grad_pre


def dueling_q_values(value: torch.Tensor, advantage: torch.Tensor) -> torch.Tensor:
    """``Q = V + A − mean(A)``: value (batch, 1), advantage (batch, actions) → (batch, actions).

    Subtracting the mean advantage makes the split identifiable (V is the mean Q over actions).
    """
    return value + advantage - advantage.mean(dim=-1, keepdim=True)
