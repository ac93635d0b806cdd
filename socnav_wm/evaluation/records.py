"""The evaluation's records: its two Parquet tables, their files' run metadata, and the
aggregation of the episodes table.

* **episodes** — one row per (training seed, scenario): the key columns, the outcome, and every
  metric of :mod:`socnav_wm.metrics` (paper definitions, world frame);
* **trajectories** — one row per recorded state ``t = 0..T`` of every episode: robot pose, goal,
  every human's position and heading, and the step that led to the state (action, executed
  command, reward, ``dmin``; null at ``t = 0``), with the outcome on the last row. Any metric
  can be recomputed from it (:func:`recompute_metrics`) and any episode redrawn
  (:func:`episode_from_trajectories`).

Both Parquet files carry the run's identity (method, scenario seed, scenario parameters,
training seeds) in their schema metadata (:func:`evaluation_metadata`), so the report can refuse
to pair runs made on different scenarios. :mod:`socnav_wm.evaluation.evaluate` runs a method and
writes them.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from socnav_wm.env.episode import Episode
from socnav_wm.env.params import EnvParams
from socnav_wm.evaluation.intervals import mean_ci_crossed
from socnav_wm.io import check_format
from socnav_wm.metrics import (
    ALL_METRICS,
    PAPER_METRICS,
    MetricParams,
    Trajectory,
    episode_metrics,
)

__all__ = [
    "BASELINE_SEED",
    "EPISODE_KEY_COLUMNS",
    "OUTCOMES",
    "episode_from_trajectories",
    "episodes_table",
    "evaluation_metadata",
    "metric_params",
    "per_seed_means",
    "read_evaluation",
    "recompute_metrics",
    "summarise",
    "trajectories_table",
    "trajectory_from_episode",
    "with_metadata",
]

BASELINE_SEED = -1
"""``training_seed`` of a baseline's (or a planner's) rows: it has no training seed (it is not
trained)."""

EPISODE_KEY_COLUMNS: tuple[str, ...] = ("method", "training_seed", "scenario_id")
"""Columns identifying an episode, in both tables."""

OUTCOMES: tuple[str, ...] = (
    "success",
    "human_collision",
    "wall_collision",
    "obstacle_collision",
    "timeout",
)
"""Values of the ``outcome`` column: how an episode ended (exactly one of them)."""

METADATA_KEY = b"socnav-wm"
"""Schema-metadata key of the run's identity (JSON) in both Parquet files."""

EVAL_FORMAT = "socnav-wm-eval"
EVAL_FORMAT_VERSION = 1


# --------------------------------------------------------------------------------------------
# Episodes → metrics and tables
# --------------------------------------------------------------------------------------------


def metric_params(env_params: EnvParams) -> MetricParams:
    """The metric constants of these scenario parameters (dt, radii, discomfort, goal).

    The personal space (0.5 m), idle threshold (0.05 m per step) and the code's 2.02 m radius
    are the paper's and stay at their defaults.
    """
    return MetricParams(
        dt=env_params.dt,
        robot_radius=env_params.robot_radius,
        human_radius=env_params.human_radius,
        discomfort_distance=env_params.discomfort_distance,
        goal_threshold=env_params.success_distance,
    )


def _outcome(episode: Episode) -> str:
    if episode.success:
        return "success"
    if episode.collision is not None:
        return f"{episode.collision}_collision"
    return "timeout"


def trajectory_from_episode(episode: Episode) -> Trajectory:
    """The metrics' view of a recorded episode (validated on construction)."""
    return Trajectory(
        robot_xy=episode.robot_xy,
        human_xy=episode.human_xy,
        goal_xy=episode.goal_xy,
        dmin=episode.dmin,
        rewards=episode.rewards,
        success=episode.success,
        collision=episode.collision,
        truncated=episode.truncated,
        human_group=episode.human_group,
    )


