"""The latent dynamics model: (z_t, a_t, h_{t−1}) → ẑ_{t+1} (paper_spec §4).

One set of weights, two forms: the sequence form (``nn.LSTM``) trains on windows; the step form
runs one step at a time for acting, with the gate algebra written out so the one-hot action
becomes a column lookup in ``weight_ih`` and all four candidate actions can share one matmul
(:meth:`LatentLSTM.step_all_actions`, called by the agents every env step for thousands of
envs). The paper's code fed the 2-D continuous action; we feed the one-hot action, as the paper's
text says (paper_spec §8.7).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

State = tuple[torch.Tensor, torch.Tensor]
"""(h, c), each (batch, hidden_dim) — or (batch, actions, hidden_dim) after step_all_actions."""


class LatentLSTM(nn.Module):
    """LSTM over [latent ⊕ one-hot action] with a linear head predicting the next latent."""

    def __init__(self, latent_dim: int = 16, num_actions: int = 4, hidden_dim: int = 256) -> None:
        super().__init__()
        self.latent_dim = latent_dim
        self.num_actions = num_actions
        self.hidden_dim = hidden_dim
        self.lstm = nn.LSTM(latent_dim + num_actions, hidden_dim, num_layers=1, batch_first=True)
        self.head = nn.Linear(hidden_dim, latent_dim)

    def hyperparameters(self) -> dict[str, int]:
        """Constructor arguments, as saved in checkpoints."""
        return {
            "latent_dim": self.latent_dim,
            "num_actions": self.num_actions,
            "hidden_dim": self.hidden_dim,
        }

    def initial_state(self, batch: int, device: torch.device | str | None = None) -> State:
        """Zero (h, c), each (batch, hidden_dim), on ``device`` (the model's by default)."""
        if device is None:
            device = self.head.weight.device
        zeros = torch.zeros(batch, self.hidden_dim, device=device, dtype=self.head.weight.dtype)
        return zeros, zeros.clone()

    # -- sequence form (training) ------------------------------------------------------------

    def forward(
        self, z: torch.Tensor, actions: torch.Tensor, state: State | None = None
    ) -> tuple[torch.Tensor, State]:
        """Run a batch of sequences.

        Args:
            z: (batch, seq, latent_dim) latents z_t.
            actions: (batch, seq) int64 actions a_t.
            state: (h, c), each (batch, hidden_dim), or None for zeros.

        Returns:
            (z_next_pred (batch, seq, latent_dim), (h, c) after the last step, each
            (batch, hidden_dim)).
        """
        one_hot = F.one_hot(actions, self.num_actions).to(z.dtype)
        lstm_state = None if state is None else (state[0].unsqueeze(0), state[1].unsqueeze(0))
        output, (h, c) = self.lstm(torch.cat([z, one_hot], dim=-1), lstm_state)
        return self.head(output), (h.squeeze(0), c.squeeze(0))

    # -- step form (acting) ------------------------------------------------------------------

    def _gate_weights(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """(W_z^T (latent, 4H), W_a^T (actions, 4H), W_hh^T (H, 4H), bias (4H,)).

        Gate order along 4H is PyTorch's: input, forget, cell (g), output.
        """
        weight_ih = self.lstm.weight_ih_l0  # (4H, latent + actions)
        latent_part = weight_ih[:, : self.latent_dim].t()
        # A one-hot input times weight_ih is just one column of weight_ih: index it instead.
        action_part = weight_ih[:, self.latent_dim :].t()
        bias = self.lstm.bias_ih_l0 + self.lstm.bias_hh_l0
        return latent_part, action_part, self.lstm.weight_hh_l0.t(), bias

    def _cell(self, gates: torch.Tensor, c: torch.Tensor) -> State:
        """LSTM cell update from pre-activations (..., 4H) and the previous cell (..., H)."""
        input_gate, forget_gate, cell_gate, output_gate = gates.chunk(4, dim=-1)
        c_next = torch.sigmoid(forget_gate) * c + torch.sigmoid(input_gate) * torch.tanh(cell_gate)
        h_next = torch.sigmoid(output_gate) * torch.tanh(c_next)
        return h_next, c_next

    def _shared_gates(self, z: torch.Tensor, state: State | None) -> tuple[torch.Tensor, ...]:
        """Action-independent pre-activations (batch, 4H), the action rows, and the cell."""
        latent_part, action_part, hidden_part, bias = self._gate_weights()
        gates = torch.addmm(bias, z, latent_part)
        if state is None:
            c = torch.zeros(z.shape[0], self.hidden_dim, device=z.device, dtype=z.dtype)
        else:
            h, c = state
            gates = torch.addmm(gates, h, hidden_part)
        return gates, action_part, c

    def step(
        self, z: torch.Tensor, actions: torch.Tensor, state: State | None = None
    ) -> tuple[torch.Tensor, State]:
        """One step for a batch of environments.

        Args:
            z: (batch, latent_dim) latent z_t.
            actions: (batch,) int64 action a_t.
            state: (h, c), each (batch, hidden_dim), or None for zeros.

        Returns:
            (z_next_pred (batch, latent_dim), (h, c) each (batch, hidden_dim)).
        """
        gates, action_part, c = self._shared_gates(z, state)
        h_next, c_next = self._cell(gates + action_part[actions], c)
        return self.head(h_next), (h_next, c_next)

    def step_all_actions(
        self, z: torch.Tensor, state: State | None = None
    ) -> tuple[torch.Tensor, State]:
        """One step for every candidate action from the same state (shared matmuls).

        Args:
            z: (batch, latent_dim) latent z_t.
            state: (h, c), each (batch, hidden_dim), or None for zeros.

        Returns:
            (z_next_pred (batch, num_actions, latent_dim), (h, c) each
            (batch, num_actions, hidden_dim)); slot k equals ``step(z, k, state)``.
        """
        gates, action_part, c = self._shared_gates(z, state)
        all_gates = gates.unsqueeze(1) + action_part.unsqueeze(0)  # (batch, actions, 4H)
        h_next, c_next = self._cell(all_gates, c.unsqueeze(1))
        return self.head(h_next), (h_next, c_next)


def masked_mse(prediction: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mean squared error per latent dim over the unmasked steps (the LSTM's training loss).

    Args:
        prediction, target: (batch, seq, latent).
        mask: (batch, seq) bool; padding (False) contributes nothing.
    """
    per_step = (prediction - target).pow(2).mean(dim=-1)
    weights = mask.to(per_step.dtype)
    return (per_step * weights).sum() / weights.sum().clamp_min(1.0)
