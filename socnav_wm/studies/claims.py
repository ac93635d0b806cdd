"""The paper's claims that a study checks: the look-ahead claim on the ``horizon`` study
(:func:`horizon_verdict`), the training claims on a study without a grid such as ``seeds``
(:func:`training_claims`). Each study's ``summary.md`` and ``claims.json`` carry them; the
``study_claims`` stage (:mod:`socnav_wm.stages.study_claims`) merges them with the report's.
"""

from __future__ import annotations

import statistics
from typing import Any

from socnav_wm.studies.plan import SweepResult

__all__ = ["HORIZON_CLAIM", "TRAINING_CLAIMS_NOTE", "horizon_verdict", "training_claims"]

HORIZON_CLAIM = (
    "predicting more than 2 steps ahead did not improve the results in our SocNavGym setup and "
    "made training slower (the paper, section 3.1)"
)


def horizon_verdict(outcome: SweepResult) -> dict[str, Any] | None:
    """The paper's horizon claim checked on a study whose only grid key is ``agent.horizon``
    with 2 among its values (None for any other study): for each variant and each horizon above
    2, a paired t-test over the seeds that finished both, on test success and on the training's
    CPU seconds. The claim holds when no longer horizon has a higher success (p < α, the report
    section's ``alpha``) and every one trains slower (p < α); it fails when a longer horizon
    succeeds more or trains faster; otherwise the seeds do not decide it."""
    from scipy import stats

    plan = outcome.plan
    if plan.grid_keys != ["agent.horizon"] or 2 not in plan.study.grid["agent.horizon"]:
        return None
    alpha = plan.params[plan.runs[0]].report.alpha
    by_point: dict[tuple[str, Any], dict[int, dict[str, float]]] = {}
    for run in plan.runs:
        result = outcome.results.get(run)
        if result and result.get("status") == "done":
            by_point.setdefault((run.variant, run.values[0][1]), {})[run.seed] = result["metrics"]
    lines, better, faster, undecided = [], [], [], []
    for variant in plan.study.variants:
        base = by_point.get((variant, 2), {})
        for horizon in plan.study.grid["agent.horizon"]:
            if horizon <= 2:
                continue
            other = by_point.get((variant, horizon), {})
            seeds = sorted(set(base) & set(other))
            line = f"- `{variant}`, horizon {horizon} against 2, {len(seeds)} paired seeds:"
            where = f"{variant} at {horizon}"
            if len(seeds) < 2:
                lines.append(f"{line} too few to test.")
                undecided.append(where)
                continue
            parts = []
            for metric, label in (("success", "success"), ("train_cpu_s", "training CPU s")):
                diffs = [other[s][metric] - base[s][metric] for s in seeds]
                diff = statistics.fmean(diffs)
                if statistics.stdev(diffs) > 0:
                    p = float(stats.ttest_1samp(diffs, 0.0).pvalue)  # the paired t-test
                else:  # the same difference on every seed
                    p = 1.0 if diff == 0 else 0.0
                shown = f"{diff:+.1%}" if metric == "success" else f"{diff:+.0f}"
                parts.append(f"{label} {shown} (p = {p:.3f})")
                significant = p < alpha
                if metric == "success" and significant and diff > 0:
                    better.append(where)
                if metric == "train_cpu_s":
                    if significant and diff < 0:
                        faster.append(where)
                    elif not (significant and diff > 0):
                        undecided.append(where)
            lines.append(f"{line} {'; '.join(parts)}.")
    if better or faster:
        verdict = (
            "does not hold ("
            + ", ".join(
                [*(f"{w} succeeds more" for w in better), *(f"{w} trains faster" for w in faster)]
            )
            + ")"
        )
    elif undecided:
        verdict = "not decided by these seeds (" + ", ".join(sorted(set(undecided))) + ")"
    else:
        verdict = "holds: no horizon above 2 succeeds more, and every one trains slower"
    return {"claim": HORIZON_CLAIM, "comparisons": lines, "verdict": verdict}


TRAINING_CLAIMS_NOTE = (
    "Checked as the report checks them (`socnav_wm/evaluation/claims.py`), on this study's "
    "seeds: per-seed final smoothed training return or episodes to solve, Mann–Whitney, Holm "
    "within each claim."
)


def training_claims(outcome: SweepResult) -> list[dict[str, Any]] | None:
    """The paper's training claims (``training-…`` in :data:`socnav_wm.evaluation.paper.CLAIMS`)
    checked on a study without a grid (one run per variant and seed, like the pipeline's, with
    more seeds), from its runs' training logs, with the report's rules and the report section's
    window and α; None for a study with a grid or fewer than two variants finished."""
    plan = outcome.plan
    if plan.grid_keys:
        return None
    import pyarrow.parquet as pq

    from socnav_wm.evaluation.claims import check_claims
    from socnav_wm.evaluation.paper import CLAIMS
    from socnav_wm.evaluation.results import training_summary

    logs: dict[str, dict[int, Any]] = {}
    for run in plan.runs:
        result = outcome.results.get(run)
        if result and result.get("status") == "done":
            path = plan.run_dir(run) / "training" / run.variant / f"seed-{run.seed}.parquet"
            logs.setdefault(run.variant, {})[run.seed] = pq.read_table(path)
    if len(logs) < 2:
        return None
    params = plan.params[plan.runs[0]]
    summary = training_summary(
        logs,
        window=params.report.smoothing_window,
        solved_window=params.agent.solved_window,
        solved_success_rate=params.agent.solved_success_rate,
    )
    claims = [c for c in CLAIMS if c.kind in ("training-better", "training-fastest")]
    results = check_claims({}, {}, summary, claims=claims, alpha=params.report.alpha)
    return [{"id": result.claim.claim_id, **result.to_dict()} for result in results]
