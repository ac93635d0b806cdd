"""A sweep's results: ``results.parquet`` (one row per run: grid values × metrics),
``summary.md`` (means and 95% intervals over seeds, and the claims the study checks),
``claims.json`` and ``figures/<key>.png`` (each metric against each grid parameter).
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from socnav_wm.studies.claims import (
    HORIZON_CLAIM,
    TRAINING_CLAIMS_NOTE,
    horizon_verdict,
    training_claims,
)
from socnav_wm.studies.plan import SweepResult, format_value

__all__ = ["SUMMARY_METRICS", "seed_interval", "write_results"]

# The metrics of a run that the summary and the figures show (all of them go to the table).
SUMMARY_METRICS = (
    "success",
    "human_collision",
    "wall_collision",
    "discomfort",
    "time_to_reach_goal",
    "train_episodes_to_solve",
    "train_cpu_s",
)


def _is_rate(name: str) -> bool:
    return name in ("success", "human_collision", "wall_collision") or name.endswith("_rate")


def seed_interval(values: Sequence[float], name: str) -> tuple[float, float, float]:
    """Mean and 95% Student-t interval over seeds (NaN bounds for one seed), cut to the
    metric's range: every summary metric is non-negative, and a rate is at most 1."""
    from socnav_wm.evaluation.intervals import mean_ci

    mean, low, high, _, _ = mean_ci(values, confidence=0.95, method="t")
    if math.isnan(low):
        return mean, math.nan, math.nan
    return mean, max(low, 0.0), min(high, 1.0) if _is_rate(name) else high


def _groups(outcome: SweepResult) -> dict[tuple[str, tuple[Any, ...]], list[dict[str, Any]]]:
    groups: dict[tuple[str, tuple[Any, ...]], list[dict[str, Any]]] = {}
    for run in outcome.plan.runs:
        result = outcome.results.get(run)
        if result and result.get("status") == "done":
            key = (run.variant, tuple(value for _, value in run.values))
            groups.setdefault(key, []).append(result)
    return groups


