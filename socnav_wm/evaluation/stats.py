"""Paired tests against a reference method, multiple comparisons (Holm) and the Pareto front.

Pure functions of plain arrays; nothing here knows about methods, files or MLflow. The
confidence intervals of a method's mean are in :mod:`socnav_wm.evaluation.intervals` (its
docstring says which interval for which number, and how NaN values are treated: the same way
here).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Literal, NamedTuple

import numpy as np
from scipy import stats

from socnav_wm.evaluation.intervals import as_values, check_confidence, wilson_interval

__all__ = [
    "DiscordantOddsRatio",
    "HolmResult",
    "McNemarResult",
    "ProportionDifference",
    "WilcoxonResult",
    "discordant_odds_ratio",
    "dominated_by",
    "holm",
    "mcnemar",
    "paired_proportion_difference",
    "pareto_front",
    "wilcoxon_signed_rank",
]

MCNEMAR_EXACT_BELOW = 25
"""Fewer discordant pairs than this: exact binomial McNemar; otherwise chi-square (corrected)."""


class McNemarResult(NamedTuple):
    statistic: float
    """min(b01, b10) for the exact test; the corrected chi-square otherwise."""
    p_value: float
    b01: int
    """Pairs with a = 0 and b = 1."""
    b10: int
    """Pairs with a = 1 and b = 0."""


class WilcoxonResult(NamedTuple):
    statistic: float
    """scipy's statistic: min(T+, T−) for the two-sided test."""
    p_value: float
    effect_size: float
    """Matched-pairs rank-biserial correlation in [−1, 1]; positive when a tends to exceed b."""
    n: int
    """Pairs used (both values non-NaN; zero differences included)."""


class ProportionDifference(NamedTuple):
    difference: float
    """p_a − p_b, the difference of the two success rates over the same pairs."""
    low: float
    high: float
    n: int


class DiscordantOddsRatio(NamedTuple):
    odds_ratio: float
    """b10 / b01: how many times more often a alone succeeds than b alone."""
    low: float
    high: float
    b01: int
    b10: int


class HolmResult(NamedTuple):
    adjusted: np.ndarray
    """Holm-adjusted p-values, in the input order (NaN stays NaN)."""
    reject: np.ndarray
    """Whether each hypothesis is rejected at ``alpha`` (family-wise)."""


# --------------------------------------------------------------------------------------------
# Paired tests against a reference method (same scenarios)
# --------------------------------------------------------------------------------------------


def _paired_binary(a: np.ndarray | Sequence[float], b: np.ndarray | Sequence[float]):
    """(a, b) as bool arrays of the pairs where neither is NaN; both must be 0/1."""
    a_values = as_values(a, "a")
    b_values = as_values(b, "b")
    if a_values.shape != b_values.shape:
        raise ValueError(f"a and b must pair up: shapes {a_values.shape} and {b_values.shape}")
    keep = ~(np.isnan(a_values) | np.isnan(b_values))
    a_values, b_values = a_values[keep], b_values[keep]
    for name, array in (("a", a_values), ("b", b_values)):
        if not np.all((array == 0.0) | (array == 1.0)):
            raise ValueError(f"{name}: expected 0/1 (or boolean) values")
    return a_values.astype(bool), b_values.astype(bool)


