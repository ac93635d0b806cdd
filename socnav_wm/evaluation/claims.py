"""The paper's claims (:data:`socnav_wm.evaluation.paper.CLAIMS`) checked against this run.

Verdicts
--------
A claim is a conjunction of checks ("A beats B on m"); a claim's checks are one Holm family. A
check is *reproduced* when its Holm-adjusted p-value is ≤ α and the difference favours the
paper's side, *contradicted* when it is ≤ α the other way, *inconclusive* otherwise, and *not
testable* when a method is missing. A claim is **reproduced** when all its testable checks are,
**not reproduced** when any is contradicted, **partly reproduced** when some are reproduced and
the rest inconclusive, **inconclusive** when none is decided, and **not testable** without any
testable check. Training claims compare per-seed values (final smoothed return; episodes to
reach the solved criterion) with a Mann–Whitney U test (exact without ties), which needs at
least 4 seeds a side to reach p < 0.05 (5 a side to survive Holm over a claim's four checks) —
with fewer they stay inconclusive, as they should. Pareto and rank claims compare means (no
test).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from scipy import stats as scipy_stats

from socnav_wm.evaluation import paper
from socnav_wm.evaluation.comparisons import compare, pareto_analysis
from socnav_wm.evaluation.formatting import fmt_p, fmt_value
from socnav_wm.evaluation.results import MethodEvaluation
from socnav_wm.evaluation.stats import holm
from socnav_wm.method_names import PAPER_METHOD_NAMES
from socnav_wm.metrics import METRIC_DIRECTIONS

__all__ = ["VERDICTS", "ClaimCheck", "ClaimResult", "check_claims"]

VERDICTS = ("reproduced", "partly reproduced", "inconclusive", "not reproduced", "not testable")
"""Possible claim verdicts, from best to worst agreement."""


@dataclass
class ClaimCheck:
    """One check of a claim: ``subject`` beats ``other`` on ``metric`` (or a rank, …).

    Attributes:
        subject, other, metric: what is checked.
        status: ``reproduced``, ``contradicted``, ``inconclusive`` or ``not testable``.
        evidence: one line with the numbers behind the status.
        p_value, p_holm: for tested checks (NaN otherwise).
    """

    subject: str
    other: str
    metric: str
    status: str = "not testable"
    evidence: str = ""
    p_value: float = math.nan
    p_holm: float = math.nan
    favours_subject: bool | None = None
    seeds_needed: int | None = None
    """For an undecided check over seeds: about how many seeds a side would decide it."""


@dataclass
class ClaimResult:
    """A claim of the paper and what this run says about it."""

    claim: paper.Claim
    verdict: str
    checks: list[ClaimCheck] = field(default_factory=list)
    note: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {
            "statement": self.claim.statement,
            "source": self.claim.source,
            "kind": self.claim.kind,
            "verdict": self.verdict,
            "note": self.note,
            "checks": [asdict(c) for c in self.checks],
        }


def _combine(checks: Sequence[ClaimCheck]) -> str:
    statuses = [c.status for c in checks if c.status != "not testable"]
    if not statuses:
        return "not testable"
    if "contradicted" in statuses:
        return "not reproduced"
    if all(s == "reproduced" for s in statuses):
        return "reproduced"
    if "reproduced" in statuses:
        return "partly reproduced"
    return "inconclusive"


def _mann_whitney(a: Sequence[float], b: Sequence[float]) -> float:
    """Two-sided Mann–Whitney U p-value of per-seed values (NaN with < 2 a side).

    scipy's ``auto`` method: exact for small samples without ties, normal approximation with a
    tie correction otherwise.
    """
    if len(a) < 2 or len(b) < 2:
        return math.nan
    return float(scipy_stats.mannwhitneyu(a, b, alternative="two-sided").pvalue)


MANN_WHITNEY_EFFICIENCY = 3 / math.pi
"""Mann–Whitney's asymptotic efficiency relative to the t-test on normal data (about 0.955)."""

MAX_SEEDS_NEEDED = 100
"""Above this many seeds a side, :func:`seeds_needed` just says "more"."""


