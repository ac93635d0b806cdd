"""Rollout shards: writing whole episodes to Parquet, reading and checking them back.

A dataset is a directory of ``shard-00000.parquet``, ``shard-00001.parquet``, … files, each with
the schema of :func:`socnav_wm.data.schema.rollout_schema`. An episode never straddles two shards,
so any shard can be read, checked and used on its own.
"""

from __future__ import annotations

import contextlib
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from socnav_wm.data.compatibility import check_made_with
from socnav_wm.data.schema import (
    COLLISION_NONE,
    COLLISION_WALL,
    COLUMN_NAMES,
    NUM_ACTIONS,
    SCHEMA_VERSION,
    rollout_schema,
    schema_env,
    schema_num_humans,
    schema_version,
)
from socnav_wm.env.params import EnvParams
from socnav_wm.io import atomic_path

SHARD_GLOB = "shard-*.parquet"
DEFAULT_ROW_GROUP_ROWS = 131_072
"""Rows buffered before a row group is written: large groups compress better and read faster."""


# Scalar column types → numpy dtypes (pyarrow's to_pandas_dtype() would import pandas).
_NUMPY_DTYPES: dict[pa.DataType, type] = {
    pa.int64(): np.int64,
    pa.int32(): np.int32,
    pa.int8(): np.int8,
    pa.float32(): np.float32,
    pa.bool_(): np.bool_,
}


class RolloutError(ValueError):
    """A rollout file or dataset is missing, unreadable, or inconsistent (one-line message)."""


FINITE_COLUMNS: tuple[str, ...] = ("obs", "next_obs", "reward")
"""Float columns the world model and the agents learn from: every value must be finite.

Other float columns may legitimately hold ``inf`` (``dmin`` with no humans in the scene).
"""

VALUE_RANGES: dict[str, tuple[int, int]] = {
    "action": (0, NUM_ACTIONS - 1),
    "collision": (COLLISION_NONE, COLLISION_WALL),
}
"""Integer columns that hold codes: the smallest and largest valid value of each."""


def shard_name(index: int) -> str:
    """File name of the ``index``-th shard: ``shard-00000.parquet``."""
    return f"shard-{index:05d}.parquet"


def list_shards(directory: str | Path) -> list[Path]:
    """The shard files of a dataset directory, in write order (sorted by name)."""
    return sorted(Path(directory).glob(SHARD_GLOB))


def _episode_starts(episode_id: np.ndarray) -> np.ndarray:
    """Row indices where a new episode begins, shape (num_episodes,); rows must be contiguous."""
    if episode_id.size == 0:
        return np.zeros(0, dtype=np.int64)
    change = np.flatnonzero(episode_id[1:] != episode_id[:-1]) + 1
    return np.concatenate([[0], change]).astype(np.int64)


def _fixed_list(values: np.ndarray, width: int, name: str, rows: int) -> pa.FixedSizeListArray:
    """A (rows, width) numpy array as an Arrow fixed-size list column, without a per-row loop."""
    values = np.asarray(values, dtype=np.float32)
    if values.shape != (rows, width):
        raise ValueError(f"column {name!r} has shape {values.shape}, expected ({rows}, {width})")
    flat = pa.array(np.ascontiguousarray(values).reshape(-1), type=pa.float32())
    return pa.FixedSizeListArray.from_arrays(flat, width)