def mcnemar(
    a: Sequence[float] | np.ndarray,
    b: Sequence[float] | np.ndarray,
    *,
    exact: bool | None = None,
) -> McNemarResult:
    """McNemar's test of equal success rates for paired 0/1 outcomes (two-sided).

    Only discordant pairs carry information: b01 (a failed, b succeeded) and b10 (a succeeded,
    b failed). Under the null each discordant pair goes either way with probability 1/2.

    Args:
        a: (n,) 0/1 outcomes of one method, pair i on scenario i (NaN pairs are dropped).
        b: (n,) 0/1 outcomes of the reference on the same scenarios.
        exact: True: exact binomial test, p = min(1, 2·P(X ≤ min(b01, b10))), X ~ Bin(b01 + b10,
            1/2); False: chi-square with continuity correction, (|b01 − b10| − 1)²/(b01 + b10)
            on 1 degree of freedom; None (default): exact when there are fewer than 25
            discordant pairs, where the chi-square approximation is poor.

    Returns:
        ``McNemarResult(statistic, p_value, b01, b10)``; p = 1 without discordant pairs.
    """
    a_bool, b_bool = _paired_binary(a, b)
    b01 = int(np.count_nonzero(~a_bool & b_bool))
    b10 = int(np.count_nonzero(a_bool & ~b_bool))
    discordant = b01 + b10
    if exact is None:
        exact = discordant < MCNEMAR_EXACT_BELOW
    if discordant == 0:
        return McNemarResult(0.0, 1.0, b01, b10)
    if exact:
        smaller = min(b01, b10)
        p_value = min(1.0, 2.0 * stats.binom.cdf(smaller, discordant, 0.5))
        return McNemarResult(float(smaller), float(p_value), b01, b10)
    statistic = (abs(b01 - b10) - 1.0) ** 2 / discordant
    return McNemarResult(float(statistic), float(stats.chi2.sf(statistic, 1)), b01, b10)


def paired_proportion_difference(
    a: Sequence[float] | np.ndarray,
    b: Sequence[float] | np.ndarray,
    confidence: float = 0.95,
) -> ProportionDifference:
    """Difference of paired success rates p_a − p_b with Newcombe's square-and-add interval.

    Newcombe (1998, Stat. Med. 17:2635, method 10): the Wilson intervals (l_i, u_i) of the two
    rates are combined with the continuity-corrected correlation φ of the paired table, e.g.
    low = D − sqrt((p_a − l_a)² − 2φ(p_a − l_a)(u_b − p_b) + (u_b − p_b)²). It keeps good
    coverage near 0 and 1, where the Wald interval does not. The effect size to report next to
    :func:`mcnemar`.

    Args:
        a, b: (n,) paired 0/1 outcomes (NaN pairs dropped).

    Returns:
        ``ProportionDifference(difference, low, high, n)``.
    """
    check_confidence(confidence)
    a_bool, b_bool = _paired_binary(a, b)
    n = int(a_bool.size)
    if n == 0:
        return ProportionDifference(math.nan, math.nan, math.nan, 0)
    both = int(np.count_nonzero(a_bool & b_bool))
    only_a = int(np.count_nonzero(a_bool & ~b_bool))
    only_b = int(np.count_nonzero(~a_bool & b_bool))
    neither = n - both - only_a - only_b
    successes_a, successes_b = both + only_a, both + only_b
    p_a, p_b = successes_a / n, successes_b / n
    low_a, high_a = wilson_interval(successes_a, n, confidence)
    low_b, high_b = wilson_interval(successes_b, n, confidence)
    margins = float(successes_a) * (n - successes_a) * successes_b * (n - successes_b)
    cross = float(both) * neither - float(only_a) * only_b
    if margins == 0.0:
        phi = 0.0
    elif cross > n / 2.0:
        phi = (cross - n / 2.0) / math.sqrt(margins)
    elif cross >= 0.0:
        phi = 0.0
    else:
        phi = cross / math.sqrt(margins)
    difference = p_a - p_b
    da, ub = p_a - low_a, high_b - p_b
    db, ua = p_b - low_b, high_a - p_a
    low = difference - math.sqrt(max(0.0, da * da - 2.0 * phi * da * ub + ub * ub))
    high = difference + math.sqrt(max(0.0, db * db - 2.0 * phi * db * ua + ua * ua))
    return ProportionDifference(float(difference), max(-1.0, low), min(1.0, high), n)


