"""Is a rerun the same result? Compare its evaluation metrics with the committed ones.

A run on the same CPU model, library build and thread count reproduces every file bit for bit;
on another machine the floating-point sums round differently, trainings diverge and only the
statistics reproduce. :func:`compare_runs` checks that: each method's mean of each metric in
the rerun must lie within the committed run's 95% interval, and the committed mean within the
rerun's (``socnav-wm check``). Every committed method must have been rerun.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from socnav_wm.io import read_json

CHECKED_METRICS = ("success", "human_collision", "discomfort", "simulation_time")


@dataclass(frozen=True)
class MetricCheck:
    method: str
    metric: str
    committed: dict[str, float]
    rerun: dict[str, float]

    @property
    def agrees(self) -> bool:
        """Each mean lies in the other's 95% interval."""
        a, b = self.committed, self.rerun
        return a["low"] <= b["mean"] <= a["high"] and b["low"] <= a["mean"] <= b["high"]

    @property
    def identical(self) -> bool:
        return all(self.committed[k] == self.rerun[k] for k in ("mean", "low", "high"))


def _read_metrics(path: Path, metrics: tuple[str, ...]) -> dict[str, Any]:
    """An evaluation's ``{method}.json``, checked to hold what is compared; otherwise a
    ValueError naming the file."""
    content = read_json(path, "evaluation metrics file")
    if not isinstance(content, dict) or not isinstance(content.get("metrics"), dict):
        raise ValueError(f"{path}: not a socnav-wm evaluation metrics file (no 'metrics')")
    for metric in metrics:
        entry = content["metrics"].get(metric)
        if entry is None:
            raise ValueError(f"{path}: no {metric!r} metric")
        if not isinstance(entry, dict) or not all(
            isinstance(entry.get(k), int | float) for k in ("mean", "low", "high")
        ):
            raise ValueError(f"{path}: metric {metric!r} lacks its mean, low and high")
    return content


def compare_runs(
    committed_dir: str | Path, rerun_dir: str | Path, metrics: tuple[str, ...] = CHECKED_METRICS
) -> list[MetricCheck]:
    """One check per method of the committed folder of ``{method}.json`` evaluation metrics
    (``metrics/eval/``) and per metric.

    Raises:
        ValueError: one line: the committed folder holds no evaluation metrics, the rerun lacks
            a method of the committed run (naming them), a file is not valid JSON or lacks a
            metric (naming it), or the folders were evaluated on different test scenarios.
    """
    committed_dir, rerun_dir = Path(committed_dir), Path(rerun_dir)
    committed = sorted(committed_dir.glob("*.json"))
    if not committed:
        raise ValueError(f"{committed_dir}: no evaluation metrics to compare with (no *.json)")
    if not rerun_dir.is_dir():
        raise ValueError(f"{rerun_dir}: no such folder of evaluation metrics")
    missing = [path.stem for path in committed if not (rerun_dir / path.name).is_file()]
    if missing:
        raise ValueError(
            f"{rerun_dir}: no evaluation metrics of {', '.join(missing)} (evaluated in "
            f"{committed_dir}); a rerun must evaluate every committed method"
        )
    checks = []
    for path in committed:
        other = rerun_dir / path.name
        a, b = _read_metrics(path, metrics), _read_metrics(other, metrics)
        for key in ("scenario_seed", "episodes"):
            if a.get(key) != b.get(key):
                raise ValueError(
                    f"{other}: {key} {b.get(key)!r}, the committed run has {a.get(key)!r}"
                )
        for metric in metrics:
            name = a.get("method", path.stem)
            checks.append(MetricCheck(name, metric, a["metrics"][metric], b["metrics"][metric]))
    return checks