class ShardWriter:
    """Writes whole episodes to size-bounded, atomically published Parquet shards.

    Rows are buffered and written in large row groups; a shard is closed at the first episode
    boundary at which it holds ``>= max_rows_per_shard`` rows, so shards are slightly larger than
    the bound but never split an episode. Each shard is written to a hidden temporary file and
    renamed onto ``shard-NNNNN.parquet`` when complete, so a crash never leaves a truncated shard
    under a shard name. Shards of an earlier run in ``out_dir`` are deleted when the writer opens.

    ``env``: the scenarios' parameters (:func:`socnav_wm.data.compatibility.made_with`), kept
    in every shard's metadata for the readers to check.

    Usage::

        with ShardWriter(out_dir, num_humans=3, max_rows_per_shard=500_000) as writer:
            writer.write(columns)   # whole episodes, any number per call
        paths = writer.paths
    """

    def __init__(
        self,
        out_dir: str | Path,
        num_humans: int,
        max_rows_per_shard: int,
        *,
        compression: str = "zstd",
        row_group_rows: int = DEFAULT_ROW_GROUP_ROWS,
        env: Mapping[str, Any] | None = None,
    ) -> None:
        if max_rows_per_shard < 1:
            raise ValueError(f"max_rows_per_shard must be >= 1, got {max_rows_per_shard}")
        if env is not None and env.get("num_humans") != num_humans:
            raise ValueError(f"env has {env.get('num_humans')} humans, the shards {num_humans}")
        self.out_dir = Path(out_dir)
        self.schema = rollout_schema(num_humans, env)
        self.num_humans = num_humans
        self.max_rows_per_shard = max_rows_per_shard
        self.compression = compression
        self.row_group_rows = max(1, row_group_rows)
        self.paths: list[Path] = []

        self.out_dir.mkdir(parents=True, exist_ok=True)
        # A re-run must never mix its shards with those of an earlier, possibly larger, run.
        for stale in list_shards(self.out_dir):
            stale.unlink()
        # Temporaries of shards that a killed run never published.
        for orphan in self.out_dir.glob(".shard-*.parquet.tmp-*"):
            orphan.unlink(missing_ok=True)

        self._closed = False
        self._shard_stack: contextlib.ExitStack | None = None
        self._current_path: Path | None = None
        self._parquet: pq.ParquetWriter | None = None
        self._rows_in_shard = 0
        self._pending: list[pa.RecordBatch] = []
        self._pending_rows = 0
        self.rows_written = 0
        self.episodes_written = 0

    # -- public API -------------------------------------------------------------------------

    def write(self, columns: Mapping[str, np.ndarray]) -> None:
        """Append one or more whole episodes.

        Args:
            columns: one numpy array per schema column, all with the same number of rows ``n``,
                rows contiguous per episode and every episode complete (starts with ``is_first``,
                ends with ``is_last``). ``obs`` and ``next_obs`` have shape (n, obs_dim),
                ``human_xy`` (n, 2·num_humans); the others (n,). Dtypes are cast to the schema.
        """
        if self._closed:
            raise RuntimeError("ShardWriter.write called after close()")
        batch = self._to_record_batch(columns)
        if batch.num_rows == 0:
            return
        episode_id = np.asarray(columns["episode_id"], dtype=np.int64)
        starts = _episode_starts(episode_id)
        ends = np.append(starts[1:], batch.num_rows)  # exclusive end row of each episode
        self._check_whole_episodes(columns, starts, ends)

        offset = 0
        while offset < batch.num_rows:
            # Cut after the first episode that brings the open shard to the bound, if any.
            needed = self.max_rows_per_shard - self._rows_in_shard
            cut = int(np.searchsorted(ends, offset + needed, side="left"))
            if cut < len(ends):
                stop = int(ends[cut])
                self._append(batch.slice(offset, stop - offset))
                self._close_shard()
                offset = stop
            else:
                self._append(batch.slice(offset))
                offset = batch.num_rows
        self.rows_written += batch.num_rows
        self.episodes_written += len(starts)

    def close(self) -> list[Path]:
        """Flush and publish the open shard; return every shard path written, in order."""
        if not self._closed:
            self._closed = True
            self._close_shard()
        return list(self.paths)

    def abort(self) -> None:
        """Discard the open shard (its temporary file); already published shards are kept."""
        self._closed = True
        self._pending, self._pending_rows = [], 0
        if self._parquet is not None:
            self._parquet.close()
            self._parquet = None
        if self._shard_stack is not None:
            stack, self._shard_stack = self._shard_stack, None
            with contextlib.suppress(RuntimeError):
                # Re-raising inside the stack deletes the temporary file without publishing it.
                stack.__exit__(RuntimeError, RuntimeError("aborted"), None)

    def __enter__(self) -> ShardWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    # -- internals --------------------------------------------------------------------------

    def _to_record_batch(self, columns: Mapping[str, np.ndarray]) -> pa.RecordBatch:
        missing = [name for name in COLUMN_NAMES if name not in columns]
        extra = [name for name in columns if name not in COLUMN_NAMES]
        if missing or extra:
            raise ValueError(f"rollout columns: missing {missing}, unexpected {extra}")
        rows = len(columns["episode_id"])
        arrays: list[pa.Array] = []
        for field in self.schema:
            values = columns[field.name]
            if pa.types.is_fixed_size_list(field.type):
                arrays.append(_fixed_list(values, field.type.list_size, field.name, rows))
                continue
            values = np.asarray(values)
            if values.shape != (rows,):
                raise ValueError(
                    f"column {field.name!r} has shape {values.shape}, expected ({rows},)"
                )
            arrays.append(pa.array(values.astype(_NUMPY_DTYPES[field.type], copy=False)))
        return pa.RecordBatch.from_arrays(arrays, schema=self.schema)

    @staticmethod
    def _check_whole_episodes(
        columns: Mapping[str, np.ndarray], starts: np.ndarray, ends: np.ndarray
    ) -> None:
        """Refuse partial episodes: each must start with is_first and end with is_last."""
        episode_id = np.asarray(columns["episode_id"])
        if len(np.unique(episode_id)) != len(starts):
            raise ValueError("rows of an episode must be contiguous within a write() call")
        is_first = np.asarray(columns["is_first"], dtype=bool)
        is_last = np.asarray(columns["is_last"], dtype=bool)
        bad_first = ~is_first[starts]
        bad_last = ~is_last[ends - 1]
        if bad_first.any() or bad_last.any():
            index = int(np.flatnonzero(bad_first | bad_last)[0])
            raise ValueError(
                f"episode {int(episode_id[starts[index]])} is not whole: write() takes complete "
                "episodes (first row is_first, last row is_last)"
            )

    def _append(self, batch: pa.RecordBatch) -> None:
        self._pending.append(batch)
        self._pending_rows += batch.num_rows
        self._rows_in_shard += batch.num_rows
        if self._pending_rows >= self.row_group_rows:
            self._flush()

    def _flush(self) -> None:
        if not self._pending:
            return
        if self._parquet is None:
            final = self.out_dir / shard_name(len(self.paths))
            self._shard_stack = contextlib.ExitStack()
            tmp = self._shard_stack.enter_context(atomic_path(final))
            self._current_path = final
            self._parquet = pq.ParquetWriter(
                tmp,
                self.schema,
                compression=self.compression,
                # Floats barely repeat: dictionary pages only cost time. Integers and flags keep it.
                use_dictionary=["episode_id", "t", "action", "collision"],
            )
        table = pa.Table.from_batches(self._pending, schema=self.schema)
        self._parquet.write_table(table, row_group_size=max(table.num_rows, 1))
        self._pending, self._pending_rows = [], 0

    def _close_shard(self) -> None:
        self._flush()
        if self._parquet is None:
            return
        self._parquet.close()
        self._parquet = None
        assert self._shard_stack is not None and self._current_path is not None
        stack, self._shard_stack = self._shard_stack, None
        stack.close()  # renames the temporary file onto the shard name
        self.paths.append(self._current_path)
        self._rows_in_shard = 0