def discordant_odds_ratio(
    a: Sequence[float] | np.ndarray,
    b: Sequence[float] | np.ndarray,
    confidence: float = 0.95,
) -> DiscordantOddsRatio:
    """Conditional odds ratio b10/b01 of the discordant pairs, with a transformed Wilson interval.

    Given the discordant pairs, the share q = b10/(b01 + b10) where a alone succeeds is
    binomial; its Wilson interval (l, u) maps to the odds ratio's as (l/(1−l), u/(1−u))
    (Fagerland, Lydersen & Laake 2013). An alternative effect size to
    :func:`paired_proportion_difference` for :func:`mcnemar`.

    Returns:
        ``DiscordantOddsRatio(odds_ratio, low, high, b01, b10)``; the ratio is inf when b01 = 0
        (and NaN, with a NaN interval, without discordant pairs).
    """
    check_confidence(confidence)
    a_bool, b_bool = _paired_binary(a, b)
    b01 = int(np.count_nonzero(~a_bool & b_bool))
    b10 = int(np.count_nonzero(a_bool & ~b_bool))
    discordant = b01 + b10
    if discordant == 0:
        return DiscordantOddsRatio(math.nan, math.nan, math.nan, b01, b10)
    ratio = math.inf if b01 == 0 else b10 / b01
    low_q, high_q = wilson_interval(b10, discordant, confidence)
    high = math.inf if high_q >= 1.0 else high_q / (1.0 - high_q)
    return DiscordantOddsRatio(float(ratio), float(low_q / (1.0 - low_q)), float(high), b01, b10)


def wilcoxon_signed_rank(
    a: Sequence[float] | np.ndarray,
    b: Sequence[float] | np.ndarray,
    *,
    zero_method: Literal["wilcox", "pratt"] = "wilcox",
) -> WilcoxonResult:
    """Wilcoxon signed-rank test of a − b on paired values (two-sided), with its effect size.

    The test is ``scipy.stats.wilcoxon`` (exact for small samples without ties, normal
    approximation with tie correction otherwise). ``zero_method="wilcox"`` (default, Wilcoxon's
    original) drops zero differences before ranking, so the test is about the pairs where the
    methods differ; ``"pratt"`` ranks them too and then drops them, which is more conservative
    when many pairs tie (e.g. idle time 0 for both). The effect size is the matched-pairs
    rank-biserial correlation r = (T+ − T−)/(T+ + T−) (Kerby 2014), computed on the same ranks
    as the test: the share of rank mass favouring a > b minus the share favouring a < b.

    Args:
        a: (n,) one method's values; b: (n,) the reference's, pair i on scenario i. Pairs with a
            NaN on either side are dropped.
        zero_method: how zero differences are handled (see above).

    Returns:
        ``WilcoxonResult(statistic, p_value, effect_size, n)``; statistic 0, p 1 and effect 0
        when every difference is zero.
    """
    if zero_method not in ("wilcox", "pratt"):
        raise ValueError(f"zero_method: expected wilcox or pratt, got {zero_method!r}")
    a_values = as_values(a, "a")
    b_values = as_values(b, "b")
    if a_values.shape != b_values.shape:
        raise ValueError(f"a and b must pair up: shapes {a_values.shape} and {b_values.shape}")
    keep = ~(np.isnan(a_values) | np.isnan(b_values))
    difference = a_values[keep] - b_values[keep]
    n = int(difference.size)
    if n == 0:
        return WilcoxonResult(math.nan, math.nan, math.nan, 0)
    nonzero = difference != 0.0
    if not np.any(nonzero):
        return WilcoxonResult(0.0, 1.0, 0.0, n)
    # Ranks as scipy computes them: of |d| over the non-zero differences ("wilcox") or over all
    # of them ("pratt"), average ranks for ties; zeros never count in T+ or T−.
    ranked = difference[nonzero] if zero_method == "wilcox" else difference
    ranks = stats.rankdata(np.abs(ranked))
    signs = np.sign(ranked)
    t_plus = float(ranks[signs > 0].sum())
    t_minus = float(ranks[signs < 0].sum())
    effect = (t_plus - t_minus) / (t_plus + t_minus)
    result = stats.wilcoxon(difference, zero_method=zero_method, alternative="two-sided")
    return WilcoxonResult(float(result.statistic), float(result.pvalue), effect, n)


