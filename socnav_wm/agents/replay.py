"""Uniform experience replay in preallocated arrays, returning typed batches of tensors, and the
per-environment accumulator that turns one-step transitions into n-step ones.

Storage is one numpy table of float32 rows, allocated once with ``np.zeros``: the operating
system hands out zeroed pages lazily, so a 1M-transition buffer (the paper's MASPM setting) costs
memory only as it fills. A row holds a whole transition (features, next features, reward,
terminal flag, discount, and the action, an integer below 2²⁴ and so exact as a float32), so a
sampled batch is one indexed gather and one copy to the learner's device; the batch's fields
are views of it. Sampling draws indices from the buffer's own numpy ``Generator``, whose state is
part of :meth:`ReplayBuffer.state_dict`, so a resumed run samples exactly what an uninterrupted
one would.
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
        rewards: (batch,) float32, the (n-step discounted) reward from t on.
        next_features: (batch, feature_dim) float32, the Q-network input k steps later (for
            the last steps of an episode: the features of its final observation).
        terminals: (batch,) float32, 1 where the return must not be bootstrapped from
            ``next_features`` (a true terminal state; also a time-limit truncation when the
            learner treats timeouts as terminal), else 0.
        discounts: (batch,) float32, γᵏ for the k steps between ``features`` and
            ``next_features`` (γ for one-step transitions).
    """

    features: torch.Tensor
    actions: torch.Tensor
    rewards: torch.Tensor
    next_features: torch.Tensor
    terminals: torch.Tensor
    discounts: torch.Tensor