def seeds_needed(
    a: Sequence[float], b: Sequence[float], alpha: float, power: float = 0.8
) -> int | None:
    """About how many seeds a side a two-sided Mann–Whitney test at ``alpha`` needs to detect
    the difference of means of ``a`` and ``b`` with probability ``power``, if the seeds spread
    as they do here (normal approximation: ``2 (z₁₋α/₂ + z_power)² σ² / Δ²``, σ the pooled
    standard deviation, divided by Mann–Whitney's efficiency), and at least the seeds at which
    the exact test can reach ``alpha`` at all. ``MAX_SEEDS_NEEDED + 1`` for
    a difference too small for that many, None with fewer than 2 seeds a side. An estimate
    from few seeds: a guide to the next study's size, not a test."""
    if len(a) < 2 or len(b) < 2:
        return None
    difference = abs(float(np.mean(a)) - float(np.mean(b)))
    pooled = (
        (np.var(a, ddof=1) * (len(a) - 1) + np.var(b, ddof=1) * (len(b) - 1))
        / (len(a) + len(b) - 2)
    ) ** 0.5
    if difference == 0:
        return MAX_SEEDS_NEEDED + 1
    z = scipy_stats.norm.ppf(1 - alpha / 2) + scipy_stats.norm.ppf(power)
    n = 2 * (z * float(pooled) / difference) ** 2 / MANN_WHITNEY_EFFICIENCY
    # However far apart, n seeds a side cannot beat the exact test's smallest p, 2 / C(2n, n).
    fewest = 2
    while 2 / math.comb(2 * fewest, fewest) > alpha:
        fewest += 1
    return int(min(max(math.ceil(n), fewest), MAX_SEEDS_NEEDED + 1))


