"""Paired evaluation of every method on the same test scenarios, recorded step by step.

Every method runs scenarios ``0..episodes−1`` of one scenario seed (the simulator makes scenario
``i`` of a seed a pure function of ``(seed, i)``, whatever else runs in the batch), so methods can
be compared scenario by scenario. A learned method is evaluated once per training seed (one agent
file each), greedily; a baseline or a planner is deterministic and runs once, recorded with
training seed :data:`~socnav_wm.evaluation.records.BASELINE_SEED` (−1). Every method's policy
comes from the registry, :mod:`socnav_wm.methods`.

:func:`evaluate_method` records two tables, episodes and trajectories
(:mod:`socnav_wm.evaluation.records` defines them, their files' run metadata and their
aggregation); :func:`write_evaluation` writes them with the metrics JSON.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from socnav_wm.env.episode import Episode
from socnav_wm.env.params import EnvParams
from socnav_wm.env.rollout import run_episodes
from socnav_wm.evaluation.records import (
    BASELINE_SEED,
    EVAL_FORMAT,
    EVAL_FORMAT_VERSION,
    episodes_table,
    per_seed_means,
    summarise,
    trajectories_table,
    with_metadata,
)
from socnav_wm.io import atomic_path, write_json_atomic
from socnav_wm.methods import PolicyFactory, method
from socnav_wm.metrics import ALL_METRICS, METRIC_UNITS
from socnav_wm.planning.params import PlanningParams
from socnav_wm.progress import progress

__all__ = ["EvaluationResult", "evaluate_method", "evaluation_metrics", "write_evaluation"]

_KIND_WORDS = {"agent": "agent", "robot": "baseline", "planner": "planner"}
"""How the errors name each kind of method."""


@dataclass(frozen=True)
class EvaluationResult:
    """One method evaluated on scenarios ``0..num_scenarios−1`` of ``scenario_seed``.

    Attributes:
        method: one of :data:`~socnav_wm.method_names.METHOD_NAMES`.
        scenario_seed: the test scenarios' seed.
        num_scenarios: scenarios per training seed.
        env_params: the scenario parameters.
        training_seeds: the evaluated agents' seeds, ascending; ``(BASELINE_SEED,)`` for a
            baseline.
        episodes: one row per (training seed, scenario) (see :func:`episodes_table`).
        trajectories: one row per state (see :func:`trajectories_table`).
        wall_time: seconds the evaluation took.
        settings: what else identifies the run (baseline parameters, agent files).
    """

    method: str
    scenario_seed: int
    num_scenarios: int
    env_params: EnvParams
    training_seeds: tuple[int, ...]
    episodes: pa.Table
    trajectories: pa.Table
    wall_time: float
    settings: dict[str, Any]

    def summary(self, metrics: Sequence[str] = ALL_METRICS) -> dict[str, dict[str, float]]:
        """:func:`summarise` of the episodes table."""
        return summarise(self.episodes, metrics)

    def metadata(self) -> dict[str, Any]:
        """The run's identity, stored in both Parquet files (see :func:`evaluation_metadata`)."""
        return {
            "format": EVAL_FORMAT,
            "format_version": EVAL_FORMAT_VERSION,
            "method": self.method,
            "scenario_seed": self.scenario_seed,
            "num_scenarios": self.num_scenarios,
            "training_seeds": list(self.training_seeds),
            "env_params": self.env_params.to_dict(),
            "settings": self.settings,
        }


def _chunks(ids: np.ndarray, size: int) -> list[np.ndarray]:
    return [ids[start : start + size] for start in range(0, ids.size, size)]


