"""Is a rerun the same result? Compare its evaluation metrics with the committed ones.

A run on the same CPU model, library build and thread count reproduces every file bit for bit;
on another machine the floating-point sums round differently, trainings diverge and only the
statistics reproduce. :func:`compare_runs` checks that: each method's mean of each metric in
the rerun must lie within the committed run's 95% interval, and the committed mean within the
rerun's (``socnav-wm check``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

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


def compare_runs(
    committed_dir: str | Path, rerun_dir: str | Path, metrics: tuple[str, ...] = CHECKED_METRICS
) -> list[MetricCheck]:
    """One check per method present in both folders of ``{method}.json`` evaluation metrics
    (``metrics/eval/``) and per metric. Raises ValueError when the folders share no method or
    were evaluated on different test scenarios."""
    committed_dir, rerun_dir = Path(committed_dir), Path(rerun_dir)
    checks = []
    for path in sorted(committed_dir.glob("*.json")):
        other = rerun_dir / path.name
        if not other.is_file():
            continue
        a, b = json.loads(path.read_text()), json.loads(other.read_text())
        for key in ("scenario_seed", "episodes"):
            if a.get(key) != b.get(key):
                raise ValueError(
                    f"{other}: {key} {b.get(key)!r}, the committed run has {a.get(key)!r}"
                )
        for metric in metrics:
            checks.append(
                MetricCheck(a["method"], metric, a["metrics"][metric], b["metrics"][metric])
            )
    if not checks:
        raise ValueError(f"{rerun_dir}: no evaluation metrics of the methods in {committed_dir}")
    return checks
