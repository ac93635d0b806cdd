"""The evaluation's results read back: each method's evaluation files, and the agents' training
logs (what the report, its comparisons, claims and text are made of).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from socnav_wm.env.params import EnvParams
from socnav_wm.evaluation.records import evaluation_metadata
from socnav_wm.method_names import METHOD_NAMES, VARIANT_NAMES
from socnav_wm.metrics import episodes_to_solve

__all__ = [
    "MethodEvaluation",
    "load_evaluations",
    "load_training_returns",
    "smooth",
    "training_summary",
]


@dataclass(frozen=True)
class MethodEvaluation:
    """One method's evaluation files, read back.

    Attributes:
        method: the method's name.
        episodes: its episodes table (one row per training seed × scenario).
        metadata: the run identity stored in the file (scenario seed, env params, seeds).
        trajectories_path: its trajectories file, None when it is missing.
    """

    method: str
    episodes: pa.Table
    metadata: dict[str, Any]
    trajectories_path: Path | None

    @property
    def training_seeds(self) -> list[int]:
        return sorted(set(self.episodes["training_seed"].to_pylist()))

    @property
    def is_agent(self) -> bool:
        return self.method in VARIANT_NAMES


def load_evaluations(
    eval_dir: str | Path,
    methods: Sequence[str] = METHOD_NAMES,
    *,
    scenario_seed: int | None = None,
    env_params: EnvParams | None = None,
) -> tuple[dict[str, MethodEvaluation], list[str]]:
    """The evaluation files of ``methods`` found in ``eval_dir``, and the methods without one.

    Paired comparisons need every method to have run the same scenarios, so all files must
    share one scenario seed, number of scenarios and scenario parameters (and match
    ``scenario_seed`` / ``env_params`` when given).

    Raises:
        ValueError: files made on different scenarios, or not evaluation files.
    """
    eval_dir = Path(eval_dir)
    found: dict[str, MethodEvaluation] = {}
    absent: list[str] = []
    reference: tuple[str, dict[str, Any]] | None = None
    for method in methods:
        path = eval_dir / f"{method}.parquet"
        if not path.is_file():
            absent.append(method)
            continue
        metadata = evaluation_metadata(path)
        identity = {
            "scenario_seed": metadata["scenario_seed"],
            "num_scenarios": metadata["num_scenarios"],
            "env_params": metadata["env_params"],
        }
        expected = {}
        if scenario_seed is not None:
            expected["scenario_seed"] = int(scenario_seed)
        if env_params is not None:
            expected["env_params"] = env_params.to_dict()
        for key, value in expected.items():
            if identity[key] != value:
                raise ValueError(
                    f"{path}: evaluated with another {key} than the report's; "
                    "re-run `socnav-wm evaluate`"
                )
        if reference is None:
            reference = (method, identity)
        elif identity != reference[1]:
            differing = sorted(k for k in identity if identity[k] != reference[1][k])
            raise ValueError(
                f"{path}: evaluated on other scenarios than {reference[0]} "
                f"({', '.join(differing)} differ); re-run `socnav-wm evaluate` for both"
            )
        trajectories = eval_dir / f"{method}-trajectories.parquet"
        found[method] = MethodEvaluation(
            method=method,
            episodes=pq.read_table(path),
            metadata=metadata,
            trajectories_path=trajectories if trajectories.is_file() else None,
        )
    return found, absent


def load_training_returns(
    training_dir: str | Path, variants: Sequence[str] = VARIANT_NAMES
) -> dict[str, dict[int, pa.Table]]:
    """Training logs ``{variant: {seed: table}}`` from ``{training_dir}/{variant}/seed-*.parquet``.

    Each table has (at least) ``return`` and ``success`` columns, one row per episode, sorted
    by the ``episode`` column when there is one. Variants without logs are left out.
    """
    training_dir = Path(training_dir)
    logs: dict[str, dict[int, pa.Table]] = {}
    for variant in variants:
        folder = training_dir / variant
        if not folder.is_dir():
            continue
        for path in sorted(folder.glob("seed-*.parquet")):
            try:
                seed = int(path.stem.removeprefix("seed-"))
            except ValueError:
                continue
            table = pq.read_table(path)
            if "episode" in table.column_names:
                table = table.sort_by("episode")
            logs.setdefault(variant, {})[seed] = table
    return logs


def smooth(values: np.ndarray | Sequence[float], window: int) -> np.ndarray:
    """Trailing rolling mean: entry ``i`` is the mean of ``values[max(0, i − window + 1) : i + 1]``.

    The first ``window − 1`` entries average the episodes so far, so the curve starts at the
    first episode, and the last entry is the mean of the final ``window`` episodes (the
    plateau the report quotes).

    Args:
        values: (E,) one value per episode, in episode order.
        window: episodes averaged (≥ 1).

    Returns:
        (E,) float64.
    """
    if isinstance(window, bool) or not isinstance(window, int | np.integer) or window < 1:
        raise ValueError(f"window: expected a positive integer, got {window!r}")
    x = np.asarray(values, dtype=np.float64)
    cumulative = np.concatenate([[0.0], np.cumsum(x)])
    end = np.arange(1, x.size + 1)
    begin = np.maximum(0, end - window)
    return (cumulative[end] - cumulative[begin]) / (end - begin)


# --------------------------------------------------------------------------------------------
# Training logs
# --------------------------------------------------------------------------------------------


def training_summary(
    logs: Mapping[str, Mapping[int, pa.Table]],
    *,
    window: int,
    solved_window: int,
    solved_success_rate: float,
) -> dict[str, dict[str, Any]]:
    """Per variant and seed: episodes, final smoothed return, episodes to solve.

    The final smoothed return ("plateau") is the mean return of the last ``window`` episodes
    (the last point of the Fig. 6 curve). Episodes to solve is the project's definition
    (:func:`socnav_wm.metrics.episodes_to_solve`: first episode at which the success rate of the
    last ``solved_window`` episodes reaches ``solved_success_rate``: ``agent.solved_window`` and
    ``agent.solved_success_rate``), None when never reached. ``window`` is
    ``report.smoothing_window``.

    Returns:
        ``{variant: {"seeds": [...], "episodes": {seed: E}, "plateau": {seed: value},
        "episodes_to_solve": {seed: int | None}}}``.
    """
    if not logs:
        return {}
    summary: dict[str, dict[str, Any]] = {}
    for variant, seeds in logs.items():
        entry: dict[str, Any] = {"seeds": sorted(seeds), "episodes": {}, "plateau": {}}
        entry["episodes_to_solve"] = {}
        for seed in sorted(seeds):
            table = seeds[seed]
            returns = table["return"].to_numpy().astype(np.float64)
            entry["episodes"][seed] = int(returns.size)
            entry["plateau"][seed] = float(smooth(returns, window)[-1]) if returns.size else None
            if "success" in table.column_names:
                success = table["success"].to_numpy().astype(bool)
                entry["episodes_to_solve"][seed] = episodes_to_solve(
                    success, solved_window, solved_success_rate
                )
            else:
                entry["episodes_to_solve"][seed] = None
        summary[variant] = entry
    return summary
