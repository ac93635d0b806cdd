"""The replay buffer: circular storage, typed batches, seeded sampling, checkpoints."""

import numpy as np
import pytest
import torch

from socnav_wm.agents.replay import Batch, NStepAccumulator, ReplayBuffer


def fill(buffer: ReplayBuffer, start: int, n: int) -> None:
    """Transitions start..start+n−1, each marked by its number in every field."""
    ids = np.arange(start, start + n, dtype=np.float32)
    features = np.repeat(ids[:, None], buffer.feature_dim, axis=1)
    buffer.add(features, ids.astype(np.int64) % 4, ids, features + 0.5, ids % 2 == 0, ids / 100)


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
    torch.testing.assert_close(batch.discounts, ids / 100)
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
        ReplayBuffer(4, 2).add(np.zeros((1, 3)), [0], [0.0], np.zeros((1, 3)), [False], 0.9)
    with pytest.raises(ValueError, match="capacity"):
        ReplayBuffer(0, 2)


def step_of(t: int, envs: int = 2) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Features marked t (env e: t + 10e), actions t, rewards t + 1, next features t + 1."""
    marks = t + 10.0 * np.arange(envs)
    return marks[:, None], np.full(envs, t), np.full(envs, t + 1.0), (marks + 1)[:, None]


def test_one_step_accumulator_passes_transitions_through() -> None:
    acc = NStepAccumulator(num_envs=2, feature_dim=1, n=1, gamma=0.9)
    f, a, r, nf = step_of(0)
    out = acc.push(f, a, r, nf, np.array([False, True]), np.array([False, True]))
    features, actions, rewards, next_features, terminals, discounts = out
    assert features[:, 0].tolist() == [0, 10] and next_features[:, 0].tolist() == [1, 11]
    assert rewards.tolist() == [1, 1] and actions.tolist() == [0, 0]
    assert terminals.tolist() == [0, 1]
    np.testing.assert_allclose(discounts, [0.9, 0.9])


def test_three_step_returns_by_hand() -> None:
    gamma = 0.5
    acc = NStepAccumulator(num_envs=2, feature_dim=1, n=3, gamma=gamma)
    no = np.array([False, False])
    for t in range(2):  # windows fill up: nothing is complete yet
        assert acc.push(*step_of(t), no, no)[0].shape == (0, 1)
    # t = 2: both windows hold 3 steps; env 1's episode ends here (terminal).
    out = acc.push(*step_of(2), np.array([False, True]), np.array([False, True]))
    features, actions, rewards, next_features, terminals, discounts = out
    # env 0: (s_0, a_0, 1 + 0.5·2 + 0.25·3 = 2.75, s_3, γ³) — its oldest, n steps old.
    # env 1: all three pending, to the final state s_3 = 13: k = 3, 2, 1 steps.
    assert features[:, 0].tolist() == [0, 10, 11, 12]
    assert actions.tolist() == [0, 0, 1, 2]
    np.testing.assert_allclose(rewards, [2.75, 2.75, 2 + 0.5 * 3, 3])
    assert next_features[:, 0].tolist() == [3, 13, 13, 13]
    assert terminals.tolist() == [0, 1, 1, 1]
    np.testing.assert_allclose(discounts, [0.125, 0.125, 0.25, 0.5])
    # env 1 starts afresh; env 0 goes on with its window shifted by one.
    out = acc.push(*step_of(3), no, no)
    assert out[0][:, 0].tolist() == [1]  # env 0 emits (s_1, …); env 1 holds 1 step
    np.testing.assert_allclose(out[2], [2 + 0.5 * 3 + 0.25 * 4])
    assert acc.count.tolist() == [2, 1]


def test_accumulator_state_round_trip() -> None:
    acc = NStepAccumulator(num_envs=2, feature_dim=1, n=3, gamma=0.9)
    no = np.array([False, False])
    acc.push(*step_of(0), no, no)
    copy = NStepAccumulator(num_envs=2, feature_dim=1, n=3, gamma=0.9)
    copy.load_state_dict(acc.state_dict())
    done = np.array([True, False])
    restored, original = copy.push(*step_of(1), done, done), acc.push(*step_of(1), done, done)
    for x, y in zip(restored, original, strict=True):
        np.testing.assert_array_equal(x, y)