# -- reading ----------------------------------------------------------------------------------


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0]}" if text else type(exc).__name__


def _read_shard(
    path: Path,
    columns: Sequence[str] | None,
    num_humans: int | None,
    env_params: EnvParams | None = None,
) -> tuple[pa.Table, int]:
    """Read and check one shard (its format, its scenarios against ``env_params``, the values
    read); return (table, num_humans). Raises RolloutError naming it."""
    try:
        parquet = pq.ParquetFile(path)
        schema = parquet.schema_arrow
    except (OSError, pa.ArrowException) as exc:
        raise RolloutError(f"{path}: not a readable Parquet file ({_first_line(exc)})") from exc
    version = schema_version(schema)
    if version is None:
        raise RolloutError(f"{path}: no rollout schema version in the Parquet metadata")
    if version != SCHEMA_VERSION:
        raise RolloutError(
            f"{path}: rollout schema version {version}, this code reads version {SCHEMA_VERSION}"
        )
    file_humans = schema_num_humans(schema)
    if file_humans is None:
        raise RolloutError(f"{path}: no num_humans in the Parquet metadata")
    made = schema_env(schema) or {"num_humans": file_humans}
    check_made_with(path, made, env_params, verb="collected", error=RolloutError)
    if num_humans is not None and file_humans != num_humans:
        raise RolloutError(
            f"{path}: {file_humans} humans, but earlier shards of this dataset have {num_humans}"
        )
    expected = rollout_schema(file_humans)
    wanted = list(columns) if columns is not None else list(COLUMN_NAMES)
    unknown = [name for name in wanted if name not in COLUMN_NAMES]
    if unknown:
        raise RolloutError(f"{path}: unknown rollout columns requested: {', '.join(unknown)}")
    missing = [name for name in wanted if name not in schema.names]
    if missing:
        raise RolloutError(f"{path}: missing columns {', '.join(missing)}")
    for name in wanted:
        found, want = schema.field(name).type, expected.field(name).type
        if found != want:
            raise RolloutError(f"{path}: column {name!r} has type {found}, expected {want}")
    try:
        table = parquet.read(columns=wanted)
    except (OSError, pa.ArrowException) as exc:
        raise RolloutError(f"{path}: corrupt Parquet data ({_first_line(exc)})") from exc
    # One schema for all shards (types + metadata), so concatenation never fails on nullability.
    target = pa.schema([expected.field(name) for name in wanted], metadata=expected.metadata)
    try:
        table = table.cast(target)
    except (pa.ArrowException, ValueError) as exc:
        raise RolloutError(f"{path}: cannot match the rollout schema ({_first_line(exc)})") from exc
    _check_finite(path, table)
    _check_codes(path, table)
    validate_episodes(table, path)
    return table, file_humans


