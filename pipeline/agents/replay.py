"""Uniform experience replay in preallocated arrays, returning typed batches of tensors.

Storage is numpy, allocated once with ``np.zeros``: the operating system hands out zeroed pages
lazily, so a 1M-transition buffer (the paper's MASPM setting) costs memory only as it fills.
A sampled batch is gathered in numpy and moved to the learner's device in one copy per field.
Sampling draws indices from the buffer's own numpy ``Generator``, whose state is part of
:meth:`ReplayBuffer.state_dict`, so a resumed run samples exactly what an uninterrupted one would.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import torch


class Batch(NamedTuple):
    """A batch of transitions, every field on the learner's device.

    Attributes:
        features: (batch, feature_dim) float32, the Q-network input at time t.
        actions: (batch,) int64, the action taken at t.
        rewards: (batch,) float32, the reward of that step.
        next_features: (batch, feature_dim) float32, the Q-network input at t + 1 (for the last
            step of an episode: the features of its final observation).
        terminals: (batch,) float32, 1 where the return must not be bootstrapped from
            ``next_features`` (a true terminal state; also a time-limit truncation when the
            learner treats timeouts as terminal), else 0.
    """

    features: torch.Tensor
    actions: torch.Tensor
    rewards: torch.Tensor
    next_features: torch.Tensor
    terminals: torch.Tensor


def _as_numpy(array: np.ndarray | torch.Tensor) -> np.ndarray:
    if isinstance(array, torch.Tensor):
        return array.detach().cpu().numpy()
    return np.asarray(array)


class ReplayBuffer:
    """A circular buffer of ``capacity`` transitions; the oldest are overwritten first.

    Args:
        capacity: transitions kept.
        feature_dim: size of the feature vectors.
        device: where sampled batches go.
        seed: seed of the sampling generator (a numpy ``Generator``).
    """

    def __init__(
        self,
        capacity: int,
        feature_dim: int,
        device: torch.device | str = "cpu",
        seed: int | np.random.SeedSequence = 0,
    ) -> None:
        if capacity < 1:
            raise ValueError(f"capacity: must be >= 1, got {capacity}")
        self.capacity = int(capacity)
        self.feature_dim = int(feature_dim)
        self.device = torch.device(device)
        self.rng = np.random.default_rng(seed)
        self.features = np.zeros((self.capacity, self.feature_dim), dtype=np.float32)
        self.next_features = np.zeros((self.capacity, self.feature_dim), dtype=np.float32)
        self.actions = np.zeros(self.capacity, dtype=np.int64)
        self.rewards = np.zeros(self.capacity, dtype=np.float32)
        self.terminals = np.zeros(self.capacity, dtype=np.float32)
        self.position = 0
        """Index the next transition is written to."""
        self.size = 0
        """Number of valid transitions (≤ capacity)."""

    def __len__(self) -> int:
        return self.size

    def add(
        self,
        features: np.ndarray | torch.Tensor,
        actions: np.ndarray | torch.Tensor,
        rewards: np.ndarray | torch.Tensor,
        next_features: np.ndarray | torch.Tensor,
        terminals: np.ndarray | torch.Tensor,
    ) -> None:
        """Append a batch of ``n`` transitions (one per env), wrapping around at the end.

        Args:
            features, next_features: (n, feature_dim).
            actions: (n,) integers; rewards: (n,); terminals: (n,) bool or 0/1.
        """
        features = _as_numpy(features)
        n = features.shape[0]
        if features.shape != (n, self.feature_dim):
            raise ValueError(
                f"features: expected shape (n, {self.feature_dim}), got {features.shape}"
            )
        if n > self.capacity:
            raise ValueError(f"cannot add {n} transitions to a buffer of capacity {self.capacity}")
        index = (self.position + np.arange(n)) % self.capacity
        self.features[index] = features
        self.next_features[index] = _as_numpy(next_features)
        self.actions[index] = _as_numpy(actions)
        self.rewards[index] = _as_numpy(rewards)
        self.terminals[index] = _as_numpy(terminals)
        self.position = int((self.position + n) % self.capacity)
        self.size = min(self.size + n, self.capacity)

    def sample(self, batch_size: int) -> Batch:
        """``batch_size`` transitions drawn uniformly with replacement, as tensors on device."""
        if self.size == 0:
            raise ValueError("cannot sample from an empty replay buffer")
        index = self.rng.integers(0, self.size, size=batch_size)
        return self.gather(index)

    def gather(self, index: np.ndarray) -> Batch:
        """The transitions at ``index`` (stored positions), as a :class:`Batch` on device."""

        def to_device(array: np.ndarray) -> torch.Tensor:
            return torch.from_numpy(array).to(self.device, non_blocking=True)

        return Batch(
            features=to_device(self.features[index]),
            actions=to_device(self.actions[index]),
            rewards=to_device(self.rewards[index]),
            next_features=to_device(self.next_features[index]),
            terminals=to_device(self.terminals[index]),
        )

    # -- checkpoints ---------------------------------------------------------------------------

    def state_dict(self) -> dict[str, Any]:
        """Contents (valid rows only, as tensors), pointers and the sampling generator's state."""
        rows = slice(0, self.size)
        return {
            "capacity": self.capacity,
            "feature_dim": self.feature_dim,
            "position": self.position,
            "size": self.size,
            "rng": self.rng.bit_generator.state,
            "features": torch.from_numpy(self.features[rows].copy()),
            "next_features": torch.from_numpy(self.next_features[rows].copy()),
            "actions": torch.from_numpy(self.actions[rows].copy()),
            "rewards": torch.from_numpy(self.rewards[rows].copy()),
            "terminals": torch.from_numpy(self.terminals[rows].copy()),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore what :meth:`state_dict` returned (same capacity and feature size)."""
        if (state["capacity"], state["feature_dim"]) != (self.capacity, self.feature_dim):
            raise ValueError(
                f"replay buffer: saved with capacity {state['capacity']} and feature size "
                f"{state['feature_dim']}, expected {self.capacity} and {self.feature_dim}"
            )
        size = int(state["size"])
        for name in ("features", "next_features", "actions", "rewards", "terminals"):
            getattr(self, name)[:size] = state[name].numpy()
        self.size = size
        self.position = int(state["position"])
        self.rng.bit_generator.state = state["rng"]
