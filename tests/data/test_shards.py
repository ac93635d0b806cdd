"""Rollout shards on disk: round trip, episode integrity, and one-line errors for bad files."""

from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from socnav_wm.data.schema import COLUMN_NAMES, METADATA_SCHEMA_VERSION, rollout_schema
from socnav_wm.data.shards import (
    RolloutError,
    ShardWriter,
    column_to_numpy,
    read_rollouts,
    validate_episodes,
)


def make_episodes(
    first_episode: int, lengths: list[int], seed: int = 0, num_humans: int = 3
) -> dict[str, np.ndarray]:
    """Whole synthetic episodes with consistent boundary flags and obs → next_obs hand-over."""
    rng = np.random.default_rng(seed)
    lengths_arr = np.asarray(lengths)
    rows = int(lengths_arr.sum())
    num_episodes = len(lengths)
    starts = np.concatenate([[0], np.cumsum(lengths_arr)[:-1]])
    t = np.arange(rows) - np.repeat(starts, lengths_arr)
    # Each episode of n steps has n + 1 observations; obs/next_obs are views into them.
    observations = rng.standard_normal((rows + num_episodes, 2 + 7 * num_humans))
    observations = observations.astype(np.float32)
    obs_row = np.arange(rows) + np.repeat(np.arange(num_episodes), lengths_arr)
    is_last = np.zeros(rows, dtype=bool)
    is_last[np.cumsum(lengths_arr) - 1] = True
    success = is_last & (rng.random(rows) < 0.5)
    return {
        "episode_id": np.repeat(np.arange(first_episode, first_episode + num_episodes), lengths),
        "t": t.astype(np.int32),
        "obs": observations[obs_row],
        "action": rng.integers(0, 4, rows).astype(np.int8),
        "reward": rng.standard_normal(rows).astype(np.float32),
        "next_obs": observations[obs_row + 1],
        "is_first": t == 0,
        "is_last": is_last,
        "is_terminal": success,
        "truncated": is_last & ~success,
        "success": success,
        "collision": np.zeros(rows, dtype=np.int8),
        "dmin": rng.random(rows).astype(np.float32),
        "robot_x": rng.random(rows).astype(np.float32),
        "robot_y": rng.random(rows).astype(np.float32),
        "robot_theta": rng.random(rows).astype(np.float32),
        "human_xy": rng.random((rows, 2 * num_humans)).astype(np.float32),
    }


