"""Training windows for the latent LSTM, cut inside episodes, and the train/validation split.

The original code zero-padded every episode to 216 steps and trained on the padding
(paper_spec §4, §8.4). Here every window lies inside one episode; the last, shorter window of an
episode is padded at its end and the padding is masked out of every loss and metric. Because the
LSTM is causal, padding *after* the valid steps cannot change the predictions on them.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import torch


class Windows(NamedTuple):
    """Fixed-length transition windows, each inside one episode and started from a zero state.

    Attributes:
        inputs_z: (windows, seq_len, latent) float32, latent z_t of the observation at step t.
        actions: (windows, seq_len) int64, action a_t taken at step t.
        targets: (windows, seq_len, latent) float32, latent of the observation after step t
            (z_{t+1}; on an episode's last step, the latent of its terminal observation).
        mask: (windows, seq_len) bool, True on real transitions, False on padding.
    """

    inputs_z: torch.Tensor
    actions: torch.Tensor
    targets: torch.Tensor
    mask: torch.Tensor

    @property
    def num_windows(self) -> int:
        """Number of windows (``len()`` stays the tuple's field count)."""
        return int(self.inputs_z.shape[0])

    def select(self, index: torch.Tensor | slice) -> Windows:
        """The windows at ``index`` (a slice, index tensor or boolean mask over windows)."""
        return Windows(
            self.inputs_z[index], self.actions[index], self.targets[index], self.mask[index]
        )

    def to(self, device: torch.device | str) -> Windows:
        """The same windows on ``device``."""
        return Windows(*(tensor.to(device) for tensor in self))


def _episode_runs(episode_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(starts, lengths) of the runs of equal episode ids; each id must form a single run."""
    rows = len(episode_ids)
    if rows == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    starts = np.concatenate([[0], np.flatnonzero(episode_ids[1:] != episode_ids[:-1]) + 1])
    if len(np.unique(episode_ids)) != len(starts):
        raise ValueError("rows of each episode must be contiguous (in episode order)")
    lengths = np.diff(np.append(starts, rows))
    return starts.astype(np.int64), lengths.astype(np.int64)


def make_windows(
    latents: np.ndarray | torch.Tensor,
    actions: np.ndarray | torch.Tensor,
    episode_ids: np.ndarray | torch.Tensor,
    next_latents: np.ndarray | torch.Tensor,
    seq_len: int,
) -> Windows:
    """Cut encoded episodes into non-overlapping, masked windows of ``seq_len`` transitions.

    Every episode of n steps gives ceil(n / seq_len) windows covering it exactly once; windows
    never cross an episode boundary. Vectorised: no Python loop over rows or episodes.

    Args:
        latents: (n, latent), latent of ``obs`` per rollout row, rows in episode order.
        actions: (n,), action per row (0..3).
        episode_ids: (n,), episode of each row; each episode's rows contiguous.
        next_latents: (n, latent), latent of ``next_obs`` per row (the prediction target).
        seq_len: window length in steps.

    Returns:
        :class:`Windows` on the CPU.
    """
    if seq_len < 1:
        raise ValueError(f"seq_len must be >= 1, got {seq_len}")
    latents_np = np.asarray(latents, dtype=np.float32)
    next_np = np.asarray(next_latents, dtype=np.float32)
    actions_np = np.asarray(actions, dtype=np.int64)
    ids_np = np.asarray(episode_ids)
    rows = len(ids_np)
    if latents_np.ndim != 2 or latents_np.shape[0] != rows or next_np.shape != latents_np.shape:
        raise ValueError(
            f"latents {latents_np.shape} and next_latents {next_np.shape} must both be "
            f"({rows}, latent) like episode_ids"
        )
    if actions_np.shape != (rows,):
        raise ValueError(f"actions has shape {actions_np.shape}, expected ({rows},)")
    latent_dim = latents_np.shape[1]

    starts, lengths = _episode_runs(ids_np)
    windows_per_episode = -(-lengths // seq_len)  # ceil division
    first_window = np.concatenate([[0], np.cumsum(windows_per_episode)[:-1]]).astype(np.int64)
    num_windows = int(windows_per_episode.sum())

    step = np.arange(rows) - np.repeat(starts, lengths)  # step index within the episode
    window = np.repeat(first_window, lengths) + step // seq_len
    position = step % seq_len

    inputs_z = np.zeros((num_windows, seq_len, latent_dim), dtype=np.float32)
    targets = np.zeros_like(inputs_z)
    window_actions = np.zeros((num_windows, seq_len), dtype=np.int64)
    mask = np.zeros((num_windows, seq_len), dtype=bool)
    inputs_z[window, position] = latents_np
    targets[window, position] = next_np
    window_actions[window, position] = actions_np
    mask[window, position] = True
    return Windows(
        torch.from_numpy(inputs_z),
        torch.from_numpy(window_actions),
        torch.from_numpy(targets),
        torch.from_numpy(mask),
    )


def split_episodes(
    episode_ids: np.ndarray, val_fraction: float, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """Split rows into train / validation by whole episodes, deterministically for a seed.

    The distinct episode ids are sorted before shuffling, so the split depends only on the set
    of episodes and the seed, not on row order. With at least two episodes and
    ``0 < val_fraction < 1``, both sides get at least one episode.

    Args:
        episode_ids: (n,) episode id of each row.
        val_fraction: share of episodes held out for validation, in [0, 1).
        seed: seed of the numpy Generator that shuffles the episodes.

    Returns:
        (train_mask, val_mask): boolean (n,) row masks, disjoint and covering every row.
    """
    if not 0.0 <= val_fraction < 1.0:
        raise ValueError(f"val_fraction must be in [0, 1), got {val_fraction}")
    ids = np.asarray(episode_ids)
    unique = np.unique(ids)
    num_val = int(round(val_fraction * len(unique)))
    if val_fraction > 0 and len(unique) >= 2:
        num_val = min(max(num_val, 1), len(unique) - 1)
    shuffled = np.random.default_rng(seed).permutation(unique)
    val_mask = np.isin(ids, shuffled[:num_val])
    return ~val_mask, val_mask
