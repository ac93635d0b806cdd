"""The report's results turned into text: ``summary.md`` (Markdown tables and prose) and the
content of ``metrics/report.json``.

Nothing here computes a statistic: the numbers come from
:mod:`~socnav_wm.evaluation.comparisons`, :mod:`~socnav_wm.evaluation.claims` and
:func:`~socnav_wm.evaluation.records.summarise`; the number formats from
:mod:`~socnav_wm.evaluation.formatting`; the sections on the world model and the planners from
:mod:`~socnav_wm.evaluation.model_sections`. :mod:`~socnav_wm.evaluation.report` writes the
files.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from socnav_wm.evaluation import paper
from socnav_wm.evaluation.claims import VERDICTS, ClaimResult
from socnav_wm.evaluation.comparisons import PairedComparison
from socnav_wm.evaluation.formatting import (
    direction_mark,
    fmt_ci,
    fmt_p,
    fmt_value,
    markdown_table,
)
from socnav_wm.evaluation.model_sections import planning_section, prediction_section
from socnav_wm.evaluation.records import BASELINE_SEED
from socnav_wm.evaluation.results import MethodEvaluation
from socnav_wm.method_names import METHOD_NAMES, VARIANT_NAMES
from socnav_wm.metrics import ALL_METRICS, METRIC_DIRECTIONS, METRIC_UNITS, PAPER_METRICS

__all__ = [
    "ReportResults",
    "render_summary",
    "replace_marked_block",
    "report_content",
    "results_table",
]


def _fmt_difference(c: PairedComparison) -> str:
    def signed(x: float) -> str:
        text = fmt_value(c.metric, x)
        return text if text.startswith(("-", "−", "–")) else f"+{text}"

    if not (math.isfinite(c.low) and math.isfinite(c.high)):
        return signed(c.difference)
    return f"{signed(c.difference)} [{fmt_value(c.metric, c.low)}, {fmt_value(c.metric, c.high)}]"


@dataclass(frozen=True)
class ReportResults:
    """What the report found: what both ``metrics/report.json`` (:func:`report_content`) and
    ``summary.md`` (:func:`render_summary`) present."""

    evaluations: Mapping[str, MethodEvaluation]
    absent: Sequence[str]
    summaries: Mapping[str, Mapping[str, Mapping[str, float]]]
    per_seed: Mapping[str, Mapping[int, Mapping[str, float]]]
    any_collision: Mapping[str, Mapping[str, float]]
    comparisons: Sequence[PairedComparison]
    reference: str
    pareto: Mapping[str, Any]
    claims: Sequence[ClaimResult]
    training: Mapping[str, Mapping[str, Any]]
    scenario_seed: int | None
    num_scenarios: int
    smoothing_window: int
    alpha: float


# --------------------------------------------------------------------------------------------
# metrics/report.json
# --------------------------------------------------------------------------------------------


def report_content(results: ReportResults) -> dict[str, Any]:
    """The content of ``metrics/report.json``: means, intervals, p-values, Pareto set, verdicts."""
    present = list(results.evaluations)
    content: dict[str, Any] = {
        "scenario_seed": results.scenario_seed,
        "episodes": results.num_scenarios,
        "reference": results.reference,
        "alpha": results.alpha,
        "methods_present": present,
        "methods_absent": results.absent,
        "methods": {
            m: {
                "training_seeds": results.evaluations[m].training_seeds,
                "metrics": results.summaries[m],
                "any_collision": results.any_collision[m],
                **(
                    {"per_seed": {f"seed-{s}": v for s, v in results.per_seed[m].items()}}
                    if m in results.per_seed
                    else {}
                ),
            }
            for m in present
        },
        "comparisons": {},
        "pareto": results.pareto,
        # Verdicts only: the checks behind them (lists of dicts, which `dvc metrics show`
        # cannot tabulate) go to reports/claims.json.
        "claims": {
            r.claim.claim_id: {"verdict": r.verdict, "statement": r.claim.statement}
            for r in results.claims
        },
        "training": {
            v: {
                "seeds": t["seeds"],
                "plateau": {f"seed-{s}": x for s, x in t["plateau"].items()},
                "episodes_to_solve": {f"seed-{s}": x for s, x in t["episodes_to_solve"].items()},
                "paper_plateau": paper.TRAINING_TARGETS[v].plateau
                if v in paper.TRAINING_TARGETS
                else None,
            }
            for v, t in results.training.items()
        },
        "smoothing_window": results.smoothing_window,
    }
    for c in results.comparisons:
        entry = {k: v for k, v in asdict(c).items() if k not in ("method", "other", "metric")}
        entry["verdict"] = c.verdict(results.alpha)
        content["comparisons"].setdefault(c.method, {})[c.metric] = entry
    return content


# --------------------------------------------------------------------------------------------
# summary.md
# --------------------------------------------------------------------------------------------


def render_summary(
    results: ReportResults,
    *,
    figure_paths: Sequence[Path],
    figure_notes: Sequence[str],
    out_dir: Path,
    prediction: Mapping[str, Any] | None = None,
    planning_horizons: Mapping[str, int] | None = None,
) -> str:
    """The text of ``summary.md``: tables, comparisons, Pareto set, the paper, claims, the world
    model's prediction errors (``prediction``, from ``socnav-wm predict``), the planners against
    their ceiling (explained by the prediction errors at each planner's horizon,
    ``planning_horizons``), figures."""
    evaluations, summaries, pareto = results.evaluations, results.summaries, results.pareto
    comparisons, reference, alpha = results.comparisons, results.reference, results.alpha
    num_scenarios, scenario_seed = results.num_scenarios, results.scenario_seed
    absent, smoothing_window = results.absent, results.smoothing_window
    lines: list[str] = ["# socnav-wm: evaluation report", ""]
    present = list(evaluations)
    seeds_text = ", ".join(
        f"{m} ({len(e.training_seeds)} seed{'s' if len(e.training_seeds) > 1 else ''})"
        if e.is_agent
        else m
        for m, e in evaluations.items()
    )
    lines += [
        f"Test scenarios: {num_scenarios} (scenario seed {scenario_seed}), the same for every "
        "method. Agents act greedily; every training seed is evaluated. Baselines are "
        f"deterministic (one run, `training_seed = {BASELINE_SEED}`).",
        "",
        f"- Evaluated: {seeds_text or 'none'}.",
        f"- **Not evaluated: {', '.join(absent)}.**" if absent else "- Not evaluated: none.",
        "",
    ]
    if not present:
        lines += ["No evaluation file was found: nothing to report.", ""]

    # -- the table -----------------------------------------------------------------------------
    if present:
        lines += [
            "## Test metrics",
            "",
            "Mean [95% interval] over scenarios × training seeds (two-way bootstrap: seeds and "
            "scenarios resampled independently); rates in %. ↑ higher is better, ↓ lower is "
            "better. Definitions: `socnav_wm/metrics.py` (the paper's intent, world frame).",
            "",
        ]
        header = ["method", "n"] + [f"{m} {direction_mark(m)}" for m in PAPER_METRICS]
        rows = [
            [m, str(summaries[m]["success"]["n"])]
            + [fmt_ci(k, summaries[m][k]) for k in PAPER_METRICS]
            for m in present
        ]
        lines += markdown_table(header, rows) + [""]
        extra = [k for k in ALL_METRICS if k not in PAPER_METRICS]
        lines += ["Further metrics:", ""]
        header = ["method"] + [f"{m} {direction_mark(m)}" for m in extra]
        rows = [[m] + [fmt_ci(k, summaries[m][k]) for k in extra] for m in present]
        lines += markdown_table(header, rows) + [""]
        lines += [
            "`time_to_reach_goal` is over successful episodes only; "
            "`personal_space_compliance_code` is the original code's definition (centre "
            "distance ≥ 2.02 m).",
            "",
        ]
        if results.per_seed:
            lines += [
                "### Per training seed",
                "",
                "With a handful of seeds the interval's seed component is estimated poorly: "
                "here is the spread itself.",
                "",
            ]
            header = ["method", "seed"] + list(PAPER_METRICS)
            rows = [
                [m, str(s)] + [fmt_value(k, v[k]) for k in PAPER_METRICS]
                for m, seeds in results.per_seed.items()
                for s, v in seeds.items()
            ]
            lines += markdown_table(header, rows) + [""]

    # -- paired comparisons --------------------------------------------------------------------
    lines += ["## Paired comparisons with " + f"`{reference}`", ""]
    if reference not in evaluations:
        lines += [f"`{reference}` was not evaluated: no paired comparisons.", ""]
    elif not comparisons:
        lines += ["No other method was evaluated.", ""]
    else:
        lines += [
            "Same scenarios, paired scenario by scenario (same seeds: seed s, scenario i "
            "against seed s, scenario i; agent vs baseline: every seed's run against the "
            "baseline's). The scenario is the independent unit: McNemar (clustered McNemar, "
            "Durkalski et al. 2003, when a scenario holds several pairs) for 0/1 metrics, "
            "Wilcoxon signed-rank on per-scenario means otherwise. Difference = method − "
            f"reference with a 95% interval; Holm over all {len(comparisons)} comparisons; "
            f"verdict at α = {alpha}.",
            "",
        ]
        header = [
            "method",
            "metric",
            "test",
            "pairs (scenarios)",
            "difference [95%]",
            "effect",
            "p",
            "Holm p",
            "verdict",
        ]
        rows = []
        for c in comparisons:
            if c.num_pairs == 0:
                rows.append([c.method, c.metric, "–", "0", "–", "–", "–", "–", "no pairs"])
                continue
            effect = (
                f"{c.effect_size:+.3f} (r)"
                if c.effect_name.startswith("rank")
                else f"{100 * c.effect_size:+.1f} pp"
            )
            rows.append(
                [
                    c.method,
                    c.metric,
                    c.test,
                    f"{c.num_pairs} ({c.num_scenarios})",
                    _fmt_difference(c),
                    effect,
                    fmt_p(c.p_value),
                    fmt_p(c.p_holm),
                    c.verdict(alpha),
                ]
            )
        lines += markdown_table(header, rows) + [""]

    # -- Pareto --------------------------------------------------------------------------------
    lines += ["## Pareto analysis", ""]
    if present:
        metrics_text = ", ".join(f"{m} {direction_mark(m)}" for m in pareto["metrics"])
        lines += [
            f"Over the means of: {metrics_text} (directions declared in "
            "`socnav_wm.metrics.METRIC_DIRECTIONS`). No statistical test: a method is dominated "
            "when another is at least as good on every metric and better on one.",
            "",
            f"- Non-dominated: **{', '.join(pareto['front'])}**",
        ]
        for method, winners in pareto["dominated_by"].items():
            lines.append(f"- {method} is dominated by {', '.join(winners)}")
        if pareto["dropped_metrics"]:
            lines.append(f"- Left out (undefined mean): {', '.join(pareto['dropped_metrics'])}")
        lines.append("")
    else:
        lines += ["No method evaluated.", ""]

    # -- the paper -----------------------------------------------------------------------------
    lines += _paper_section(
        evaluations, summaries, results.any_collision, results.training, smoothing_window
    )
    lines += ["## The paper's claims, checked", ""]
    lines += [
        'Each claim is split into checks ("A beats B on a metric"), Holm-adjusted within the '
        f"claim (α = {alpha}). A claim is reproduced when all its testable checks are "
        "significant in the paper's direction, not reproduced when one is significant the "
        "other way; _inconclusive_ means no significant difference either way. Training "
        "claims compare per-seed values (Mann–Whitney): with fewer than 4–5 seeds a side "
        "they cannot be decided. Verdicts are computed from this run's data. The studies "
        "(`make study`, hours of trainings outside `dvc repro`) check the training claims "
        "with five seeds and the paper's look-ahead claim; `reports/studies/claims.md` gives "
        "every claim with the strongest evidence present (stage `study_claims`).",
        "",
    ]
    for result in results.claims:
        note = f" ({result.note})" if result.note else ""
        lines.append(
            f"- **{result.verdict.upper()}**{note} — {result.claim.statement} "
            f"[{result.claim.source}]"
        )
        for check in result.checks:
            lines.append(
                f"  - {check.status}: {check.subject} vs {check.other}, "
                f"{check.metric}: {check.evidence}"
            )
    lines += ["", f"> {paper.BASELINE_NOTE}", ""]
    if prediction is not None:
        lines += prediction_section(prediction)
    lines += planning_section(evaluations, summaries, prediction, planning_horizons or {})

    # -- figures -------------------------------------------------------------------------------
    lines += ["## Figures", ""]
    captions = {
        "training_curves.png": "Training return per episode, trailing rolling mean of "
        f"{smoothing_window} episodes; line = mean over seeds, band = min–max over seeds "
        "(the paper's Fig. 6).",
        "histograms.png": "Distribution of each metric over test episodes, methods side by "
        "side; fraction of each method's episodes (the paper's Figs. 7–8).",
        "means.png": "Means and 95% intervals of the table.",
        "scenarios.gif": "The same test scenarios played by every method (agents: lowest "
        "training seed), rebuilt from the recorded trajectories.",
    }
    for path in figure_paths:
        relative = path.relative_to(out_dir).as_posix() if path.is_relative_to(out_dir) else path
        lines += [f"![{path.name}]({relative})", "", captions.get(path.name, ""), ""]
    for note in figure_notes:
        lines.append(f"- {note}")
    if figure_notes:
        lines.append("")
    return "\n".join(lines).rstrip() + "\n"


def _paper_section(
    evaluations: Mapping[str, MethodEvaluation],
    summaries: Mapping[str, Mapping[str, Mapping[str, float]]],
    any_collision: Mapping[str, Mapping[str, float]],
    training: Mapping[str, Mapping[str, Any]],
    smoothing_window: int,
) -> list[str]:
    lines = [
        "## Side by side with the paper",
        "",
        "Paper values read from the UKCI 2023 figures (paper_spec §7): rates ±0.6 pp (±3 "
        'episodes of 500), means ±half a histogram bin. "comparable" says whether the '
        "paper's scripts measured the same thing as ours.",
        "",
    ]
    header = ["method", "metric", "paper", "this run [95%]", "comparable", "note"]
    rows = []
    for method in METHOD_NAMES:
        if method not in evaluations or method not in paper.TEST_TARGETS:
            continue
        for label, target in paper.TEST_TARGETS[method].items():
            ours = (
                any_collision[method]
                if target.our_metric == paper.ANY_COLLISION
                else summaries[method][target.our_metric]
            )
            uncertainty = (
                f" ± {fmt_value(target.our_metric, target.uncertainty)}"
                if target.uncertainty
                else ""
            )
            rows.append(
                [
                    f"{method} ({paper.PAPER_METHOD_NAMES[method]})",
                    label,
                    fmt_value(target.our_metric, target.value) + uncertainty,
                    fmt_ci(target.our_metric, ours),
                    "yes" if target.comparable else "no",
                    target.note,
                ]
            )
    if rows:
        lines += markdown_table(header, rows) + [""]
    else:
        lines += ["No evaluated method to compare.", ""]
    if training:
        lines += [
            "Training (final smoothed return = mean return of the last "
            f"{smoothing_window} episodes; the paper trained up to 180k episodes, its window is "
            "unknown):",
            "",
        ]
        header = ["variant", "paper plateau", "this run: mean [min, max] over seeds", "seeds",
                  "episodes", "episodes to solve"]  # fmt: skip
        rows = []
        for variant, entry in training.items():
            plateaus = [v for v in entry["plateau"].values() if v is not None]
            solved = ["never" if v is None else str(v) for v in entry["episodes_to_solve"].values()]
            target = paper.TRAINING_TARGETS.get(variant)
            rows.append(
                [
                    variant,
                    f"{target.plateau:.2f}" if target else "–",
                    f"{np.mean(plateaus):.3f} [{min(plateaus):.3f}, {max(plateaus):.3f}]"
                    if plateaus
                    else "–",
                    str(len(entry["seeds"])),
                    ", ".join(str(e) for e in entry["episodes"].values()),
                    ", ".join(solved),
                ]
            )
        lines += markdown_table(header, rows) + [""]
    return lines


RESULTS_METRICS = (
    "success",
    "human_collision",
    "discomfort",
    "simulation_time",
    "distance_travelled",
    "personal_space_compliance",
)
"""The columns of the short results table (README); ``summary.md`` has every metric."""


def results_table(
    summaries: Mapping[str, Mapping[str, Mapping[str, float]]],
    present: Sequence[str],
    *,
    num_scenarios: int,
    scenario_seed: int | None,
    claims: Sequence[ClaimResult] = (),
) -> str:
    """The results of every evaluated method as one markdown table, with the line that says
    what it is, units in its header, and under it the verdicts: the paper's claims
    (:func:`claims_verdict`) and where a robot or a planner beats every learned agent
    (:func:`beats_every_agent`). The block :func:`replace_marked_block` writes into the
    README."""
    lines = [
        f"Every method on the same {num_scenarios} test scenarios (scenario seed "
        f"{scenario_seed}); agents: every training seed, greedy. Mean [95% interval]; "
        "↑ higher is better, ↓ lower. Written by `socnav-wm report` "
        "(all metrics and the paired tests: `reports/summary.md`).",
        "",
    ]
    header = ["method"] + [f"{m} ({_unit(m)}) {direction_mark(m)}" for m in RESULTS_METRICS]
    rows = [[f"`{m}`"] + [fmt_ci(k, summaries[m][k]) for k in RESULTS_METRICS] for m in present]
    verdicts = [v for v in (claims_verdict(claims), beats_every_agent(summaries, present)) if v]
    return "\n".join(lines + markdown_table(header, rows) + ([""] + verdicts if verdicts else []))


def _unit(metric: str) -> str:
    """A column's unit as the table prints its values: rates in %."""
    unit = METRIC_UNITS[metric]
    return "%" if unit == "0/1" else unit


