"""LSTM training windows stay inside episodes and mask their padding; episode-level split."""

import numpy as np
import pytest
import torch

from socnav_wm.data.windows import make_windows, split_episodes


def encoded_episodes(lengths: list[int]) -> tuple[np.ndarray, ...]:
    """Rows whose latent records (episode id, step) so every window can be traced back."""
    episode_ids = np.repeat(np.arange(len(lengths)) + 100, lengths)
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    steps = np.arange(len(episode_ids)) - np.repeat(starts, lengths)
    latents = np.stack([episode_ids, steps, np.ones_like(steps)], axis=1).astype(np.float32)
    next_latents = latents + np.array([0, 1, 0], dtype=np.float32)  # "z_{t+1}"
    actions = steps % 4
    return latents, actions, episode_ids, next_latents


def test_windows_never_cross_episode_boundaries_and_cover_every_step() -> None:
    lengths = [1, 4, 5, 9, 16, 17]
    seq_len = 4
    latents, actions, episode_ids, next_latents = encoded_episodes(lengths)
    windows = make_windows(latents, actions, episode_ids, next_latents, seq_len)
    assert windows.num_windows == sum(-(-n // seq_len) for n in lengths)
    assert windows.inputs_z.shape == (windows.num_windows, seq_len, 3)
    assert windows.actions.dtype == torch.int64 and windows.mask.dtype == torch.bool
    assert int(windows.mask.sum()) == sum(lengths)  # every step exactly once
    for index in range(windows.num_windows):
        valid = windows.mask[index]
        real = windows.inputs_z[index][valid]
        # Valid steps form a prefix, come from one episode, and are consecutive steps.
        assert bool(valid[: int(valid.sum())].all())
        assert len(torch.unique(real[:, 0])) == 1
        assert torch.equal(real[:, 1], real[0, 1] + torch.arange(len(real), dtype=torch.float32))
        assert int(real[0, 1]) % seq_len == 0  # non-overlapping, aligned to the episode start
        assert torch.equal(windows.targets[index][valid][:, 1], real[:, 1] + 1)
        assert torch.equal(windows.actions[index][valid], real[:, 1].long() % 4)


def test_the_short_last_window_is_masked_not_filled_from_the_next_episode() -> None:
    latents, actions, episode_ids, next_latents = encoded_episodes([5, 3])
    windows = make_windows(latents, actions, episode_ids, next_latents, seq_len=4)
    assert windows.mask.tolist() == [
        [True, True, True, True],
        [True, False, False, False],
        [True, True, True, False],
    ]
    # The padded slots of episode 100's second window hold nothing of episode 101.
    assert torch.all(windows.inputs_z[1, 1:] == 0)
    assert torch.all(windows.targets[1, 1:] == 0)


def test_windows_refuse_interleaved_episodes() -> None:
    latents, actions, episode_ids, next_latents = encoded_episodes([3, 3])
    episode_ids = np.array([100, 100, 101, 101, 100, 100])
    with pytest.raises(ValueError, match="contiguous"):
        make_windows(latents, actions, episode_ids, next_latents, seq_len=2)


def test_split_is_by_episode_disjoint_and_deterministic() -> None:
    episode_ids = np.repeat(np.arange(200), 7)
    train, val = split_episodes(episode_ids, val_fraction=0.1, seed=5)
    assert not np.any(train & val) and np.all(train | val)
    assert set(episode_ids[train]).isdisjoint(set(episode_ids[val]))
    assert len(np.unique(episode_ids[val])) == 20
    again_train, again_val = split_episodes(episode_ids[::-1], val_fraction=0.1, seed=5)
    assert set(episode_ids[::-1][again_val]) == set(episode_ids[val])  # row order is irrelevant
    _, other_val = split_episodes(episode_ids, val_fraction=0.1, seed=6)
    assert set(episode_ids[other_val]) != set(episode_ids[val])


def test_split_keeps_both_sides_non_empty() -> None:
    episode_ids = np.array([0, 0, 1, 1, 1])
    train, val = split_episodes(episode_ids, val_fraction=0.01, seed=0)
    assert train.any() and val.any()
    with pytest.raises(ValueError):
        split_episodes(episode_ids, val_fraction=1.0, seed=0)