def episodes_table(
    method: str, training_seed: int, episodes: Sequence[Episode], env_params: EnvParams
) -> pa.Table:
    """One row per episode: key columns, ``outcome``, ``num_steps`` and every metric.

    Columns: ``method`` (string), ``training_seed`` (int64), ``scenario_id`` (int64),
    ``outcome`` (one of :data:`OUTCOMES`), ``num_steps`` (int64, T), then the metrics of
    :data:`socnav_wm.metrics.ALL_METRICS` as float64 (units in ``METRIC_UNITS``; 0/1 for the
    binary ones, NaN for ``time_to_reach_goal`` of a failure).
    """
    params = metric_params(env_params)
    values = [episode_metrics(trajectory_from_episode(e), params) for e in episodes]
    n = len(episodes)
    columns: dict[str, pa.Array] = {
        "method": pa.array([method] * n, pa.string()),
        "training_seed": pa.array(np.full(n, training_seed, dtype=np.int64)),
        "scenario_id": pa.array(np.array([e.scenario_id for e in episodes], dtype=np.int64)),
        "outcome": pa.array([_outcome(e) for e in episodes], pa.string()),
        "num_steps": pa.array(np.array([e.num_steps for e in episodes], dtype=np.int64)),
    }
    for metric in ALL_METRICS:
        columns[metric] = pa.array(np.array([v[metric] for v in values], dtype=np.float64))
    return pa.table(columns)


def _fixed_list(values: np.ndarray) -> pa.Array:
    """A (rows, d1, d2, …) float array as nested Arrow fixed-size lists, without a row loop."""
    flat: pa.Array = pa.array(np.ascontiguousarray(values, dtype=np.float64).reshape(-1))
    for size in reversed(values.shape[1:]):
        flat = pa.FixedSizeListArray.from_arrays(flat, size)
    return flat


def trajectories_table(
    method: str, training_seed: int, episodes: Sequence[Episode], num_humans: int
) -> pa.Table:
    """One row per recorded state of every episode (``T + 1`` rows for a ``T``-step episode).

    Columns (world frame; metres, radians, seconds):

    * ``method``, ``training_seed``, ``scenario_id``, ``t`` (int64: 0 = after reset, t = after
      step t);
    * ``robot_x``, ``robot_y``, ``robot_theta``, ``goal_x``, ``goal_y`` (float64);
    * ``human_xy``: fixed-size list of ``H`` fixed-size lists ``[x, y]`` (float64);
      ``human_theta``: fixed-size list of ``H`` headings (float64); ``human_group``: fixed-size
      list of ``H`` group numbers (−1: alone; float64 holding integers), the episode's;
    * the step that led to state ``t`` (null at ``t = 0``): ``action`` (int8: the discrete
      action 0–3 of an agent; −1 for a baseline, which sends continuous commands), ``v`` and
      ``omega`` (float64, the command the robot executed, m/s and rad/s), ``reward`` (float64)
      and ``dmin`` (float64, m);
    * ``outcome``: one of :data:`OUTCOMES` on the episode's last row, null before.
    """
    rows = sum(e.num_steps + 1 for e in episodes)
    h = num_humans
    scenario = np.empty(rows, dtype=np.int64)
    t = np.empty(rows, dtype=np.int64)
    robot = np.empty((rows, 3))
    goal = np.empty((rows, 2))
    human_xy = np.empty((rows, h, 2))
    human_theta = np.empty((rows, h))
    human_group = np.full((rows, h), -1, dtype=np.int64)
    action = np.full(rows, -1, dtype=np.int8)
    command = np.zeros((rows, 2))
    reward = np.zeros(rows)
    dmin = np.zeros(rows)
    first = np.zeros(rows, dtype=bool)
    outcome: list[str | None] = [None] * rows
    row = 0
    for e in episodes:
        n = e.num_steps + 1
        if e.human_xy.shape[1] != h:
            raise ValueError(f"episode has {e.human_xy.shape[1]} humans, expected {h}")
        block = slice(row, row + n)
        steps = slice(row + 1, row + n)
        scenario[block] = e.scenario_id
        t[block] = np.arange(n)
        robot[block, :2] = e.robot_xy
        robot[block, 2] = e.robot_theta
        goal[block] = e.goal_xy
        human_xy[block] = e.human_xy
        human_theta[block] = e.human_theta
        if e.human_group is not None:
            human_group[block] = e.human_group
        actions = np.asarray(e.actions)
        if actions.ndim == 1:  # discrete actions of an agent
            action[steps] = actions
        if e.commands is not None:
            command[steps] = e.commands
        elif actions.ndim == 2:
            command[steps] = actions
        else:
            raise ValueError("a discrete-action episode needs its executed commands recorded")
        reward[steps] = e.rewards
        dmin[steps] = e.dmin
        first[row] = True
        outcome[row + n - 1] = _outcome(e)
        row += n

    def with_nulls(values: np.ndarray) -> pa.Array:
        return pa.array(values, mask=first)

    return pa.table(
        {
            "method": pa.array([method] * rows, pa.string()),
            "training_seed": pa.array(np.full(rows, training_seed, dtype=np.int64)),
            "scenario_id": pa.array(scenario),
            "t": pa.array(t),
            "robot_x": pa.array(robot[:, 0]),
            "robot_y": pa.array(robot[:, 1]),
            "robot_theta": pa.array(robot[:, 2]),
            "goal_x": pa.array(goal[:, 0]),
            "goal_y": pa.array(goal[:, 1]),
            "human_xy": _fixed_list(human_xy),
            "human_theta": _fixed_list(human_theta),
            "human_group": _fixed_list(human_group),
            "action": with_nulls(action),
            "v": with_nulls(command[:, 0]),
            "omega": with_nulls(command[:, 1]),
            "reward": with_nulls(reward),
            "dmin": with_nulls(dmin),
            "outcome": pa.array(outcome, pa.string()),
        }
    )