def claims_verdict(claims: Sequence[ClaimResult]) -> str:
    """One line: how many of the paper's claims this run reproduces, and which verdict each
    has (empty without claims)."""
    if not claims:
        return ""
    by_verdict = {v: [c.claim.claim_id for c in claims if c.verdict == v] for v in VERDICTS}
    found = ", ".join(f"{v}: {', '.join(ids)}" for v, ids in by_verdict.items() if ids)
    reproduced = len(by_verdict["reproduced"])
    return (
        f"**The paper's claims: {reproduced} of {len(claims)} reproduced** ({found}; "
        "`reports/claims.json`, why in `reports/summary.md`)."
    )


def beats_every_agent(
    summaries: Mapping[str, Mapping[str, Mapping[str, float]]], present: Sequence[str]
) -> str:
    """One line: for each evaluated robot and planner, the table's metrics on which it beats
    every evaluated learned agent, its 95% interval clear of each agent's (empty without
    both kinds)."""
    agents = [m for m in present if m in VARIANT_NAMES]
    others = [m for m in present if m not in VARIANT_NAMES]
    if not agents or not others:
        return ""

    def better(method: str, metric: str) -> bool:
        own = summaries[method][metric]
        for agent in agents:
            theirs = summaries[agent][metric]
            if METRIC_DIRECTIONS[metric] == "max" and not own["low"] > theirs["high"]:
                return False
            if METRIC_DIRECTIONS[metric] == "min" and not own["high"] < theirs["low"]:
                return False
        return True

    found = []
    for method in others:
        wins = [metric for metric in RESULTS_METRICS if better(method, metric)]
        found.append(f"`{method}` on {', '.join(wins) if wins else 'none'}")
    return (
        "**Robots and planners against the learned agents** (better than every agent, the "
        f"95% intervals apart): {'; '.join(found)}."
    )


def replace_marked_block(text: str, name: str, body: str) -> str:
    """``text`` with what lies between ``<!-- socnav-wm:name -->`` and
    ``<!-- /socnav-wm:name -->`` replaced by ``body``. Raises ValueError if the markers are
    missing (a document that should carry the block must have them)."""
    start, end = f"<!-- socnav-wm:{name} -->", f"<!-- /socnav-wm:{name} -->"
    before, found, rest = text.partition(start)
    _, found_end, after = rest.partition(end)
    if not found or not found_end:
        raise ValueError(f"no block {start} … {end} to fill")
    return f"{before}{start}\n{body.rstrip()}\n{end}{after}"