def holm(p_values: Sequence[float] | np.ndarray, alpha: float = 0.05) -> HolmResult:
    """Holm–Bonferroni step-down adjustment of a family of p-values.

    Sorted ascending, p_(i) is multiplied by (m − i + 1) and the running maximum is taken, so the
    adjusted values are monotone and rejecting those ≤ alpha controls the family-wise error rate
    at alpha without assuming independence. NaN p-values are not part of the family.

    Args:
        p_values: (m,) the family's p-values, e.g. every method × metric against the reference.
        alpha: family-wise error rate.

    Returns:
        ``HolmResult(adjusted, reject)``, in the input order.
    """
    p = as_values(p_values, "p_values")
    if np.any((p < 0.0) | (p > 1.0)):
        raise ValueError("p_values: must be in [0, 1]")
    adjusted = np.full(p.shape, np.nan)
    valid = np.flatnonzero(~np.isnan(p))
    m = valid.size
    if m:
        order = valid[np.argsort(p[valid], kind="stable")]
        scaled = p[order] * (m - np.arange(m))
        adjusted[order] = np.minimum(1.0, np.maximum.accumulate(scaled))
    reject = np.zeros(p.shape, dtype=bool)
    reject[valid] = adjusted[valid] <= alpha
    return HolmResult(adjusted, reject)


# --------------------------------------------------------------------------------------------
# Pareto analysis
# --------------------------------------------------------------------------------------------


def _oriented(
    table: Mapping[str, Mapping[str, float]], directions: Mapping[str, str]
) -> tuple[list[str], np.ndarray]:
    """Methods and a (methods, metrics) array where larger is better everywhere."""
    for metric, direction in directions.items():
        if direction not in ("max", "min"):
            raise ValueError(f"directions[{metric!r}]: expected 'max' or 'min', got {direction!r}")
    metrics = list(directions)
    methods = list(table)
    rows = []
    for method in methods:
        missing = [m for m in metrics if m not in table[method]]
        if missing:
            raise ValueError(f"method {method!r} has no value for {', '.join(missing)}")
        row = [float(table[method][m]) for m in metrics]
        if any(math.isnan(v) for v in row):
            bad = [m for m, v in zip(metrics, row, strict=True) if math.isnan(v)]
            raise ValueError(f"method {method!r} has NaN for {', '.join(bad)}; drop the metric")
        rows.append(row)
    sign = np.array([1.0 if directions[m] == "max" else -1.0 for m in metrics])
    return methods, np.array(rows).reshape(len(methods), len(metrics)) * sign


def dominated_by(
    table: Mapping[str, Mapping[str, float]], directions: Mapping[str, str]
) -> dict[str, list[str]]:
    """For each dominated method, the methods that dominate it (in table order).

    Method x dominates y when x is at least as good as y on every metric of ``directions`` and
    strictly better on at least one; methods with identical values do not dominate each other.

    Args:
        table: {method: {metric: value}}, e.g. the mean of each metric.
        directions: {metric: "max" | "min"}, the metrics to compare on (e.g.
            ``socnav_wm.metrics.METRIC_DIRECTIONS`` restricted to the paper's metrics).

    Returns:
        {dominated method: [dominating methods]}; methods on the front are absent.
    """
    methods, values = _oriented(table, directions)
    # at_least[x, y]: x ≥ y on every metric; better[x, y]: x > y on some metric.
    at_least = np.all(values[:, None, :] >= values[None, :, :], axis=-1)
    better = np.any(values[:, None, :] > values[None, :, :], axis=-1)
    dominates = at_least & better
    result: dict[str, list[str]] = {}
    for j, method in enumerate(methods):
        winners = [methods[i] for i in np.flatnonzero(dominates[:, j])]
        if winners:
            result[method] = winners
    return result


def pareto_front(
    table: Mapping[str, Mapping[str, float]], directions: Mapping[str, str]
) -> list[str]:
    """The non-dominated methods of ``table``, in table order (see :func:`dominated_by`)."""
    dominated = dominated_by(table, directions)
    return [method for method in table if method not in dominated]