def concat(batches: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    return {name: np.concatenate([batch[name] for batch in batches]) for name in COLUMN_NAMES}


def write_dataset(out_dir: Path, batches: list[dict[str, np.ndarray]], max_rows: int) -> list[Path]:
    with ShardWriter(out_dir, num_humans=3, max_rows_per_shard=max_rows) as writer:
        for batch in batches:
            writer.write(batch)
    return writer.paths


def test_round_trip_preserves_every_column(tmp_path: Path) -> None:
    batches = [make_episodes(0, [5, 12, 7], seed=1), make_episodes(3, [20, 3], seed=2)]
    paths = write_dataset(tmp_path, batches, max_rows=15)
    assert [path.name for path in paths] == [f"shard-{i:05d}.parquet" for i in range(len(paths))]
    table = read_rollouts(tmp_path)
    expected = concat(batches)
    assert table.num_rows == len(expected["t"])
    for name in COLUMN_NAMES:
        np.testing.assert_array_equal(column_to_numpy(table, name), expected[name], err_msg=name)
    validate_episodes(table)
    # Column selection, and a single file as input.
    assert read_rollouts(tmp_path, columns=["t", "obs"]).column_names == ["t", "obs"]
    assert read_rollouts(paths[0]).num_rows > 0


def test_episodes_are_never_split_across_shards(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    batches = [make_episodes(10 * i, list(rng.integers(1, 40, 10)), seed=i) for i in range(4)]
    max_rows = 50
    paths = write_dataset(tmp_path, batches, max_rows=max_rows)
    assert len(paths) > 3
    seen: set[int] = set()
    for index, path in enumerate(paths):
        shard = read_rollouts(path)
        validate_episodes(shard)  # whole episodes only: t from 0, is_first ... is_last
        ids = column_to_numpy(shard, "episode_id")
        assert not seen & set(ids.tolist()), "an episode appears in two shards"
        seen |= set(ids.tolist())
        if index < len(paths) - 1:
            # Closed at the first episode boundary at or past the bound.
            last_length = int(np.sum(ids == ids[-1]))
            assert shard.num_rows >= max_rows
            assert shard.num_rows - last_length < max_rows
    assert seen == set(concat(batches)["episode_id"].tolist())


def test_rerun_removes_stale_shards(tmp_path: Path) -> None:
    write_dataset(tmp_path, [make_episodes(0, [30] * 10)], max_rows=30)
    assert len(list(tmp_path.glob("shard-*.parquet"))) == 10
    write_dataset(tmp_path, [make_episodes(0, [5])], max_rows=30)
    assert [path.name for path in tmp_path.glob("shard-*.parquet")] == ["shard-00000.parquet"]
    assert read_rollouts(tmp_path).num_rows == 5


def test_failure_inside_the_writer_publishes_no_partial_shard(tmp_path: Path) -> None:
    with pytest.raises(RuntimeError), ShardWriter(tmp_path, 3, 1_000, row_group_rows=1) as w:
        w.write(make_episodes(0, [5, 5]))
        raise RuntimeError("collector crashed")
    assert list(tmp_path.iterdir()) == []


def test_write_rejects_partial_episodes_and_bad_shapes(tmp_path: Path) -> None:
    columns = make_episodes(0, [6, 4])
    with ShardWriter(tmp_path, 3, 100) as writer:
        cut = {name: values[:8] for name, values in columns.items()}  # episode 1 incomplete
        with pytest.raises(ValueError, match="episode 1 is not whole"):
            writer.write(cut)
        bad_obs = dict(columns, obs=columns["obs"][:, :20])
        with pytest.raises(ValueError, match="'obs' has shape"):
            writer.write(bad_obs)
        with pytest.raises(ValueError, match="missing"):
            writer.write({name: v for name, v in columns.items() if name != "dmin"})


def _assert_one_line_naming(error: pytest.ExceptionInfo[RolloutError], path: Path) -> None:
    message = str(error.value)
    assert "\n" not in message
    assert str(path) in message


def test_missing_directory_and_empty_directory(tmp_path: Path) -> None:
    missing = tmp_path / "nope"
    with pytest.raises(RolloutError) as error:
        read_rollouts(missing)
    _assert_one_line_naming(error, missing)
    with pytest.raises(RolloutError, match="no shard-") as error:
        read_rollouts(tmp_path)
    _assert_one_line_naming(error, tmp_path)


def test_truncated_shard_is_reported_with_its_name(tmp_path: Path) -> None:
    paths = write_dataset(tmp_path, [make_episodes(0, [20, 20, 20])], max_rows=20)
    data = paths[1].read_bytes()
    paths[1].write_bytes(data[: len(data) // 2])
    with pytest.raises(RolloutError) as error:
        read_rollouts(tmp_path)
    _assert_one_line_naming(error, paths[1])


def test_corrupt_data_pages_are_reported_with_the_name(tmp_path: Path) -> None:
    (path,) = write_dataset(tmp_path, [make_episodes(0, [50])], max_rows=100)
    data = bytearray(path.read_bytes())
    # Scribble over the column data but keep the footer (and the magic bytes) intact.
    data[8:400] = bytes(392)
    path.write_bytes(bytes(data))
    with pytest.raises(RolloutError) as error:
        read_rollouts(path)
    _assert_one_line_naming(error, path)


def _table_from(columns: dict[str, np.ndarray], schema: pa.Schema) -> pa.Table:
    arrays = []
    for field in schema:
        values = columns[field.name]
        if pa.types.is_fixed_size_list(field.type):
            flat = pa.array(values.reshape(-1), type=pa.float32())
            arrays.append(pa.FixedSizeListArray.from_arrays(flat, field.type.list_size))
        else:
            arrays.append(pa.array(values, type=field.type))
    return pa.Table.from_arrays(arrays, schema=schema)


def test_wrong_schema_version_is_refused(tmp_path: Path) -> None:
    schema = rollout_schema(3)
    metadata = dict(schema.metadata)
    metadata[METADATA_SCHEMA_VERSION] = b"2"
    path = tmp_path / "shard-00000.parquet"
    pq.write_table(_table_from(make_episodes(0, [4]), schema.with_metadata(metadata)), path)
    with pytest.raises(RolloutError, match="schema version 2") as error:
        read_rollouts(tmp_path)
    _assert_one_line_naming(error, path)


def test_missing_columns_are_named(tmp_path: Path) -> None:
    full = rollout_schema(3)
    schema = pa.schema([f for f in full if f.name != "dmin"], metadata=full.metadata)
    path = tmp_path / "shard-00000.parquet"
    pq.write_table(_table_from(make_episodes(0, [4]), schema), path)
    with pytest.raises(RolloutError, match="missing columns dmin") as error:
        read_rollouts(tmp_path)
    _assert_one_line_naming(error, path)
    # Reading only columns that are present works.
    assert read_rollouts(tmp_path, columns=["t"]).num_rows == 4


def _table(columns: dict[str, np.ndarray]) -> pa.Table:
    return _table_from(columns, rollout_schema(3))


def test_validate_episodes_catches_a_broken_hand_over() -> None:
    columns = make_episodes(0, [5, 6, 4])
    validate_episodes(_table(columns))
    columns["next_obs"] = columns["next_obs"].copy()
    columns["next_obs"][7, 3] += 1.0  # inside episode 1 (rows 5..10)
    with pytest.raises(RolloutError, match="episode 1: next_obs"):
        validate_episodes(_table(columns))


def test_validate_episodes_catches_bad_flags_and_steps() -> None:
    columns = make_episodes(0, [5, 6, 4])
    missing_last = dict(columns, is_last=columns["is_last"].copy())
    missing_last["is_last"][10] = False  # episode 1's final row
    with pytest.raises(RolloutError, match="episode 1: is_last"):
        validate_episodes(_table(missing_last))
    extra_first = dict(columns, is_first=columns["is_first"].copy())
    extra_first["is_first"][12] = True
    with pytest.raises(RolloutError, match="episode 2: is_first"):
        validate_episodes(_table(extra_first))
    skipped = dict(columns, t=columns["t"].copy())
    skipped["t"][3] = 7
    with pytest.raises(RolloutError, match="episode 0: t does not run"):
        validate_episodes(_table(skipped))
    # Episode 0 again after episode 1: rows not contiguous.
    interleaved = {name: np.concatenate([v, v[:5]]) for name, v in columns.items()}
    with pytest.raises(RolloutError, match="episode 0: rows are not contiguous"):
        validate_episodes(_table(interleaved))


def test_non_finite_observation_is_refused_naming_shard_row_and_column(tmp_path: Path) -> None:
    episodes = make_episodes(0, [20, 20, 20])
    episodes["obs"][27, 5] = np.nan  # row 7 of the second shard (20 rows per shard)
    paths = write_dataset(tmp_path, [episodes], max_rows=20)
    with pytest.raises(RolloutError) as error:
        read_rollouts(tmp_path, columns=["episode_id", "obs"])
    assert str(error.value) == f"{paths[1]}: row 7, column obs[5]: not finite (nan)"
    _assert_one_line_naming(error, paths[1])
    # The other shards are clean and read on their own.
    assert read_rollouts(paths[0]).num_rows == 20


def test_infinite_next_obs_and_reward_are_refused(tmp_path: Path) -> None:
    episodes = make_episodes(0, [10])
    episodes["next_obs"][3, 0] = -np.inf
    (path,) = write_dataset(tmp_path, [episodes], max_rows=100)
    with pytest.raises(RolloutError, match=r"row 3, column next_obs\[0\]: not finite \(-inf\)"):
        read_rollouts(path)
    episodes = make_episodes(0, [10])
    episodes["reward"][9] = np.inf
    (path,) = write_dataset(tmp_path, [episodes], max_rows=100)
    with pytest.raises(RolloutError, match=r"row 9, column reward: not finite \(inf\)"):
        read_rollouts(path)
    # Columns not read are not checked, and dmin may be infinite (no human in sight).
    assert read_rollouts(path, columns=["t", "obs"]).num_rows == 10
    episodes = make_episodes(0, [10])
    episodes["dmin"][:] = np.inf
    write_dataset(tmp_path, [episodes], max_rows=100)
    assert read_rollouts(tmp_path).num_rows == 10