def _select(table: pa.Table, method: str, training_seed: int, scenario_id: int) -> pa.Table:
    mask = pc.and_(
        pc.and_(pc.equal(table["method"], method), pc.equal(table["training_seed"], training_seed)),
        pc.equal(table["scenario_id"], scenario_id),
    )
    return table.filter(mask)


def _fixed_list_numpy(column: pa.ChunkedArray, shape: tuple[int, ...]) -> np.ndarray:
    """A (nested) fixed-size list column as a (rows, *shape) float64 array."""
    array = column.combine_chunks()
    while pa.types.is_fixed_size_list(array.type):
        array = array.flatten()  # respects slices, unlike .values
    return array.to_numpy(zero_copy_only=False).astype(np.float64).reshape(-1, *shape)


def episode_from_trajectories(
    table: pa.Table, method: str, training_seed: int, scenario_id: int
) -> Episode:
    """Rebuild one recorded episode from a trajectories table (see :func:`trajectories_table`).

    ``actions`` is the discrete action per step (T,) for an agent, the executed commands
    (T, 2) for a baseline.

    Raises:
        KeyError: no such episode in the table.
        ValueError: the rows do not form one complete episode (t = 0..T, outcome on the last).
    """
    rows = _select(table, method, training_seed, scenario_id)
    if rows.num_rows == 0:
        raise KeyError(f"no trajectory of {method!r}, seed {training_seed}, scenario {scenario_id}")
    rows = rows.sort_by("t")
    t = rows["t"].to_numpy()
    if not np.array_equal(t, np.arange(rows.num_rows)):
        raise ValueError(
            f"trajectory of {method!r}, seed {training_seed}, scenario {scenario_id}: "
            f"steps are not 0..{rows.num_rows - 1} (duplicated or missing rows)"
        )
    if rows.num_rows < 2:
        raise ValueError(f"trajectory of {method!r}, scenario {scenario_id} has no step")
    outcome = rows["outcome"].to_pylist()
    if outcome[-1] not in OUTCOMES or any(o is not None for o in outcome[:-1]):
        raise ValueError(
            f"trajectory of {method!r}, seed {training_seed}, scenario {scenario_id}: "
            "the outcome must be on the last row only"
        )
    num_humans = rows.schema.field("human_theta").type.list_size
    steps = rows.slice(1)

    def floats(name: str, source: pa.Table = rows) -> np.ndarray:
        return source[name].to_numpy().astype(np.float64)

    action = steps["action"].to_numpy()
    commands = np.stack([floats("v", steps), floats("omega", steps)], axis=-1)
    end = outcome[-1]
    return Episode(
        scenario_id=int(scenario_id),
        robot_xy=np.stack([floats("robot_x"), floats("robot_y")], axis=-1),
        robot_theta=floats("robot_theta"),
        goal_xy=np.array([floats("goal_x")[0], floats("goal_y")[0]]),
        human_xy=_fixed_list_numpy(rows["human_xy"], (num_humans, 2)),
        human_theta=_fixed_list_numpy(rows["human_theta"], (num_humans,)),
        actions=commands.copy() if np.all(action < 0) else action.astype(np.int64),
        rewards=floats("reward", steps),
        dmin=floats("dmin", steps),
        success=end == "success",
        collision=end.removesuffix("_collision") if end.endswith("_collision") else None,
        truncated=end == "timeout",
        commands=commands,
        human_group=(
            _fixed_list_numpy(rows["human_group"], (num_humans,))[0].astype(np.int64)
            if "human_group" in rows.column_names
            else None
        ),
    )


