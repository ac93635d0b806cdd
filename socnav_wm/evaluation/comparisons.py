"""Paired comparisons between methods (tests, intervals, Holm adjustment) and the Pareto
analysis of their means: the statistics behind the report's comparison table and its claims.

Statistics (see :mod:`socnav_wm.evaluation.stats` for the building blocks)
------------------------------------------------------------------------
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
  :data:`socnav_wm.metrics.METRIC_DIRECTIONS`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import pyarrow as pa
from scipy import stats as scipy_stats

from socnav_wm.evaluation.intervals import mean_ci_clustered
from socnav_wm.evaluation.results import MethodEvaluation
from socnav_wm.evaluation.stats import (
    dominated_by,
    holm,
    mcnemar,
    paired_proportion_difference,
    pareto_front,
    wilcoxon_signed_rank,
)
from socnav_wm.metrics import METRIC_DIRECTIONS, METRIC_UNITS, PAPER_METRICS

__all__ = [
    "PairedComparison",
    "clustered_mcnemar",
    "compare",
    "compare_with_reference",
    "pareto_analysis",
]


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