def _check_finite(path: Path, table: pa.Table) -> None:
    """Refuse NaN or infinite values in the :data:`FINITE_COLUMNS` of one shard (vectorised).

    Raises:
        RolloutError: naming the shard, the first offending row (within the shard) and column.
    """
    for name in FINITE_COLUMNS:
        if name not in table.column_names:
            continue
        values = column_to_numpy(table, name)
        finite = np.isfinite(values)
        if finite.all():
            continue
        row, *position = np.argwhere(~finite)[0]
        label = f"{name}[{position[0]}]" if position else name
        value = values[(row, *position)]
        raise RolloutError(f"{path}: row {row}, column {label}: not finite ({value})")


def _check_codes(path: Path, table: pa.Table) -> None:
    """Refuse a value outside its :data:`VALUE_RANGES` (an action 7 or −3) in one shard.

    Raises:
        RolloutError: naming the shard, the first offending row (within the shard), the column
            and the value.
    """
    for name, (low, high) in VALUE_RANGES.items():
        if name not in table.column_names:
            continue
        values = column_to_numpy(table, name)
        bad = (values < low) | (values > high)
        if bad.any():
            row = int(np.flatnonzero(bad)[0])
            value = int(values[row])
            raise RolloutError(
                f"{path}: row {row}, column {name}: {value}, not one of {low}..{high}"
            )


def read_rollouts(
    path_or_dir: str | Path,
    columns: Sequence[str] | None = None,
    env_params: EnvParams | None = None,
) -> pa.Table:
    """Read a shard file, or every ``shard-*.parquet`` of a directory in order, into one table.

    Each shard is checked on what is read, cheaply (vectorised): finite observations and
    rewards, actions and collision codes in range, and its episodes whole and in order as far
    as the columns read tell (:func:`validate_episodes`); no episode may continue in another
    shard.

    Args:
        path_or_dir: a dataset directory or a single shard file.
        columns: column names to read (all by default).
        env_params: the scenarios the rollouts must have been collected in (the number of
            humans and the room size, :func:`socnav_wm.data.compatibility.check_made_with`);
            None: not checked.

    Raises:
        RolloutError: one line naming the file, when the path is missing, the directory holds
            no shards, a file is not readable Parquet (truncated or corrupt), its schema version
            is not ``SCHEMA_VERSION``, columns are missing, shards disagree on ``num_humans``,
            a shard was collected in other scenarios than ``env_params``, a value of a
            :data:`FINITE_COLUMNS` column is NaN or infinite, a code is out of range, or an
            episode is broken.
    """
    path = Path(path_or_dir)
    if not path.exists():
        raise RolloutError(f"{path}: no such file or directory")
    if path.is_dir():
        files = list_shards(path)
        if not files:
            raise RolloutError(f"{path}: no {SHARD_GLOB} files in this directory")
    else:
        files = [path]
    tables: list[pa.Table] = []
    num_humans: int | None = None
    seen = np.zeros(0, dtype=np.int64)  # the episode ids of the shards before, when read
    owner = np.zeros(0, dtype=np.int64)  # the index in ``files`` of the shard of each
    for index, file in enumerate(files):
        table, num_humans = _read_shard(file, columns, num_humans, env_params)
        if "episode_id" in table.column_names:
            ids = np.unique(column_to_numpy(table, "episode_id"))
            shared, _, where = np.intersect1d(ids, seen, return_indices=True)
            if shared.size:
                raise RolloutError(
                    f"{file}: episode {int(shared[0])} is also in {files[owner[where[0]]]} "
                    "(an episode's rows must be contiguous, in one shard)"
                )
            seen = np.concatenate([seen, ids])
            owner = np.concatenate([owner, np.full(ids.size, index)])
        tables.append(table)
    return pa.concat_tables(tables) if len(tables) > 1 else tables[0]


