"""The report: the paper's table for every evaluated method, paired comparisons, Pareto analysis,
figures, and a claim-by-claim check of the paper against this run.

Inputs are the evaluation files (``data/eval/{method}.parquet`` and
``{method}-trajectories.parquet``, from :mod:`pipeline.evaluation.evaluate`) and the training
logs (``data/training/{variant}/seed-{seed}.parquet``, one row per episode). Outputs:
``reports/summary.md``, ``reports/pareto.json``, ``reports/claims.json`` (every claim's checks
and evidence), ``reports/figures/*.png``, ``reports/figures/scenarios.gif`` and
``metrics/report.json`` (means, intervals, p-values, Pareto set, claim verdicts). Any method may
be missing: the report says which, and every section uses what is there.

Statistics (see :mod:`pipeline.evaluation.stats` for the building blocks)
------------------------------------------------------------------------
* **Table.** Mean of each metric over scenarios × training seeds with a 95% two-way bootstrap
  interval (:func:`~pipeline.evaluation.evaluate.summarise`); per-seed means beside it.
* **Pairing.** Two methods are compared on the scenarios both ran. When both have the same
  training seeds (two agents trained with the same seeds, or two baselines) episode (seed s,
  scenario i) of one is paired with episode (s, i) of the other; otherwise (an agent against a
  baseline) every run of one on scenario i is paired with every run of the other on scenario i.
  Either way the pairs of one scenario share that scenario's difficulty, so the **scenario is
  the independent unit**: the tests below treat each scenario as a cluster of pairs, which keeps
  several seeds from inflating the evidence. With one pair per scenario they are the textbook
  tests.
* **Binary metrics** (success, human_collision, max_steps): McNemar's test (exact below 25
  discordant pairs) with Newcombe's interval for the difference of rates when each scenario
  holds one pair; the clustered McNemar test of Durkalski et al. (2003, Stat. Med. 22:2417),
  ``(Σ_k (b_k − c_k))² / Σ_k (b_k − c_k)²`` on 1 degree of freedom, with a cluster-robust
  interval for the difference of rates, when it holds several.
* **Other metrics:** the Wilcoxon signed-rank test on the per-scenario mean values (mean over the
  scenario's pairs), with the matched-pairs rank-biserial correlation as the effect size and a
  cluster-robust t interval for the mean difference.
* **Multiple comparisons.** Holm over the family "every method against the reference × the nine
  metrics"; each claim's checks form their own family, also Holm-adjusted.
* **Pareto.** On the means of the nine metrics, directions from
  :data:`pipeline.metrics.METRIC_DIRECTIONS`.

Claim verdicts (:data:`pipeline.evaluation.paper.CLAIMS`)
--------------------------------------------------------
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
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from scipy import stats as scipy_stats

from pipeline.agents.params import AgentParams
from pipeline.env.params import EnvParams
from pipeline.evaluation import paper
from pipeline.evaluation.evaluate import (
    AGENT_METHODS,
    BASELINE_SEED,
    METHODS,
    episode_from_trajectories,
    evaluation_metadata,
    per_seed_means,
    summarise,
)
from pipeline.evaluation.figures import (
    DEFAULT_SMOOTHING_WINDOW,
    histograms_figure,
    means_figure,
    scenarios_gif,
    smooth,
    training_curves_figure,
)
from pipeline.evaluation.stats import (
    dominated_by,
    holm,
    mcnemar,
    mean_ci_clustered,
    mean_ci_crossed,
    paired_proportion_difference,
    pareto_front,
    wilcoxon_signed_rank,
)
from pipeline.io import write_json_atomic, write_text_atomic
from pipeline.metrics import ALL_METRICS, METRIC_DIRECTIONS, METRIC_UNITS, PAPER_METRICS

__all__ = [
    "FIGURE_NAMES",
    "VERDICTS",
    "ClaimCheck",
    "ClaimResult",
    "MethodEvaluation",
    "PairedComparison",
    "ReportResult",
    "build_report",
    "check_claims",
    "clustered_mcnemar",
    "compare",
    "compare_with_reference",
    "load_evaluations",
    "load_training_returns",
    "pareto_analysis",
    "training_summary",
]

FIGURE_NAMES = ("training_curves.png", "histograms.png", "means.png", "scenarios.gif")
"""The files :func:`build_report` may write under ``reports/figures/``."""

VERDICTS = ("reproduced", "partly reproduced", "inconclusive", "not reproduced", "not testable")
"""Possible claim verdicts, from best to worst agreement."""


# --------------------------------------------------------------------------------------------
# Loading
# --------------------------------------------------------------------------------------------


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
        return self.method in AGENT_METHODS


def load_evaluations(
    eval_dir: str | Path,
    methods: Sequence[str] = METHODS,
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
    training_dir: str | Path, variants: Sequence[str] = AGENT_METHODS
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


# --------------------------------------------------------------------------------------------
# Paired comparisons
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PairedComparison:
    """``method`` against ``other`` on one metric, on the scenarios both ran.

    Attributes:
        method, other, metric: what is compared (differences are method − other).
        test: ``mcnemar``, ``clustered-mcnemar`` or ``wilcoxon``.
        pairing: ``seed+scenario`` (same seeds) or ``scenario`` (every run against every run).
        num_scenarios: scenarios (clusters) with at least one complete pair.
        num_pairs: pairs used.
        method_mean, other_mean: means over the pairs used.
        difference, low, high: mean difference method − other, with its 95% interval (rates
            for binary metrics).
        effect_size: rate difference (binary) or matched-pairs rank-biserial correlation
            (others; positive when the method's values tend to be larger).
        effect_name: what ``effect_size`` is.
        statistic, p_value: the test's.
        p_holm: Holm-adjusted p-value within its family (NaN until adjusted).
    """

    method: str
    other: str
    metric: str
    test: str
    pairing: str
    num_scenarios: int
    num_pairs: int
    method_mean: float
    other_mean: float
    difference: float
    low: float
    high: float
    effect_size: float
    effect_name: str
    statistic: float
    p_value: float
    p_holm: float = math.nan

    def favours(self) -> str | None:
        """Which side the mean difference favours (per METRIC_DIRECTIONS), None for a tie."""
        if not math.isfinite(self.difference) or self.difference == 0.0:
            return None
        higher_is_better = METRIC_DIRECTIONS[self.metric] == "max"
        return self.method if (self.difference > 0) == higher_is_better else self.other

    def verdict(self, alpha: float = 0.05) -> str:
        """``better`` / ``worse`` (the method, Holm-adjusted p ≤ alpha) or ``n.s.``."""
        if not (self.p_holm <= alpha):  # also NaN
            return "n.s."
        side = self.favours()
        if side is None:
            return "n.s."
        return "better" if side == self.method else "worse"


def clustered_mcnemar(
    a: np.ndarray, b: np.ndarray, clusters: np.ndarray
) -> tuple[float, float, int, int]:
    """Clustered McNemar test of Durkalski et al. (2003) for paired 0/1 outcomes.

    With ``b_k`` the pairs of cluster k where only ``a`` is 1 and ``c_k`` those where only ``b``
    is, ``X² = (Σ_k (b_k − c_k))² / Σ_k (b_k − c_k)²`` is chi-square with 1 degree of freedom
    under the null of equal rates, whatever the correlation within clusters. With one pair per
    cluster it is McNemar's statistic without continuity correction.

    Args:
        a, b: (n,) paired 0/1 values.
        clusters: (n,) the cluster (scenario) of each pair.

    Returns:
        ``(statistic, p_value, b01, b10)`` with b01 = #(a=0, b=1), b10 = #(a=1, b=0); p = 1 when
        the discordant pairs balance within every cluster.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    _, index = np.unique(np.asarray(clusters), return_inverse=True)
    only_a = ((a == 1) & (b == 0)).astype(np.float64)
    only_b = ((a == 0) & (b == 1)).astype(np.float64)
    per_cluster = np.bincount(index, weights=only_a - only_b)
    denominator = float(np.sum(per_cluster**2))
    b10, b01 = int(only_a.sum()), int(only_b.sum())
    if denominator == 0.0:
        return 0.0, 1.0, b01, b10
    statistic = float(per_cluster.sum() ** 2 / denominator)
    return statistic, float(scipy_stats.chi2.sf(statistic, 1)), b01, b10


def _pairs(a: pa.Table, b: pa.Table, metric: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """Paired values (a, b) and each pair's scenario, NaN pairs dropped (see module docstring)."""
    a_seed = a["training_seed"].to_numpy()
    b_seed = b["training_seed"].to_numpy()
    a_scenario = a["scenario_id"].to_numpy()
    b_scenario = b["scenario_id"].to_numpy()
    a_value = a[metric].to_numpy().astype(np.float64)
    b_value = b[metric].to_numpy().astype(np.float64)
    left: list[float] = []
    right: list[float] = []
    scenario: list[int] = []
    if set(a_seed.tolist()) == set(b_seed.tolist()):
        pairing = "seed+scenario"
        lookup = {
            (int(s), int(i)): float(v) for s, i, v in zip(b_seed, b_scenario, b_value, strict=True)
        }
        for s, i, v in zip(a_seed, a_scenario, a_value, strict=True):
            match = lookup.get((int(s), int(i)))
            if match is not None:
                left.append(float(v))
                right.append(match)
                scenario.append(int(i))
    else:
        pairing = "scenario"
        by_scenario: dict[int, list[float]] = {}
        for i, v in zip(b_scenario, b_value, strict=True):
            by_scenario.setdefault(int(i), []).append(float(v))
        for i, v in zip(a_scenario, a_value, strict=True):
            for match in by_scenario.get(int(i), []):
                left.append(float(v))
                right.append(match)
                scenario.append(int(i))
    left_array, right_array = np.array(left), np.array(right)
    keep = ~(np.isnan(left_array) | np.isnan(right_array))
    return left_array[keep], right_array[keep], np.array(scenario, dtype=np.int64)[keep], pairing


def _scenario_means(values: np.ndarray, index: np.ndarray, count: np.ndarray) -> np.ndarray:
    return np.bincount(index, weights=values) / count


def compare(a: pa.Table, b: pa.Table, metric: str) -> PairedComparison:
    """``a``'s method against ``b``'s on ``metric``, paired scenario by scenario.

    See the module docstring for the pairing and the tests; ``p_holm`` is left NaN.
    """
    method = a["method"][0].as_py() if a.num_rows else "?"
    other = b["method"][0].as_py() if b.num_rows else "?"
    left, right, scenario, pairing = _pairs(a, b, metric)
    n = int(left.size)
    _, index, count = np.unique(scenario, return_inverse=True, return_counts=True)
    num_scenarios = int(count.size)
    nan = math.nan
    if n == 0:
        return PairedComparison(
            method, other, metric, "none", pairing, 0, 0, nan, nan, nan, nan, nan, nan, "", nan, nan
        )
    difference = left - right
    clustered = mean_ci_clustered(difference, scenario, method="t")
    if METRIC_UNITS[metric] == "0/1":
        if np.all(count == 1):
            result = mcnemar(left, right)
            effect = paired_proportion_difference(left, right)
            test, statistic, p_value = "mcnemar", result.statistic, result.p_value
            low, high = effect.low, effect.high
        else:
            statistic, p_value, _, _ = clustered_mcnemar(left, right, scenario)
            test, low, high = "clustered-mcnemar", clustered.low, clustered.high
        effect_size, effect_name = float(difference.mean()), "rate difference"
    else:
        wilcoxon = wilcoxon_signed_rank(
            _scenario_means(left, index, count), _scenario_means(right, index, count)
        )
        test, statistic, p_value = "wilcoxon", wilcoxon.statistic, wilcoxon.p_value
        effect_size, effect_name = wilcoxon.effect_size, "rank-biserial r"
        low, high = clustered.low, clustered.high
    return PairedComparison(
        method=method,
        other=other,
        metric=metric,
        test=test,
        pairing=pairing,
        num_scenarios=num_scenarios,
        num_pairs=n,
        method_mean=float(left.mean()),
        other_mean=float(right.mean()),
        difference=float(difference.mean()),
        low=float(low),
        high=float(high),
        effect_size=float(effect_size),
        effect_name=effect_name,
        statistic=float(statistic),
        p_value=float(p_value),
    )


def _with_holm(comparisons: list[PairedComparison], alpha: float) -> list[PairedComparison]:
    if not comparisons:
        return []
    adjusted = holm([c.p_value for c in comparisons], alpha).adjusted
    return [
        PairedComparison(**{**asdict(c), "p_holm": float(p)})
        for c, p in zip(comparisons, adjusted, strict=True)
    ]


def compare_with_reference(
    evaluations: Mapping[str, MethodEvaluation],
    reference: str,
    metrics: Sequence[str] = PAPER_METRICS,
    alpha: float = 0.05,
) -> list[PairedComparison]:
    """Every other method against ``reference`` on every metric, Holm-adjusted as one family.

    Returns an empty list when the reference was not evaluated.
    """
    if reference not in evaluations:
        return []
    comparisons = [
        compare(evaluation.episodes, evaluations[reference].episodes, metric)
        for method, evaluation in evaluations.items()
        if method != reference
        for metric in metrics
    ]
    return _with_holm(comparisons, alpha)


# --------------------------------------------------------------------------------------------
# Pareto
# --------------------------------------------------------------------------------------------


def pareto_analysis(
    means: Mapping[str, Mapping[str, float]], metrics: Sequence[str] = PAPER_METRICS
) -> dict[str, Any]:
    """The Pareto non-dominated methods over ``metrics`` (by their means) and the dominators.

    Metrics with a NaN mean for some method cannot be compared and are left out (listed).

    Returns:
        ``{"metrics", "directions", "dropped_metrics", "front", "dominated_by"}``.
    """
    usable = [m for m in metrics if all(math.isfinite(means[x][m]) for x in means)]
    dropped = [m for m in metrics if m not in usable]
    directions = {m: METRIC_DIRECTIONS[m] for m in usable}
    table = {method: {m: means[method][m] for m in usable} for method in means}
    if not table or not usable:
        return {
            "metrics": usable,
            "directions": directions,
            "dropped_metrics": dropped,
            "front": list(table),
            "dominated_by": {},
        }
    return {
        "metrics": usable,
        "directions": directions,
        "dropped_metrics": dropped,
        "front": pareto_front(table, directions),
        "dominated_by": dominated_by(table, directions),
    }


# --------------------------------------------------------------------------------------------
# Training logs
# --------------------------------------------------------------------------------------------


def training_summary(
    logs: Mapping[str, Mapping[int, pa.Table]],
    *,
    window: int = DEFAULT_SMOOTHING_WINDOW,
    solved_window: int | None = None,
    solved_success_rate: float | None = None,
) -> dict[str, dict[str, Any]]:
    """Per variant and seed: episodes, final smoothed return, episodes to solve.

    The final smoothed return ("plateau") is the mean return of the last ``window`` episodes
    (the last point of the Fig. 6 curve). Episodes to solve is the project's definition
    (``pipeline.agents.dqn.episodes_to_solve``: first episode at which the success rate of the
    last ``solved_window`` episodes reaches ``solved_success_rate``; defaults from
    :class:`~pipeline.agents.params.AgentParams`), None when never reached.

    Returns:
        ``{variant: {"seeds": [...], "episodes": {seed: E}, "plateau": {seed: value},
        "episodes_to_solve": {seed: int | None}}}``.
    """
    if not logs:
        return {}
    # The project's one definition of "solved" (importing it imports torch: only when needed).
    from pipeline.agents.dqn import episodes_to_solve

    defaults = AgentParams()
    solved_window = solved_window or defaults.solved_window
    solved_success_rate = solved_success_rate or defaults.solved_success_rate
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


# --------------------------------------------------------------------------------------------
# Claims
# --------------------------------------------------------------------------------------------


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


def _fmt_p(p: float) -> str:
    if not math.isfinite(p):
        return "–"
    return f"{p:.2g}" if p >= 0.001 else "<0.001"


def _mann_whitney(a: Sequence[float], b: Sequence[float]) -> float:
    """Two-sided Mann–Whitney U p-value of per-seed values (NaN with < 2 a side).

    scipy's ``auto`` method: exact for small samples without ties, normal approximation with a
    tie correction otherwise.
    """
    if len(a) < 2 or len(b) < 2:
        return math.nan
    return float(scipy_stats.mannwhitneyu(a, b, alternative="two-sided").pvalue)


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
        training: :func:`training_summary` of the training logs.
        claims: the claims to check.
        alpha: family-wise error rate of each claim's tests (Holm within the claim).
    """
    results: list[ClaimResult] = []
    tested: list[ClaimCheck] = []  # the current claim's checks with a p-value: its Holm family

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
            f"{subject} {_fmt_value(metric, comparison.method_mean)} vs {other} "
            f"{_fmt_value(metric, comparison.other_mean)} ({comparison.test}, "
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
            complete = all(m in means for m in METHODS)
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
            check.evidence += f", p = {_fmt_p(check.p_value)}, Holm p = {_fmt_p(check.p_holm)})"
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


# --------------------------------------------------------------------------------------------
# Markdown
# --------------------------------------------------------------------------------------------


def _fmt_value(metric: str, value: float) -> str:
    """A metric value as the report prints it: rates in %, others to 2–3 significant places."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "–"
    if math.isinf(value):
        return "∞" if value > 0 else "−∞"
    if METRIC_UNITS.get(metric) == "0/1" or metric == paper.ANY_COLLISION:
        return f"{100.0 * value:.1f}%"
    if abs(value) >= 100:
        return f"{value:.0f}"
    if abs(value) >= 10:
        return f"{value:.1f}"
    return f"{value:.3f}" if abs(value) < 1 else f"{value:.2f}"


def _fmt_ci(metric: str, entry: Mapping[str, float]) -> str:
    mean = _fmt_value(metric, entry["mean"])
    if not (math.isfinite(entry["low"]) and math.isfinite(entry["high"])):
        return mean
    return f"{mean} [{_fmt_value(metric, entry['low'])}, {_fmt_value(metric, entry['high'])}]"


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return lines


def _direction_mark(metric: str) -> str:
    return "↑" if METRIC_DIRECTIONS[metric] == "max" else "↓"


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


def build_report(
    eval_dir: str | Path,
    training_dir: str | Path,
    out_dir: str | Path,
    metrics_path: str | Path,
    *,
    env_params: EnvParams | None = None,
    scenario_seed: int | None = None,
    reference: str = "dueling-dqn",
    methods: Sequence[str] = METHODS,
    gif_scenarios: Sequence[int] = (0, 1, 2),
    smoothing_window: int = DEFAULT_SMOOTHING_WINDOW,
    solved_window: int | None = None,
    solved_success_rate: float | None = None,
    alpha: float = 0.05,
    gif_size: int = 200,
    gif_max_frames: int = 60,
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
        reference: the method every other is compared with.
        methods: the methods to look for.
        gif_scenarios: test scenarios shown in ``figures/scenarios.gif`` (empty: no GIF).
        smoothing_window: rolling-mean window of the training curves, episodes.
        solved_window, solved_success_rate: the "solved" criterion of the training claims
            (defaults: :class:`~pipeline.agents.params.AgentParams`).
        alpha: family-wise error rate of the paired tests.
        gif_size: GIF cell side, px.
        gif_max_frames: frames per scenario in the GIF (long episodes are subsampled).

    Returns:
        A :class:`ReportResult`.

    Raises:
        ValueError: evaluation files made on different scenarios.
    """
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

    # -- machine-readable ----------------------------------------------------------------------
    content: dict[str, Any] = {
        "scenario_seed": scenario_seed,
        "episodes": num_scenarios,
        "reference": reference,
        "alpha": alpha,
        "methods_present": present,
        "methods_absent": absent,
        "methods": {
            m: {
                "training_seeds": evaluations[m].training_seeds,
                "metrics": summaries[m],
                "any_collision": any_collision[m],
                **(
                    {"per_seed": {f"seed-{s}": v for s, v in per_seed[m].items()}}
                    if m in per_seed
                    else {}
                ),
            }
            for m in present
        },
        "comparisons": {},
        "pareto": pareto,
        # Verdicts only: the checks behind them (lists of dicts, which `dvc metrics show`
        # cannot tabulate) go to reports/claims.json.
        "claims": {
            r.claim.claim_id: {"verdict": r.verdict, "statement": r.claim.statement} for r in claims
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
            for v, t in training.items()
        },
        "smoothing_window": smoothing_window,
    }
    for c in comparisons:
        entry = {k: v for k, v in asdict(c).items() if k not in ("method", "other", "metric")}
        entry["verdict"] = c.verdict(alpha)
        content["comparisons"].setdefault(c.method, {})[c.metric] = entry

    summary_md = _render_markdown(
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
        figure_paths=figure_paths,
        figure_notes=figure_notes,
        out_dir=out_dir,
        scenario_seed=scenario_seed,
        num_scenarios=num_scenarios,
        smoothing_window=smoothing_window,
        alpha=alpha,
    )
    summary_path = out_dir / "summary.md"
    pareto_path = out_dir / "pareto.json"
    claims_path = out_dir / "claims.json"
    write_text_atomic(summary_path, summary_md)
    write_json_atomic(pareto_path, {**pareto, "means": {m: means[m] for m in present}})
    write_json_atomic(claims_path, {r.claim.claim_id: r.to_dict() for r in claims})
    write_json_atomic(metrics_path, content)
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


def _render_markdown(
    *,
    evaluations: Mapping[str, MethodEvaluation],
    absent: Sequence[str],
    summaries: Mapping[str, Mapping[str, Mapping[str, float]]],
    per_seed: Mapping[str, Mapping[int, Mapping[str, float]]],
    any_collision: Mapping[str, Mapping[str, float]],
    comparisons: Sequence[PairedComparison],
    reference: str,
    pareto: Mapping[str, Any],
    claims: Sequence[ClaimResult],
    training: Mapping[str, Mapping[str, Any]],
    figure_paths: Sequence[Path],
    figure_notes: Sequence[str],
    out_dir: Path,
    scenario_seed: int | None,
    num_scenarios: int,
    smoothing_window: int,
    alpha: float,
) -> str:
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
            "better. Definitions: `pipeline/metrics.py` (the paper's intent, world frame).",
            "",
        ]
        header = ["method", "n"] + [f"{m} {_direction_mark(m)}" for m in PAPER_METRICS]
        rows = [
            [m, str(summaries[m]["success"]["n"])]
            + [_fmt_ci(k, summaries[m][k]) for k in PAPER_METRICS]
            for m in present
        ]
        lines += _table(header, rows) + [""]
        extra = [k for k in ALL_METRICS if k not in PAPER_METRICS]
        lines += ["Further metrics:", ""]
        header = ["method"] + [f"{m} {_direction_mark(m)}" for m in extra]
        rows = [[m] + [_fmt_ci(k, summaries[m][k]) for k in extra] for m in present]
        lines += _table(header, rows) + [""]
        lines += [
            "`time_to_reach_goal` is over successful episodes only; "
            "`personal_space_compliance_code` is the original code's definition (centre "
            "distance ≥ 2.02 m).",
            "",
        ]
        if per_seed:
            lines += [
                "### Per training seed",
                "",
                "With a handful of seeds the interval's seed component is estimated poorly: "
                "here is the spread itself.",
                "",
            ]
            header = ["method", "seed"] + list(PAPER_METRICS)
            rows = [
                [m, str(s)] + [_fmt_value(k, v[k]) for k in PAPER_METRICS]
                for m, seeds in per_seed.items()
                for s, v in seeds.items()
            ]
            lines += _table(header, rows) + [""]

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
                    _fmt_p(c.p_value),
                    _fmt_p(c.p_holm),
                    c.verdict(alpha),
                ]
            )
        lines += _table(header, rows) + [""]

    # -- Pareto --------------------------------------------------------------------------------
    lines += ["## Pareto analysis", ""]
    if present:
        metrics_text = ", ".join(f"{m} {_direction_mark(m)}" for m in pareto["metrics"])
        lines += [
            f"Over the means of: {metrics_text} (directions declared in "
            "`pipeline.metrics.METRIC_DIRECTIONS`). No statistical test: a method is dominated "
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
    lines += _paper_section(evaluations, summaries, any_collision, training, smoothing_window)
    lines += ["## The paper's claims, checked", ""]
    lines += [
        'Each claim is split into checks ("A beats B on a metric"), Holm-adjusted within the '
        f"claim (α = {alpha}). A claim is reproduced when all its testable checks are "
        "significant in the paper's direction, not reproduced when one is significant the "
        "other way; _inconclusive_ means no significant difference either way. Training "
        "claims compare per-seed values (Mann–Whitney): with fewer than 4–5 seeds a side "
        "they cannot be decided. Verdicts are computed from this run's data.",
        "",
    ]
    for result in claims:
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


def _fmt_difference(c: PairedComparison) -> str:
    def signed(x: float) -> str:
        text = _fmt_value(c.metric, x)
        return text if text.startswith(("-", "−", "–")) else f"+{text}"

    if not (math.isfinite(c.low) and math.isfinite(c.high)):
        return signed(c.difference)
    return f"{signed(c.difference)} [{_fmt_value(c.metric, c.low)}, {_fmt_value(c.metric, c.high)}]"


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
    for method in METHODS:
        if method not in evaluations or method not in paper.TEST_TARGETS:
            continue
        for label, target in paper.TEST_TARGETS[method].items():
            ours = (
                any_collision[method]
                if target.our_metric == paper.ANY_COLLISION
                else summaries[method][target.our_metric]
            )
            uncertainty = (
                f" ± {_fmt_value(target.our_metric, target.uncertainty)}"
                if target.uncertainty
                else ""
            )
            rows.append(
                [
                    f"{method} ({paper.PAPER_METHOD_NAMES[method]})",
                    label,
                    _fmt_value(target.our_metric, target.value) + uncertainty,
                    _fmt_ci(target.our_metric, ours),
                    "yes" if target.comparable else "no",
                    target.note,
                ]
            )
    if rows:
        lines += _table(header, rows) + [""]
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
        lines += _table(header, rows) + [""]
    return lines
