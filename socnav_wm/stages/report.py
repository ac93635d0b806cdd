"""Stage ``report``: table, paired tests, Pareto set, figures and the paper's claims checked."""

from __future__ import annotations

from pathlib import Path

from socnav_wm.config import Params
from socnav_wm.evaluation.report import build_report
from socnav_wm.layout import LAYOUT
from socnav_wm.method_names import METHOD_NAMES
from socnav_wm.planning.params import PLANNER_NAMES
from socnav_wm.stages.common import open_stage

RESULTS_DOCUMENTS = LAYOUT.results_documents
"""The markdown files whose ``results`` block the stage fills (outputs of the DVC stage)."""


def run(
    params: Params,
    *,
    eval_dir: Path,
    training_dir: Path,
    out_dir: Path,
    metrics: Path,
    documents: tuple[Path, ...] | None = None,
    prediction: Path | None,
    tracking: bool = True,
) -> str:
    """The report of the evaluations in ``eval_dir``; refused in one line, before anything is
    written, when it holds none."""
    if not any((eval_dir / f"{method}.parquet").is_file() for method in METHOD_NAMES):
        raise ValueError(
            f"no evaluation found in {eval_dir} (no {{method}}.parquet; run `socnav-wm "
            "evaluate --method …` first)"
        )
    if documents is None:  # the results blocks of the README and the docs, where they exist
        documents = tuple(p for p in RESULTS_DOCUMENTS if p.is_file())
    with open_stage("report", "report", params, tracking=tracking) as run:
        result = build_report(
            eval_dir,
            training_dir,
            out_dir,
            metrics,
            env_params=params.env,
            scenario_seed=params.eval.scenario_seed,
            report=params.report,
            solved_window=params.agent.solved_window,
            solved_success_rate=params.agent.solved_success_rate,
            documents=documents,
            prediction_path=prediction if prediction is not None and prediction.is_file() else None,
            planning_horizons={
                method: params.planning.resolved(method).horizon for method in PLANNER_NAMES
            },
        )
        for claim, verdict in result.verdicts.items():
            run.set_tag(f"claim.{claim}", verdict)
        run.set_tag("methods", ",".join(result.present))
        for path in (result.summary_path, result.pareto_path, result.claims_path, *result.figures):
            run.log_artifact(path, "figures" if path in result.figures else None)
    missing = f"; missing: {', '.join(result.absent)}" if result.absent else ""
    return f"wrote {result.summary_path} ({len(result.present)} methods{missing})"