def check_claims(
    evaluations: Mapping[str, MethodEvaluation],
    means: Mapping[str, Mapping[str, float]],
    training: Mapping[str, Mapping[str, Any]],
    *,
    claims: Sequence[paper.Claim] = paper.CLAIMS,
    alpha: float = 0.05,
) -> list[ClaimResult]:
    """Check the paper's claims against this run (see the module docstring for the rules).

    Args:
        evaluations: the evaluated methods.
        means: method → metric → mean (the table's means).
        training: :func:`~socnav_wm.evaluation.results.training_summary` of the training
            logs.
        claims: the claims to check.
        alpha: family-wise error rate of each claim's tests (Holm within the claim).
    """
    # The paper's claims are about its seven methods: others (the planners) do not enter its
    # comparisons, Pareto fronts and ranks.
    evaluations = {m: e for m, e in evaluations.items() if m in PAPER_METHOD_NAMES}
    means = {m: v for m, v in means.items() if m in PAPER_METHOD_NAMES}
    results: list[ClaimResult] = []
    tested: list[ClaimCheck] = []  # the current claim's checks with a p-value: its Holm family
    per_seed: dict[int, tuple[list[float], list[float]]] = {}  # id(check) → a seeds check's values

    def paired_check(subject: str, other: str, metric: str) -> ClaimCheck:
        check = ClaimCheck(subject, other, metric)
        if subject not in evaluations or other not in evaluations:
            missing = [m for m in (subject, other) if m not in evaluations]
            check.evidence = f"not evaluated: {', '.join(missing)}"
            return check
        comparison = compare(evaluations[subject].episodes, evaluations[other].episodes, metric)
        if comparison.num_pairs == 0:
            check.evidence = "no common scenarios"
            return check
        check.p_value = comparison.p_value
        side = comparison.favours()
        check.favours_subject = None if side is None else side == subject
        check.evidence = (
            f"{subject} {fmt_value(metric, comparison.method_mean)} vs {other} "
            f"{fmt_value(metric, comparison.other_mean)} ({comparison.test}, "
            f"{comparison.num_scenarios} scenarios"
        )
        tested.append(check)
        return check

    def seeds_check(
        subject: str, other: str, key: str, label: str, lower_is_better: bool
    ) -> ClaimCheck:
        check = ClaimCheck(subject, other, label)
        if subject not in training or other not in training:
            missing = [m for m in (subject, other) if m not in training]
            check.evidence = f"no training logs: {', '.join(missing)}"
            return check

        def values(variant: str) -> list[float]:
            entry = training[variant]
            raw = [entry[key][s] for s in entry["seeds"]]
            if key == "episodes_to_solve":
                # Never solved ranks after every solved run: one more than the longest log.
                never = max(entry["episodes"].values(), default=0) + 1
                return [float(v) if v is not None else float(never) for v in raw]
            return [float(v) for v in raw if v is not None]

        a, b = values(subject), values(other)
        if not a or not b:
            check.evidence = "empty training logs"
            return check
        mean_a, mean_b = float(np.mean(a)), float(np.mean(b))
        if mean_a != mean_b:
            check.favours_subject = (mean_a < mean_b) if lower_is_better else (mean_a > mean_b)
        check.p_value = _mann_whitney(a, b)
        per_seed[id(check)] = (a, b)
        check.evidence = (
            f"{subject} {mean_a:.3g} [{min(a):.3g}, {max(a):.3g}] vs {other} {mean_b:.3g} "
            f"[{min(b):.3g}, {max(b):.3g}] over {len(a)} and {len(b)} seeds (Mann–Whitney"
        )
        if math.isnan(check.p_value):
            check.status = "inconclusive"
            check.evidence += ": needs ≥ 2 seeds a side)"
        else:
            tested.append(check)
        return check

    for claim in claims:
        result = ClaimResult(claim, "not testable")
        tested.clear()
        if claim.kind in ("better", "best"):
            for subject in claim.subjects:
                others = claim.others or tuple(m for m in evaluations if m != subject)
                if claim.kind == "best" and subject not in evaluations:
                    check = ClaimCheck(subject, "every other method", ", ".join(claim.metrics))
                    check.evidence = f"not evaluated: {subject}"
                    result.checks.append(check)
                    continue
                for other in others:
                    for metric in claim.metrics:
                        result.checks.append(paired_check(subject, other, metric))
        elif claim.kind == "pareto":
            subject = claim.subjects[0]
            check = ClaimCheck(subject, "all", "nine paper metrics")
            if subject in means and len(means) > 1:
                analysis = pareto_analysis(means)
                dominators = analysis["dominated_by"].get(subject, [])
                check.status = "contradicted" if dominators else "reproduced"
                check.evidence = (
                    f"dominated by {', '.join(dominators)}"
                    if dominators
                    else f"on the front of {len(means)} methods: {', '.join(analysis['front'])}"
                )
            else:
                check.evidence = f"{subject} not evaluated, or no other method to compare with"
            result.checks.append(check)
        elif claim.kind == "rank":
            subject = claim.subjects[0]
            complete = all(m in means for m in PAPER_METHOD_NAMES)
            for metric, rank in claim.ranks:
                check = ClaimCheck(subject, "all seven", metric)
                if complete:
                    ours = _rank(means, subject, metric)
                    check.status = "reproduced" if ours == rank else "contradicted"
                    check.evidence = f"rank {ours} of {len(means)} (paper: {rank}), by means"
                else:
                    check.evidence = "needs all seven methods evaluated"
                result.checks.append(check)
        elif claim.kind in ("training-better", "training-fastest"):
            fastest = claim.kind == "training-fastest"
            key, label = (
                ("episodes_to_solve", "episodes to solve")
                if fastest
                else ("plateau", "final smoothed training return")
            )
            for subject in claim.subjects:
                for other in claim.others:
                    result.checks.append(seeds_check(subject, other, key, label, fastest))
        # The claim's tested checks are one Holm family: the claim holds only if all of them
        # do, so its family-wise error rate is what must be controlled.
        adjusted = holm([c.p_value for c in tested], alpha).adjusted if tested else []
        for check, p in zip(tested, adjusted, strict=True):
            check.p_holm = float(p)
            if p <= alpha and check.favours_subject is not None:
                check.status = "reproduced" if check.favours_subject else "contradicted"
            else:
                check.status = "inconclusive"
            check.evidence += f", p = {fmt_p(check.p_value)}, Holm p = {fmt_p(check.p_holm)})"
            needed = None
            if check.status == "inconclusive" and id(check) in per_seed:
                # At Holm's strictest threshold, α / m (Bonferroni's): a conservative size.
                needed = seeds_needed(*per_seed[id(check)], alpha / len(tested))
            if needed is not None:
                check.seeds_needed = needed
                more = (
                    f"about {needed}"
                    if needed <= MAX_SEEDS_NEEDED
                    else f"more than {MAX_SEEDS_NEEDED}"
                )
                check.evidence += f"; {more} seeds a side would decide it (80% power)"
        results.append(result)

    for result in results:
        result.verdict = _combine(result.checks)
        testable = [c for c in result.checks if c.status != "not testable"]
        if testable and len(testable) < len(result.checks):
            result.note = f"{len(testable)} of {len(result.checks)} checks testable"
    return results


def _rank(means: Mapping[str, Mapping[str, float]], method: str, metric: str) -> int:
    """1 + the number of methods strictly better than ``method`` on ``metric`` (by mean)."""
    sign = 1.0 if METRIC_DIRECTIONS[metric] == "max" else -1.0
    mine = sign * means[method][metric]
    return 1 + sum(1 for m in means if m != method and sign * means[m][metric] > mine)
