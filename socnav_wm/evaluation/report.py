"""The report: the paper's table for every evaluated method, paired comparisons, Pareto analysis,
figures, and a claim-by-claim check of the paper against this run.

Inputs are the evaluation files (``data/eval/{method}.parquet`` and
``{method}-trajectories.parquet``, from :mod:`socnav_wm.evaluation.evaluate`) and the training
logs (``data/training/{variant}/seed-{seed}.parquet``, one row per episode). Outputs:
``reports/summary.md``, ``reports/pareto.json``, ``reports/claims.json`` (every claim's checks
and evidence), ``reports/figures/*.png``, ``reports/figures/scenarios.gif`` and
``metrics/report.json`` (means, intervals, p-values, Pareto set, claim verdicts). Any method may
be missing: the report says which, and every section uses what is there.

This module reads the inputs, computes the table and writes the outputs; the rest lives beside
it: :mod:`~socnav_wm.evaluation.comparisons` (paired tests between methods, Pareto analysis),
:mod:`~socnav_wm.evaluation.claims` (the paper's claims checked),
:mod:`~socnav_wm.evaluation.rendering` (``summary.md`` and the content of ``metrics/report.json``)
and :mod:`~socnav_wm.evaluation.figures`.

Statistics (see :mod:`socnav_wm.evaluation.stats` for the building blocks)
------------------------------------------------------------------------
* **Table.** Mean of each metric over scenarios × training seeds with a 95% two-way bootstrap
  interval (:func:`~socnav_wm.evaluation.records.summarise`); per-seed means beside it.
* **Pairing, tests, multiple comparisons, Pareto:** see
  :mod:`~socnav_wm.evaluation.comparisons`.
* **Claim verdicts:** see :mod:`~socnav_wm.evaluation.claims`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from socnav_wm.env.params import EnvParams
from socnav_wm.evaluation import paper
from socnav_wm.evaluation.claims import check_claims
from socnav_wm.evaluation.comparisons import compare_with_reference, pareto_analysis
from socnav_wm.evaluation.figures import (
    histograms_figure,
    means_figure,
    training_curves_figure,
)
from socnav_wm.evaluation.intervals import mean_ci_crossed
from socnav_wm.evaluation.params import ReportParams
from socnav_wm.evaluation.records import episode_from_trajectories, per_seed_means, summarise
from socnav_wm.evaluation.rendering import (
    ReportResults,
    render_summary,
    replace_marked_block,
    report_content,
    results_table,
)
from socnav_wm.evaluation.results import (
    MethodEvaluation,
    load_evaluations,
    load_training_returns,
    training_summary,
)
from socnav_wm.evaluation.scenes import scenarios_gif
from socnav_wm.io import write_json_atomic, write_text_atomic
from socnav_wm.method_names import REPORTED_METHOD_NAMES
from socnav_wm.metrics import ALL_METRICS, PAPER_METRICS

__all__ = ["FIGURE_NAMES", "ReportResult", "build_report"]

FIGURE_NAMES = ("training_curves.png", "histograms.png", "means.png", "scenarios.gif")
"""The files :func:`build_report` may write under ``reports/figures/``."""


# --------------------------------------------------------------------------------------------
# The report
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ReportResult:
    """What :func:`build_report` wrote and found.

    Attributes:
        summary_path, pareto_path, claims_path, metrics_path: the written files.
        figures: the written figures (PNG and GIF), in order.
        present, absent: evaluated and missing methods.
        verdicts: claim id → verdict.
        content: the content of ``metrics/report.json``.
    """

    summary_path: Path
    pareto_path: Path
    claims_path: Path
    metrics_path: Path
    figures: list[Path]
    present: list[str]
    absent: list[str]
    verdicts: dict[str, str]
    content: dict[str, Any]


def _any_collision(table: pa.Table) -> dict[str, float]:
    values = table["human_collision"].to_numpy().astype(np.float64) + table[
        "wall_collision"
    ].to_numpy().astype(np.float64)
    ci = mean_ci_crossed(values, table["scenario_id"].to_numpy(), table["training_seed"].to_numpy())
    return {"mean": ci.mean, "low": ci.low, "high": ci.high, "n": ci.n}


def _gif_episodes(
    evaluations: Mapping[str, MethodEvaluation], scenarios: Sequence[int]
) -> tuple[list[dict[str, Any]], list[str]]:
    """Per scenario, method → episode rebuilt from the trajectories (agents: lowest seed)."""
    notes = []
    usable: dict[str, tuple[pa.Table, int]] = {}
    for method, evaluation in evaluations.items():
        if evaluation.trajectories_path is None:
            notes.append(f"{method}: no trajectories file")
            continue
        seed = evaluation.training_seeds[0]
        table = pq.read_table(
            evaluation.trajectories_path,
            filters=[("scenario_id", "in", list(scenarios)), ("training_seed", "=", seed)],
        )
        have = set(table["scenario_id"].to_pylist())
        if not set(scenarios) <= have:
            notes.append(f"{method}: scenarios {sorted(set(scenarios) - have)} not recorded")
            continue
        usable[method] = (table, seed)
    per_scenario = [
        {
            method: episode_from_trajectories(table, method, seed, scenario)
            for method, (table, seed) in usable.items()
        }
        for scenario in scenarios
    ]
    return per_scenario, notes


def _read_prediction(path: str | Path | None) -> dict[str, Any] | None:
    """The content of ``metrics/prediction.json`` (None without a path); one line when it is
    not a prediction file."""
    if path is None:
        return None
    try:
        content = json.loads(Path(path).read_text(encoding="utf-8"))
        content["settings"], content["policies"]  # noqa: B018 - the two keys the report reads
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"{path}: not a socnav-wm prediction file ({exc})") from None
    return content


def build_report(
    eval_dir: str | Path,
    training_dir: str | Path,
    out_dir: str | Path,
    metrics_path: str | Path,
    *,
    env_params: EnvParams | None = None,
    scenario_seed: int | None = None,
    report: ReportParams,
    methods: Sequence[str] = REPORTED_METHOD_NAMES,
    solved_window: int,
    solved_success_rate: float,
    gif_size: int = 200,
    gif_max_frames: int = 60,
    documents: Sequence[str | Path] = (),
    prediction_path: str | Path | None = None,
    planning_horizons: Mapping[str, int] | None = None,
) -> ReportResult:
    """Write the report of every evaluated method (see the module docstring).

    Args:
        eval_dir: folder of ``{method}.parquet`` and ``{method}-trajectories.parquet``.
        training_dir: folder of ``{variant}/seed-{seed}.parquet`` training logs.
        out_dir: the report folder (``reports/``): ``summary.md``, ``pareto.json``,
            ``claims.json``, ``figures/``.
        metrics_path: the machine-readable summary (``metrics/report.json``).
        env_params, scenario_seed: the test scenarios the report expects (checked against the
            files' metadata when given; the files' values are used otherwise).
        report: the ``report`` section: the reference every other method is compared with,
            the family-wise error rate of the paired tests, the training curves' rolling-mean
            window and the test scenarios of ``figures/scenarios.gif`` (empty: no GIF).
        methods: the methods to look for.
        solved_window, solved_success_rate: the "solved" criterion of the training claims
            (``agent.solved_window``, ``agent.solved_success_rate``).
        gif_size: GIF cell side, px.
        gif_max_frames: frames per scenario in the GIF (long episodes are subsampled).
        documents: markdown files (the README) whose ``results`` block
            (:func:`~socnav_wm.evaluation.rendering.replace_marked_block`) gets the results table.
        prediction_path: the world model's prediction errors (``metrics/prediction.json`` of
            ``socnav-wm predict``), reported when given.
        planning_horizons: each planner's horizon (``planning``, resolved per method), where
            the planning section reads its model's prediction errors (default: the longest
            predicted).

    Returns:
        A :class:`ReportResult`.

    Raises:
        ValueError: evaluation files made on different scenarios.
    """
    reference, alpha, smoothing_window = report.reference, report.alpha, report.smoothing_window
    gif_scenarios = report.gif_scenarios
    out_dir = Path(out_dir)
    figures_dir = out_dir / "figures"
    evaluations, absent = load_evaluations(
        eval_dir, methods, scenario_seed=scenario_seed, env_params=env_params
    )
    present = list(evaluations)
    first = next(iter(evaluations.values()), None)
    scenario_seed = first.metadata["scenario_seed"] if first else scenario_seed
    num_scenarios = first.metadata["num_scenarios"] if first else 0
    if first is not None:
        env_params = EnvParams.from_dict(first.metadata["env_params"])

    # -- numbers -------------------------------------------------------------------------------
    summaries = {m: summarise(e.episodes, ALL_METRICS) for m, e in evaluations.items()}
    means = {m: {k: v["mean"] for k, v in s.items()} for m, s in summaries.items()}
    per_seed = {m: per_seed_means(e.episodes) for m, e in evaluations.items() if e.is_agent}
    comparisons = compare_with_reference(evaluations, reference, PAPER_METRICS, alpha)
    pareto = pareto_analysis(means, PAPER_METRICS)
    logs = load_training_returns(training_dir)
    training = training_summary(
        logs,
        window=smoothing_window,
        solved_window=solved_window,
        solved_success_rate=solved_success_rate,
    )
    claims = check_claims(evaluations, means, training, alpha=alpha)
    any_collision = {m: _any_collision(e.episodes) for m, e in evaluations.items()}

    # -- figures -------------------------------------------------------------------------------
    figure_paths: list[Path] = []
    figure_notes: list[str] = []
    if logs:
        path = figures_dir / "training_curves.png"
        training_curves_figure(
            {
                v: {s: t["return"].to_numpy().astype(np.float64) for s, t in seeds.items()}
                for v, seeds in logs.items()
            },
            path,
            window=smoothing_window,
            paper_plateaus={v: t.plateau for v, t in paper.TRAINING_TARGETS.items() if v in logs},
        )
        figure_paths.append(path)
    else:
        figure_notes.append(f"no training logs under {training_dir}: no training curves")
    if evaluations:
        values = {
            m: {k: e.episodes[k].to_numpy().astype(np.float64) for k in PAPER_METRICS}
            for m, e in evaluations.items()
        }
        path = figures_dir / "histograms.png"
        histograms_figure(values, PAPER_METRICS, path)
        figure_paths.append(path)
        path = figures_dir / "means.png"
        means_figure(summaries, PAPER_METRICS, path)
        figure_paths.append(path)
        if gif_scenarios and env_params is not None:
            scenarios = [s for s in gif_scenarios if 0 <= s < num_scenarios]
            episodes, notes = _gif_episodes(evaluations, scenarios)
            figure_notes += [f"GIF: {n}" for n in notes]
            if scenarios and episodes and episodes[0]:
                path = figures_dir / "scenarios.gif"
                scenarios_gif(episodes, env_params, path, size=gif_size, max_frames=gif_max_frames)
                figure_paths.append(path)

    # A figure this run could not draw must not survive from an earlier run of the report.
    for name in FIGURE_NAMES:
        if figures_dir / name not in figure_paths:
            (figures_dir / name).unlink(missing_ok=True)

    # -- outputs -------------------------------------------------------------------------------
    results = ReportResults(
        evaluations=evaluations,
        absent=absent,
        summaries=summaries,
        per_seed=per_seed,
        any_collision=any_collision,
        comparisons=comparisons,
        reference=reference,
        pareto=pareto,
        claims=claims,
        training=training,
        scenario_seed=scenario_seed,
        num_scenarios=num_scenarios,
        smoothing_window=smoothing_window,
        alpha=alpha,
    )
    content = report_content(results)
    summary_md = render_summary(
        results,
        figure_paths=figure_paths,
        figure_notes=figure_notes,
        out_dir=out_dir,
        prediction=_read_prediction(prediction_path),
        planning_horizons=planning_horizons,
    )
    summary_path = out_dir / "summary.md"
    pareto_path = out_dir / "pareto.json"
    claims_path = out_dir / "claims.json"
    write_text_atomic(summary_path, summary_md)
    write_json_atomic(pareto_path, {**pareto, "means": {m: means[m] for m in present}})
    write_json_atomic(claims_path, {r.claim.claim_id: r.to_dict() for r in claims})
    write_json_atomic(metrics_path, content)
    table = results_table(
        summaries, present, num_scenarios=num_scenarios, scenario_seed=scenario_seed, claims=claims
    )
    for document in map(Path, documents):  # the README's results block, and the docs'
        text = replace_marked_block(document.read_text(encoding="utf-8"), "results", table)
        write_text_atomic(document, text)
    return ReportResult(
        summary_path=summary_path,
        pareto_path=pareto_path,
        claims_path=claims_path,
        metrics_path=Path(metrics_path),
        figures=figure_paths,
        present=present,
        absent=absent,
        verdicts={r.claim.claim_id: r.verdict for r in claims},
        content=content,
    )
