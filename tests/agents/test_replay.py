"""The replay buffer: circular storage, typed batches, seeded sampling, checkpoints."""

import numpy as np
import pytest
import torch

from pipeline.agents.replay import Batch, ReplayBuffer


def fill(buffer: ReplayBuffer, start: int, n: int) -> None:
    """Transitions start..start+n−1, each marked by its number in every field."""
    ids = np.arange(start, start + n, dtype=np.float32)
    features = np.repeat(ids[:, None], buffer.feature_dim, axis=1)
    buffer.add(features, ids.astype(np.int64) % 4, ids, features + 0.5, ids % 2 == 0)


def test_wraps_around_and_overwrites_the_oldest() -> None:
    buffer = ReplayBuffer(5, 3, seed=0)
    fill(buffer, 0, 3)
    assert (len(buffer), buffer.position) == (3, 3)
    fill(buffer, 3, 4)  # 3..6: 5 and 6 overwrite slots 0 and 1
    assert (len(buffer), buffer.position) == (5, 2)
    assert buffer.rewards.tolist() == [5, 6, 2, 3, 4]
    assert buffer.features[:, 0].tolist() == [5, 6, 2, 3, 4]
    assert buffer.next_features[1, 0] == 6.5
    assert buffer.actions.tolist() == [1, 2, 2, 3, 0]
    assert buffer.terminals.tolist() == [0, 1, 1, 0, 1]


def test_sample_is_a_typed_batch_of_consistent_transitions() -> None:
    buffer = ReplayBuffer(100, 4, seed=1)
    fill(buffer, 0, 30)
    batch = buffer.sample(16)
    assert isinstance(batch, Batch)
    assert batch.features.shape == (16, 4) and batch.features.dtype == torch.float32
    assert batch.actions.dtype == torch.int64 and batch.actions.shape == (16,)
    assert batch.rewards.dtype == torch.float32 and batch.terminals.dtype == torch.float32
    ids = batch.rewards
    # Every field of a row comes from the same transition, and only stored ones are drawn.
    assert torch.equal(batch.features[:, 0], ids)
    assert torch.equal(batch.next_features[:, 2], ids + 0.5)
    assert torch.equal(batch.actions, ids.long() % 4)
    assert torch.equal(batch.terminals, (ids.long() % 2 == 0).float())
    assert ids.max() < 30


def test_sampling_is_seeded_and_uniform() -> None:
    a, b = ReplayBuffer(50, 1, seed=7), ReplayBuffer(50, 1, seed=7)
    fill(a, 0, 50)
    fill(b, 0, 50)
    assert torch.equal(a.sample(32).rewards, b.sample(32).rewards)
    counts = np.bincount(a.sample(50_000).rewards.long().numpy(), minlength=50)
    assert counts.min() > 800 and counts.max() < 1200  # 1000 expected per transition


def test_state_dict_round_trip_continues_the_same_samples() -> None:
    buffer = ReplayBuffer(8, 2, seed=3)
    fill(buffer, 0, 6)
    fill(buffer, 6, 5)  # wrapped
    buffer.sample(4)
    copy = ReplayBuffer(8, 2, seed=99)
    copy.load_state_dict(buffer.state_dict())
    assert (copy.position, len(copy)) == (buffer.position, len(buffer))
    for x, y in zip(copy.sample(6), buffer.sample(6), strict=True):
        assert torch.equal(x, y)
    with pytest.raises(ValueError, match="capacity 8"):
        ReplayBuffer(9, 2).load_state_dict(buffer.state_dict())


def test_errors() -> None:
    with pytest.raises(ValueError, match="empty"):
        ReplayBuffer(4, 2).sample(1)
    with pytest.raises(ValueError, match="expected shape"):
        ReplayBuffer(4, 2).add(np.zeros((1, 3)), [0], [0.0], np.zeros((1, 3)), [False])
    with pytest.raises(ValueError, match="capacity"):
        ReplayBuffer(0, 2)