def column_to_numpy(table: pa.Table, name: str) -> np.ndarray:
    """One column as numpy: shape (n,) for scalars, (n, width) for fixed-size list columns."""
    column = table.column(name)
    if pa.types.is_fixed_size_list(column.type):
        width = column.type.list_size
        if column.num_chunks == 0:
            return np.zeros((0, width), dtype=np.float32)
        # flatten() honours slice offsets, unlike .values.
        parts = [chunk.flatten().to_numpy(zero_copy_only=False) for chunk in column.chunks]
        return np.concatenate(parts).reshape(-1, width)
    return column.to_numpy()


def validate_episodes(table: pa.Table, path: str | Path | None = None) -> None:
    """Check episode boundaries and continuity of a rollout table (vectorised), as far as its
    columns tell (:func:`read_rollouts` checks every shard on the columns it reads).

    Checks, for every episode: its rows are contiguous (``episode_id``); ``t`` runs 0..n−1;
    exactly one ``is_first`` (on t == 0) and one ``is_last`` (on the final row); ``next_obs`` of
    step t equals ``obs`` of step t+1 exactly (the collector stores the same float32 values
    twice). Without ``episode_id`` nothing is checked.

    Raises:
        RolloutError: naming ``path`` (when given) and the first offending episode.
    """
    names = set(table.column_names)
    if "episode_id" not in names:
        return
    episode_id = column_to_numpy(table, "episode_id")
    rows = len(episode_id)
    if rows == 0:
        return
    starts = _episode_starts(episode_id)
    lengths = np.diff(np.append(starts, rows))
    run_of_row = np.repeat(np.arange(len(starts)), lengths)
    where = f"{path}: " if path is not None else ""

    def fail(row_mask: np.ndarray, problem: str) -> None:
        if row_mask.any():
            row = int(np.flatnonzero(row_mask)[0])
            raise RolloutError(f"{where}episode {int(episode_id[row])}: {problem}")

    ids, first_run = np.unique(episode_id[starts], return_index=True)
    if len(ids) != len(starts):
        repeated = np.ones(len(starts), dtype=bool)
        repeated[first_run] = False
        fail(np.repeat(repeated, lengths), "rows are not contiguous (the id appears twice)")

    step_in_episode = np.arange(rows) - starts[run_of_row]
    if "t" in names:
        t = column_to_numpy(table, "t").astype(np.int64)
        fail(t != step_in_episode, "t does not run 0..n-1")
    if "is_first" in names:
        is_first = column_to_numpy(table, "is_first").astype(bool)
        fail(is_first != (step_in_episode == 0), "is_first is not set exactly on t == 0")
    is_final_row = np.zeros(rows, dtype=bool)
    is_final_row[starts + lengths - 1] = True
    if "is_last" in names:
        is_last = column_to_numpy(table, "is_last").astype(bool)
        fail(is_last != is_final_row, "is_last is not set exactly on the final row")

    if {"obs", "next_obs"} <= names:
        obs = column_to_numpy(table, "obs")
        next_obs = column_to_numpy(table, "next_obs")
        broken = np.zeros(rows, dtype=bool)
        # Row i must hand over to row i+1 unless row i ends its episode.
        broken[:-1] = np.any(next_obs[:-1] != obs[1:], axis=1) & ~is_final_row[:-1]
        fail(broken, "next_obs of a step differs from obs of the following step")