def recompute_metrics(
    trajectories: pa.Table,
    method: str,
    training_seed: int,
    scenario_id: int,
    env_params: EnvParams,
) -> dict[str, float]:
    """Every metric of one episode, recomputed from its trajectory rows alone.

    Equal to that episode's row of the episodes table: the trajectories are complete.
    """
    episode = episode_from_trajectories(trajectories, method, training_seed, scenario_id)
    return episode_metrics(trajectory_from_episode(episode), metric_params(env_params))


# --------------------------------------------------------------------------------------------
# Aggregation
# --------------------------------------------------------------------------------------------


def summarise(
    table: pa.Table,
    metrics: Sequence[str] = ALL_METRICS,
    confidence: float = 0.95,
) -> dict[str, dict[str, float]]:
    """Mean and confidence interval of each metric over scenarios × training seeds.

    The interval is :func:`~socnav_wm.evaluation.stats.mean_ci_crossed`, a two-way bootstrap
    that resamples training seeds and scenarios independently (with one seed, a baseline's
    ``−1``, it is the bootstrap over scenarios). NaN values (``time_to_reach_goal`` of failed
    episodes) are left out and ``n`` counts the values used.

    Args:
        table: an episodes table of one method (see :func:`episodes_table`).
        metrics: which metric columns to summarise.
        confidence: coverage of the intervals.

    Returns:
        ``{metric: {"mean", "low", "high", "n"}}`` (NaN where undefined, e.g. ``n = 0``).
    """
    methods = set(table["method"].to_pylist())
    if len(methods) > 1:
        raise ValueError(f"summarise: one method at a time, got {sorted(methods)}")
    scenarios = table["scenario_id"].to_numpy()
    seeds = table["training_seed"].to_numpy()
    summary = {}
    for metric in metrics:
        values = table[metric].to_numpy().astype(np.float64)
        ci = mean_ci_crossed(values, scenarios, seeds, confidence)
        summary[metric] = {"mean": ci.mean, "low": ci.low, "high": ci.high, "n": ci.n}
    return summary


def per_seed_means(
    table: pa.Table, metrics: Sequence[str] = PAPER_METRICS
) -> dict[int, dict[str, float]]:
    """``{training seed: {metric: mean over its scenarios}}`` (NaN values left out)."""
    seeds = table["training_seed"].to_numpy()
    result: dict[int, dict[str, float]] = {}
    for seed in sorted(set(seeds.tolist())):
        rows = seeds == seed
        result[int(seed)] = {}
        for metric in metrics:
            values = table[metric].to_numpy().astype(np.float64)[rows]
            values = values[~np.isnan(values)]
            result[int(seed)][metric] = float(values.mean()) if values.size else math.nan
    return result


# --------------------------------------------------------------------------------------------
# Files
# --------------------------------------------------------------------------------------------


def with_metadata(table: pa.Table, metadata: Mapping[str, Any]) -> pa.Table:
    return table.replace_schema_metadata({METADATA_KEY: json.dumps(metadata, sort_keys=True)})


def evaluation_metadata(path: str | Path) -> dict[str, Any]:
    """The run identity stored in an evaluation Parquet file (see :func:`write_evaluation`)."""
    schema = pq.read_schema(path)
    raw = (schema.metadata or {}).get(METADATA_KEY)
    if raw is None:
        raise ValueError(f"{path}: not a socnav-wm evaluation file (no run metadata)")
    metadata = json.loads(raw)
    check_format(metadata, path, "evaluation file", EVAL_FORMAT, EVAL_FORMAT_VERSION)
    return metadata


def read_evaluation(path: str | Path) -> tuple[pa.Table, dict[str, Any]]:
    """An evaluation Parquet file (episodes or trajectories) and its run metadata."""
    metadata = evaluation_metadata(path)
    return pq.read_table(path), metadata