_FIELDS = ("features", "next_features", "actions", "rewards", "terminals", "discounts")


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

    The fields (``features``, ``next_features``, ``rewards``, ``terminals``, ``discounts``,
    ``actions``) are column views of one table; ``actions`` holds the action numbers as floats.
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
        f = self.feature_dim
        self.table = np.zeros((self.capacity, 2 * f + 4), dtype=np.float32)
        """One row per transition: features | next_features | reward | terminal | discount |
        action."""
        self.features = self.table[:, :f]
        self.next_features = self.table[:, f : 2 * f]
        self.rewards = self.table[:, 2 * f]
        self.terminals = self.table[:, 2 * f + 1]
        self.discounts = self.table[:, 2 * f + 2]
        self.actions = self.table[:, 2 * f + 3]
        self.position = 0
        """Index the next transition is written to."""
        self.size = 0
        """Number of valid transitions (≤ capacity)."""

    @staticmethod
    def bytes_needed(capacity: int, feature_dim: int) -> int:
        """What a buffer of these sizes allocates: a row of two float32 feature vectors and four
        float32 scalars per transition."""
        return int(capacity) * 4 * (2 * int(feature_dim) + 4)

    def __len__(self) -> int:
        return self.size

    def add(
        self,
        features: np.ndarray | torch.Tensor,
        actions: np.ndarray | torch.Tensor,
        rewards: np.ndarray | torch.Tensor,
        next_features: np.ndarray | torch.Tensor,
        terminals: np.ndarray | torch.Tensor,
        discounts: np.ndarray | torch.Tensor | float,
    ) -> None:
        """Append a batch of ``n`` transitions, wrapping around at the end.

        Args:
            features, next_features: (n, feature_dim).
            actions: (n,) integers; rewards: (n,); terminals: (n,) bool or 0/1;
            discounts: (n,) or one number, γᵏ of each transition.
        """
        features = _as_numpy(features)
        n = features.shape[0]
        if features.shape != (n, self.feature_dim):
            raise ValueError(
                f"features: expected shape (n, {self.feature_dim}), got {features.shape}"
            )
        if n > self.capacity:
            raise ValueError(f"cannot add {n} transitions to a buffer of capacity {self.capacity}")
        start = self.position
        rows = slice(start, start + n)
        if start + n > self.capacity:  # wraps around: write through an index
            rows = (start + np.arange(n)) % self.capacity
        self.features[rows] = features
        self.next_features[rows] = _as_numpy(next_features)
        self.actions[rows] = _as_numpy(actions)
        self.rewards[rows] = _as_numpy(rewards)
        self.terminals[rows] = _as_numpy(terminals)
        self.discounts[rows] = _as_numpy(discounts)
        self.position = int((self.position + n) % self.capacity)
        self.size = min(self.size + n, self.capacity)

    def sample(self, batch_size: int) -> Batch:
        """``batch_size`` transitions drawn uniformly with replacement, as tensors on device."""
        if self.size == 0:
            raise ValueError("cannot sample from an empty replay buffer")
        index = self.rng.integers(0, self.size, size=batch_size)
        return self.gather(index)

    def gather(self, index: np.ndarray) -> Batch:
        """The transitions at ``index`` (stored positions), as a :class:`Batch` on device: one
        gather of whole rows, one copy to the device, and the fields as views of it."""
        rows = torch.from_numpy(self.table[index]).to(self.device, non_blocking=True)
        f = self.feature_dim
        return Batch(
            features=rows[:, :f],
            actions=rows[:, 2 * f + 3].long(),
            rewards=rows[:, 2 * f],
            next_features=rows[:, f : 2 * f],
            terminals=rows[:, 2 * f + 1],
            discounts=rows[:, 2 * f + 2],
        )

    # -- checkpoints ---------------------------------------------------------------------------

    def state_dict(self) -> dict[str, Any]:
        """Contents (valid rows only, as tensors), pointers and the sampling generator's state."""
        rows = slice(0, self.size)
        state: dict[str, Any] = {
            "capacity": self.capacity,
            "feature_dim": self.feature_dim,
            "position": self.position,
            "size": self.size,
            "rng": self.rng.bit_generator.state,
        }
        for name in _FIELDS:
            state[name] = torch.from_numpy(getattr(self, name)[rows].copy())
        state["actions"] = state["actions"].long()
        return state

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore what :meth:`state_dict` returned (same capacity and feature size)."""
        if (state["capacity"], state["feature_dim"]) != (self.capacity, self.feature_dim):
            raise ValueError(
                f"replay buffer: saved with capacity {state['capacity']} and feature size "
                f"{state['feature_dim']}, expected {self.capacity} and {self.feature_dim}"
            )
        size = int(state["size"])
        for name in _FIELDS:
            getattr(self, name)[:size] = state[name].numpy()
        self.size = size
        self.position = int(state["position"])
        self.rng.bit_generator.state = state["rng"]


class NStepAccumulator:
    """Turns each env's one-step transitions into n-step ones (``n = 1``: passes them through).

    Each env keeps its last ``n`` (features, action, reward). Once it holds ``n`` of them, every
    step emits the oldest as ``(s_t, a_t, Σ_{i<n} γⁱ r_{t+i}, s_{t+n}, terminal, γⁿ)``. When an
    episode ends, everything it still holds is emitted with the shorter horizons left
    (``k = n, …, 1`` steps to the final observation, discount γᵏ, the episode's terminal flag).

    Args:
        num_envs: environments stepped together.
        feature_dim: size of the feature vectors.
        n: steps per transition (≥ 1).
        gamma: discount per step.
    """

    def __init__(self, num_envs: int, feature_dim: int, n: int, gamma: float) -> None:
        if n < 1:
            raise ValueError(f"n: must be >= 1, got {n}")
        self.n = int(n)
        self.gamma = float(gamma)
        self.features = np.zeros((num_envs, self.n, feature_dim), dtype=np.float32)
        self.actions = np.zeros((num_envs, self.n), dtype=np.int64)
        self.rewards = np.zeros((num_envs, self.n), dtype=np.float64)
        self.count = np.zeros(num_envs, dtype=np.int64)
        """Pending one-step transitions of each env (oldest at index 0)."""
        self._powers = self.gamma ** np.arange(self.n + 1)

    def push(
        self,
        features: np.ndarray | torch.Tensor,
        actions: np.ndarray,
        rewards: np.ndarray,
        next_features: np.ndarray | torch.Tensor,
        terminals: np.ndarray,
        done: np.ndarray,
    ) -> tuple[np.ndarray, ...]:
        """Add one step of every env; return the transitions that are complete.

        Args:
            features, next_features: (N, feature_dim), the step's s_t and s_{t+1}.
            actions, rewards: (N,).
            terminals: (N,) bool, no bootstrapping from s_{t+1} (see :class:`Batch`).
            done: (N,) bool, the env's episode ended with this step.

        Returns:
            ``(features, actions, rewards, next_features, terminals, discounts)`` arrays of the
            ``m`` emitted transitions, in env order (an ending episode's oldest first).
        """
        features = _as_numpy(features)
        next_features = _as_numpy(next_features)
        envs = np.arange(self.count.shape[0])
        self.features[envs, self.count] = features
        self.actions[envs, self.count] = actions
        self.rewards[envs, self.count] = rewards
        self.count += 1

        # Envs whose window is full and whose episode goes on: emit their oldest, all at once.
        full = np.flatnonzero((self.count == self.n) & ~done)
        parts = [
            (
                self.features[full, 0],
                self.actions[full, 0],
                self.rewards[full] @ self._powers[: self.n],
                next_features[full],
                np.zeros(full.size),
                np.full(full.size, self._powers[self.n]),
            )
        ]
        self.features[full, :-1] = self.features[full, 1:]
        self.actions[full, :-1] = self.actions[full, 1:]
        self.rewards[full, :-1] = self.rewards[full, 1:]
        self.count[full] -= 1
        # Envs whose episode ended: emit everything pending, k = pending … 1 steps from the end.
        for env in np.flatnonzero(done):
            pending = int(self.count[env])
            steps = pending - np.arange(pending)
            # Discounted sums of the rewards from each pending step to the end of the episode.
            returns = [
                self.rewards[env, j:pending] @ self._powers[: pending - j] for j in range(pending)
            ]
            parts.append(
                (
                    self.features[env, :pending],
                    self.actions[env, :pending],
                    np.asarray(returns),
                    np.repeat(next_features[env][None], pending, axis=0),
                    np.full(pending, float(terminals[env])),
                    self._powers[steps],
                )
            )
            self.count[env] = 0
        fields = list(zip(*parts, strict=True))
        return (
            np.concatenate(fields[0]).astype(np.float32, copy=False),
            np.concatenate(fields[1]).astype(np.int64, copy=False),
            np.concatenate(fields[2]).astype(np.float32),
            np.concatenate(fields[3]).astype(np.float32, copy=False),
            np.concatenate(fields[4]).astype(np.float32),
            np.concatenate(fields[5]).astype(np.float32),
        )

    def state_dict(self) -> dict[str, Any]:
        return {
            "features": torch.from_numpy(self.features.copy()),
            "actions": torch.from_numpy(self.actions.copy()),
            "rewards": torch.from_numpy(self.rewards.copy()),
            "count": torch.from_numpy(self.count.copy()),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        for name in ("features", "actions", "rewards", "count"):
            getattr(self, name)[...] = state[name].numpy()