def evaluate_method(
    name: str,
    *,
    env_params: EnvParams,
    scenario_seed: int,
    episodes: int,
    agent_paths: Mapping[int, str | Path] | None = None,
    baseline_overrides: Mapping[str, Any] | None = None,
    planning: PlanningParams | None = None,
    planner_files: Mapping[str, str | Path] | None = None,
    device: str | None = None,
    batch_size: int = 500,
    quiet: bool = True,
    transfer: bool = False,
) -> EvaluationResult:
    """Run method ``name`` on scenarios ``0..episodes−1`` of ``scenario_seed``, record everything.

    Args:
        name: one of :data:`~socnav_wm.method_names.METHOD_NAMES`.
        env_params: the test scenarios' parameters (the same for every method).
        scenario_seed: the test scenarios' seed (the same for every method).
        episodes: number of test scenarios (the paper: 500).
        agent_paths: for an agent method, ``{training seed: agent file}``; every entry is
            evaluated (greedy, ε = 0). Ignored (must be empty) for a baseline.
        baseline_overrides: for a baseline, parameters replacing its defaults
            (``params.yaml``'s ``baselines.<name>``). Must be empty for an agent.
        planning: for a planner, its parameters (``params.yaml``'s ``planning``). Must be None
            for another method.
        planner_files: for a planner, its model files by role, replacing the pipeline's
            (:attr:`socnav_wm.methods.Method.model_files`).
        device: for an agent, where its network runs (``cpu``, ``cuda``, ``auto``:
            ``params.yaml``'s ``eval.device``); unused by another method.
        batch_size: scenarios simulated together (all of a seed's scenarios in one batch by
            default); the results do not depend on it.
        quiet: no progress bar.
        transfer: use model files trained in another world (a transfer evaluation, recorded
            in the settings); without it they are refused in one line.

    Returns:
        An :class:`EvaluationResult` (write it with :func:`write_evaluation`).

    Raises:
        ValueError: unknown method, missing or extra agent files, an agent of another variant
            or trained on another number of humans, bad counts (one line naming it).
    """
    entry = method(name)
    if isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1:
        raise ValueError(f"episodes: expected a positive integer, got {episodes!r}")
    if isinstance(batch_size, bool) or not isinstance(batch_size, int) or batch_size < 1:
        raise ValueError(f"batch_size: expected a positive integer, got {batch_size!r}")
    if (planning is not None or planner_files) and entry.kind != "planner":
        raise ValueError(f"method {name!r} is not a planner: planning parameters do not apply")
    if entry.kind != "agent" and (agent_paths or (baseline_overrides and entry.kind != "robot")):
        raise ValueError(f"method {name!r} is a {_KIND_WORDS[entry.kind]}: it takes no agent files")
    if entry.kind == "agent" and baseline_overrides:
        raise ValueError(f"method {name!r} is an agent: baseline parameters do not apply")
    if entry.kind == "agent" and not agent_paths:
        raise ValueError(f"method {name!r} needs agent files (training seed → path)")
    ids = np.arange(episodes, dtype=np.int64)
    start = time.perf_counter()
    settings: dict[str, Any] = {"transfer": True} if transfer else {}
    runs: dict[int, PolicyFactory] = {}  # training seed → its policies
    if entry.kind == "planner":
        if planning is None:
            raise ValueError(f"method {name!r} is a planner: it needs the planning parameters")
        files = entry.files(planner_files)
        settings["planning"] = planning.to_dict()
        settings["model_files"] = {role: str(path) for role, path in files.items()}
        runs[BASELINE_SEED] = entry.policies(
            env_params, files=files, planning=planning, transfer=transfer
        )
    elif entry.kind == "robot":
        overrides = dict(baseline_overrides or {})
        settings["baseline_overrides"] = overrides
        runs[BASELINE_SEED] = entry.policies(env_params, baseline=overrides, transfer=transfer)
    else:
        assert agent_paths is not None
        seeds = sorted(int(s) for s in agent_paths)
        settings["agent_files"] = {str(s): str(agent_paths[s]) for s in seeds}
        for seed in seeds:  # each agent is loaded when its seed's turn comes
            runs[seed] = functools.partial(
                entry.policies,
                env_params,
                files={"agent": Path(agent_paths[seed])},
                device=device,
                transfer=transfer,
            )
    episode_tables: list[pa.Table] = []
    trajectory_tables: list[pa.Table] = []
    total = episodes * len(runs)
    with progress(total, f"evaluate {name}", quiet=quiet, unit="episodes") as bar:
        for seed, policies in runs.items():
            if entry.kind == "agent":
                policies = policies()
            recorded: list[Episode] = []
            for chunk in _chunks(ids, batch_size):
                policy, reads_simulator = policies()
                recorded += run_episodes(
                    env_params, policy, scenario_seed, chunk, reads_simulator=reads_simulator
                )
                bar.advance(chunk.size)
            episode_tables.append(episodes_table(name, seed, recorded, env_params))
            trajectory_tables.append(
                trajectories_table(name, seed, recorded, env_params.num_humans)
            )

    return EvaluationResult(
        method=name,
        scenario_seed=int(scenario_seed),
        num_scenarios=episodes,
        env_params=env_params,
        training_seeds=tuple(runs),
        episodes=pa.concat_tables(episode_tables),
        trajectories=pa.concat_tables(trajectory_tables),
        wall_time=time.perf_counter() - start,
        settings=settings,
    )


# --------------------------------------------------------------------------------------------
# Files
# --------------------------------------------------------------------------------------------


def evaluation_metrics(result: EvaluationResult) -> dict[str, Any]:
    """The content of ``metrics/eval/{method}.json``.

    ``{"method", "scenario_seed", "episodes" (scenarios per seed), "training_seeds",
    "wall_time_s", "metrics": {metric: {"mean", "low", "high", "n"}}, "units",
    "per_seed": {"seed-<s>": {metric: mean}} (agents only)}``.
    """
    content: dict[str, Any] = {
        "method": result.method,
        "scenario_seed": result.scenario_seed,
        "episodes": result.num_scenarios,
        "training_seeds": list(result.training_seeds),
        "wall_time_s": result.wall_time,
        "metrics": result.summary(),
        "units": {metric: METRIC_UNITS[metric] for metric in ALL_METRICS},
    }
    if method(result.method).kind == "agent":
        content["per_seed"] = {
            f"seed-{seed}": means for seed, means in per_seed_means(result.episodes).items()
        }
    return content


def write_evaluation(
    result: EvaluationResult,
    episodes_path: str | Path,
    trajectories_path: str | Path,
    metrics_path: str | Path,
) -> None:
    """Write ``data/eval/{method}.parquet``, ``…-trajectories.parquet`` and the metrics JSON.

    Each file is written atomically (temporary file + rename); both Parquet files are
    zstd-compressed and carry :meth:`EvaluationResult.metadata` in their schema metadata.
    """
    metadata = result.metadata()
    for table, path in ((result.episodes, episodes_path), (result.trajectories, trajectories_path)):
        with atomic_path(path) as tmp:
            pq.write_table(with_metadata(table, metadata), tmp, compression="zstd")
    write_json_atomic(metrics_path, evaluation_metrics(result))