def write_results(outcome: SweepResult) -> list[Path]:
    """``results.parquet``, ``summary.md`` and the figures of a sweep (atomically each)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from socnav_wm.io import atomic_path, write_text_atomic

    plan = outcome.plan
    rows = []
    metric_names: list[str] = []
    for run in plan.runs:
        result = outcome.results.get(run, {"status": "not run"})
        metrics = result.get("metrics", {})
        for name in metrics:
            if name not in metric_names:
                metric_names.append(name)
        rows.append((run, result, metrics))
    columns: dict[str, list[Any]] = {
        "run": [r.name for r, _, _ in rows],
        "variant": [r.variant for r, _, _ in rows],
        "seed": [r.seed for r, _, _ in rows],
    }
    for index, key in enumerate(plan.grid_keys):
        columns[key] = [format_value(r.values[index][1]) for r, _, _ in rows]
    columns["status"] = [res.get("status", "not run") for _, res, _ in rows]
    columns["error"] = [res.get("error") for _, res, _ in rows]
    columns["resumed"] = [res.get("resumed") for _, res, _ in rows]
    columns["node"] = [res.get("node") for _, res, _ in rows]
    columns["wall_s"] = [res.get("wall_s") for _, res, _ in rows]
    for name in metric_names:
        columns[name] = [m.get(name) for _, _, m in rows]
    table = pa.table(
        {
            k: pa.array(v, type=pa.float64() if k in metric_names else None)
            for k, v in columns.items()
        }
    )
    plan.out_dir.mkdir(parents=True, exist_ok=True)
    results_path = plan.out_dir / "results.parquet"
    with atomic_path(results_path) as tmp:
        pq.write_table(table, tmp)
    summary_path = plan.out_dir / "summary.md"
    verdict = horizon_verdict(outcome)
    training = training_claims(outcome)
    write_text_atomic(summary_path, _summary(outcome, verdict, training))
    written = [results_path, summary_path]
    found = verdict if verdict is not None else training
    if found is not None:  # for machines: each claim, its comparisons, its verdict
        written.append(plan.out_dir / "claims.json")
        write_text_atomic(written[-1], json.dumps(found, indent=2) + "\n")
    return [*written, *_figures(outcome)]


def _present_metrics(groups: Mapping[Any, list[dict[str, Any]]]) -> list[str]:
    return [
        m for m in SUMMARY_METRICS if any(m in r["metrics"] for g in groups.values() for r in g)
    ]


def _fmt(value: float, name: str) -> str:
    if math.isnan(value):
        return "–"
    if _is_rate(name):
        return f"{value:.1%}"
    return f"{value:.3g}"


def _summary(
    outcome: SweepResult,
    verdict: dict[str, Any] | None,
    training: list[dict[str, Any]] | None = None,
) -> str:
    plan = outcome.plan
    groups = _groups(outcome)
    done = sum(len(v) for v in groups.values())
    grid = ", ".join(
        f"`{key}` ∈ {{{', '.join(map(format_value, vals))}}}"
        for key, vals in plan.study.grid.items()
    )
    lines = [
        f"# Study `{plan.name}`",
        "",
        f"Variants {', '.join(plan.study.variants)}; seeds "
        f"{', '.join(map(str, plan.study.seeds))}" + (f"; {grid}" if grid else "") + ". "
        f"{done} of {len(plan.runs)} runs finished"
        + (f", {len(outcome.failed)} failed" if outcome.failed else "")
        + ". Each run: `socnav-wm train-agent` then `socnav-wm evaluate` on "
        f"{plan.params[plan.runs[0]].eval.episodes} test scenarios; mean [95% interval over "
        "seeds] (Student t; – with one seed).",
        "",
    ]
    metrics = _present_metrics(groups)
    header = ["variant", *[f"`{k}`" for k in plan.grid_keys], "seeds", *metrics]
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for (variant, values), results in groups.items():
        cells = [variant, *map(format_value, values), str(len(results))]
        for metric in metrics:
            vals = [r["metrics"][metric] for r in results if metric in r["metrics"]]
            mean, low, high = seed_interval(vals, metric)
            cell = _fmt(mean, metric)
            if not math.isnan(low):
                cell += f" [{_fmt(low, metric)}, {_fmt(high, metric)}]"
            cells.append(cell)
        lines.append("| " + " | ".join(cells) + " |")
    if outcome.failed:
        lines += ["", "Failed runs:", ""]
        lines += [f"- `{r['run']}`: {r.get('error', '')}" for r in outcome.failed]
    if verdict is not None:
        lines += ["", "## The paper's horizon claim", "", f"> {HORIZON_CLAIM}", ""]
        lines += [*verdict["comparisons"], "", f"**Verdict: {verdict['verdict']}.**"]
    if training is not None:
        lines += ["", "## The paper's training claims", "", TRAINING_CLAIMS_NOTE, ""]
        for claim in training:
            lines.append(f"- **{claim['verdict'].upper()}**: {claim['statement']}")
            lines += [f"  - {check['status']}: {check['evidence']}" for check in claim["checks"]]
    lines += ["", *[f"![{key}](figures/{_figure_name(key)})" for key in plan.grid_keys]]
    return "\n".join(lines).rstrip() + "\n"


def _figure_name(key: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", key) + ".png"


def _figures(outcome: SweepResult) -> list[Path]:
    """Per grid parameter: each summary metric against the parameter's values, one line per
    variant, with the 95% intervals over seeds."""
    plan = outcome.plan
    if not plan.grid_keys:
        return []
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from socnav_wm.io import atomic_path

    groups = _groups(outcome)
    metrics = _present_metrics(groups)
    paths = []
    (plan.out_dir / "figures").mkdir(parents=True, exist_ok=True)
    for index, key in enumerate(plan.grid_keys):
        values = plan.study.grid[key]
        numeric = all(isinstance(v, int | float) and not isinstance(v, bool) for v in values)
        fig, axes = plt.subplots(1, len(metrics), figsize=(3.2 * len(metrics), 3.0), squeeze=False)
        for variant in plan.study.variants:
            for axis, metric in zip(axes[0], metrics, strict=True):
                xs, means, lows, highs = [], [], [], []
                for position, value in enumerate(values):
                    vals = [
                        r["metrics"][metric]
                        for (v, point), results in groups.items()
                        if v == variant and point[index] == value
                        for r in results
                        if metric in r["metrics"]
                    ]
                    if not vals:
                        continue
                    mean, low, high = seed_interval(vals, metric)
                    xs.append(value if numeric else position)
                    means.append(mean)
                    lows.append(mean if math.isnan(low) else low)
                    highs.append(mean if math.isnan(high) else high)
                if xs:
                    errors = [
                        [m - lo for m, lo in zip(means, lows, strict=True)],
                        [h - m for m, h in zip(means, highs, strict=True)],
                    ]
                    axis.errorbar(xs, means, yerr=errors, marker="o", capsize=3, label=variant)
        for axis, metric in zip(axes[0], metrics, strict=True):
            axis.set_title(metric, fontsize=9)
            axis.set_xlabel(key, fontsize=8)
            if not numeric:
                axis.set_xticks(range(len(values)), [format_value(v) for v in values])
            elif len(values) > 1 and min(values) > 0 and max(values) / min(values) >= 8:
                axis.set_xscale("log", base=2)
                axis.set_xticks(values, [str(v) for v in values])
        axes[0][0].legend(fontsize=7)
        fig.suptitle(f"study {plan.name}: mean and 95% interval over seeds", fontsize=10)
        fig.tight_layout()
        path = plan.out_dir / "figures" / _figure_name(key)
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format="png", dpi=90)
        plt.close(fig)
        paths.append(path)
    return paths
