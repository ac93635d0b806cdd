"""Confidence intervals, paired tests, Holm and Pareto on data whose answers are known by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from socnav_wm.evaluation.intervals import (
    is_binary,
    mean_ci,
    mean_ci_clustered,
    mean_ci_crossed,
    wilson_interval,
)
from socnav_wm.evaluation.stats import (
    discordant_odds_ratio,
    dominated_by,
    holm,
    mcnemar,
    paired_proportion_difference,
    pareto_front,
    wilcoxon_signed_rank,
)

# ------------------------------------------------------------------ mean_ci


def test_t_interval_by_hand():
    values = [2.0, 4.0, 4.0, 5.0, 7.0, 8.0]
    # mean 5, sample variance (9+1+1+0+4+9)/5 = 4.8, t_{0.975, 5} = 2.5706
    half = stats.t.ppf(0.975, 5) * math.sqrt(4.8 / 6)
    result = mean_ci(values, method="t")
    assert result.mean == pytest.approx(5.0)
    assert (result.low, result.high) == pytest.approx((5.0 - half, 5.0 + half))
    assert half == pytest.approx(2.5706 * 0.894427, rel=1e-4)
    assert result.n == 6
    assert result.method == "t"
    # 90% is narrower, with t_{0.95, 5}.
    narrow = mean_ci(values, confidence=0.90, method="t")
    assert narrow.high - narrow.mean == pytest.approx(stats.t.ppf(0.95, 5) * math.sqrt(0.8))


def test_wilson_interval_of_8_out_of_10_by_hand():
    # z = 1.959964: centre (0.8 + z²/20)/(1 + z²/10) = 0.716742,
    # half = z/(1 + z²/10)·sqrt(0.016 + z²/400) = 0.226580.
    low, high = wilson_interval(8, 10)
    assert (low, high) == pytest.approx((0.490162, 0.943318), abs=1e-6)
    result = mean_ci([1] * 8 + [0] * 2, method="wilson")
    assert result.mean == pytest.approx(0.8)
    assert (result.low, result.high) == pytest.approx((low, high))


def test_wilson_interval_stays_in_the_unit_interval_at_the_extremes():
    assert wilson_interval(0, 20)[0] == 0.0
    assert wilson_interval(20, 20)[1] == 1.0
    # 20/20: the lower limit is n/(n + z²) = 20/23.8415.
    assert wilson_interval(20, 20)[0] == pytest.approx(20 / (20 + 1.959964**2), rel=1e-6)


def test_auto_picks_wilson_for_binary_data_and_t_otherwise():
    assert mean_ci([0, 1, 1, 0, 1]).method == "wilson"
    assert mean_ci([True, False, True]).method == "wilson"
    assert mean_ci([0.0, 0.5, 1.0]).method == "t"
    assert is_binary([0.0, 1.0, math.nan])
    assert not is_binary([math.nan])


def test_nan_values_are_dropped_and_counted():
    # time_to_reach_goal: NaN for failed episodes.
    values = [10.0, math.nan, 20.0, 30.0, math.nan]
    result = mean_ci(values)
    assert result.n == 3
    assert result.mean == pytest.approx(20.0)
    half = stats.t.ppf(0.975, 2) * 10.0 / math.sqrt(3)
    assert (result.low, result.high) == pytest.approx((20.0 - half, 20.0 + half))
    # Binary with a NaN: Wilson on the 4 values left.
    binary = mean_ci([1.0, math.nan, 1.0, 0.0, 1.0])
    assert binary.n == 4
    assert binary.method == "wilson"
    assert (binary.low, binary.high) == pytest.approx(wilson_interval(3, 4))


def test_degenerate_samples():
    empty = mean_ci([math.nan, math.nan])
    assert empty.n == 0
    assert math.isnan(empty.mean) and math.isnan(empty.low)
    single = mean_ci([3.0])
    assert single.mean == 3.0 and math.isnan(single.low) and math.isnan(single.high)
    constant = mean_ci([2.0, 2.0, 2.0])
    assert (constant.low, constant.high) == (2.0, 2.0)


def test_bootstrap_interval_is_reproducible_and_close_to_t_for_normal_data():
    values = np.random.default_rng(1).normal(10.0, 2.0, size=400)
    boot = mean_ci(values, method="bootstrap", seed=3)
    assert boot == mean_ci(values, method="bootstrap", seed=3)
    t = mean_ci(values, method="t")
    assert boot.mean == pytest.approx(t.mean)
    assert boot.low == pytest.approx(t.low, abs=0.05)
    assert boot.high == pytest.approx(t.high, abs=0.05)


def test_bad_arguments():
    with pytest.raises(ValueError, match="confidence"):
        mean_ci([1.0, 2.0], confidence=95)
    with pytest.raises(ValueError, match="method"):
        mean_ci([1.0, 2.0], method="z")
    with pytest.raises(ValueError, match="0/1"):
        mean_ci([0.0, 0.5], method="wilson")


# ------------------------------------------------------------------ clustered and crossed


def seeds_by_scenarios(seed_effects, num_scenarios=300, seed=0):
    """Values = seed effect + scenario effect + noise, with their labels (flattened)."""
    rng = np.random.default_rng(seed)
    seed_effects = np.asarray(seed_effects, dtype=float)
    scenario_effects = rng.normal(0.0, 1.0, size=num_scenarios)
    values = seed_effects[:, None] + scenario_effects[None, :]
    values = values + rng.normal(0.0, 0.5, size=values.shape)
    seeds = np.repeat(np.arange(seed_effects.size), num_scenarios)
    scenarios = np.tile(np.arange(num_scenarios), seed_effects.size)
    return values.ravel(), scenarios, seeds


def test_cluster_t_interval_equals_a_t_interval_on_balanced_cluster_means():
    values = np.array([1.0, 3.0, 2.0, 6.0, 4.0, 5.0])
    clusters = np.array(["a", "a", "b", "b", "c", "c"])
    # Cluster means 2, 4, 4.5; with equal sizes the cluster-robust SE is sd(means)/sqrt(3).
    result = mean_ci_clustered(values, clusters, method="t")
    means = mean_ci([2.0, 4.0, 4.5], method="t")
    assert result.mean == pytest.approx(3.5)
    assert (result.low, result.high) == pytest.approx((means.low, means.high))
    assert result.n == 6
    assert result.method == "cluster-t"


def test_seed_clusters_widen_the_interval_when_seeds_differ():
    values, scenarios, seeds = seeds_by_scenarios([-1.0, 0.0, 1.0, 0.5, -0.5])
    naive = mean_ci(values)
    by_seed = mean_ci_clustered(values, seeds, method="bootstrap", seed=1)
    crossed = mean_ci_crossed(values, scenarios, seeds, seed=1)
    assert by_seed.mean == pytest.approx(naive.mean)
    assert crossed.mean == pytest.approx(naive.mean)
    assert by_seed.high - by_seed.low > 3 * (naive.high - naive.low)
    # The crossed interval has the seed spread plus the shared scenario noise.
    assert crossed.high - crossed.low > by_seed.high - by_seed.low


def test_crossed_bootstrap_with_one_seed_is_the_scenario_bootstrap():
    values, scenarios, seeds = seeds_by_scenarios([0.0], num_scenarios=500)
    crossed = mean_ci_crossed(values, scenarios, seeds, seed=2)
    t = mean_ci(values)
    assert crossed.n == 500
    assert crossed.low == pytest.approx(t.low, abs=0.03)
    assert crossed.high == pytest.approx(t.high, abs=0.03)
    # Scenario clusters of single values: the plain bootstrap.
    by_scenario = mean_ci_clustered(values, scenarios, seed=2)
    assert by_scenario.low == pytest.approx(t.low, abs=0.03)


def test_clustered_and_crossed_drop_nans():
    values = np.array([1.0, np.nan, 3.0, 5.0, np.nan, 7.0])
    scenarios = np.array([0, 1, 2, 0, 1, 2])
    seeds = np.array([0, 0, 0, 1, 1, 1])
    crossed = mean_ci_crossed(values, scenarios, seeds, n_resamples=500)
    assert crossed.n == 4
    assert crossed.mean == pytest.approx(4.0)
    assert crossed.low <= 4.0 <= crossed.high
    clustered = mean_ci_clustered(values, seeds, method="t")
    assert clustered.n == 4
    assert clustered.mean == pytest.approx(4.0)
    # One cluster only: no interval.
    single = mean_ci_clustered([1.0, 2.0], [0, 0])
    assert single.mean == 1.5 and math.isnan(single.low)


def test_labels_must_pair_with_values():
    with pytest.raises(ValueError, match="one label per value"):
        mean_ci_clustered([1.0, 2.0], [0])
    with pytest.raises(ValueError, match="seeds"):
        mean_ci_crossed([1.0, 2.0], [0, 1], [0])


# ------------------------------------------------------------------ McNemar


def pairs(n11: int, n10: int, n01: int, n00: int) -> tuple[np.ndarray, np.ndarray]:
    """Paired 0/1 outcomes (a, b) with the given counts of (a, b) = (1,1), (1,0), (0,1), (0,0)."""
    a = np.array([1] * n11 + [1] * n10 + [0] * n01 + [0] * n00, dtype=bool)
    b = np.array([1] * n11 + [0] * n10 + [1] * n01 + [0] * n00, dtype=bool)
    return a, b


def test_mcnemar_exact_by_hand():
    # 10 discordant pairs, 8 one way: p = 2·P(X ≤ 2), X ~ Bin(10, 1/2) = 2·(1 + 10 + 45)/1024.
    a, b = pairs(n11=30, n10=8, n01=2, n00=5)
    result = mcnemar(a, b)
    assert (result.b01, result.b10) == (2, 8)
    assert result.statistic == 2.0
    assert result.p_value == pytest.approx(112 / 1024)
    assert mcnemar(b, a).p_value == pytest.approx(112 / 1024)  # symmetric


def test_mcnemar_chi_square_with_continuity_correction():
    a, b = pairs(n11=100, n10=30, n01=12, n00=20)  # 42 discordant: the chi-square version
    result = mcnemar(a, b)
    statistic = (abs(12 - 30) - 1) ** 2 / 42  # 289 / 42
    assert result.statistic == pytest.approx(statistic)
    assert result.p_value == pytest.approx(stats.chi2.sf(statistic, 1))
    # Forced exact on the same table: 2·P(X ≤ 12), X ~ Bin(42, 1/2).
    exact = mcnemar(a, b, exact=True)
    assert exact.p_value == pytest.approx(2 * stats.binom.cdf(12, 42, 0.5))
    assert mcnemar(*pairs(5, 8, 2, 5), exact=False).statistic == pytest.approx(25 / 10)


def test_mcnemar_without_discordant_pairs_and_with_nans():
    a, b = pairs(n11=4, n10=0, n01=0, n00=3)
    assert mcnemar(a, b) == (0.0, 1.0, 0, 0)
    a = np.array([1.0, np.nan, 0.0, 1.0])
    b = np.array([0.0, 1.0, np.nan, 0.0])
    result = mcnemar(a, b)
    assert (result.b01, result.b10) == (0, 2)
    assert result.p_value == pytest.approx(0.5)  # 2·(1/2)²
    with pytest.raises(ValueError, match="0/1"):
        mcnemar([0.5, 1.0], [1.0, 1.0])
    with pytest.raises(ValueError, match="pair up"):
        mcnemar([1.0], [1.0, 0.0])


def test_paired_difference_and_odds_ratio_against_published_values():
    # Cavo et al. (2012), in Fagerland, Lydersen & Laake, "Statistical Analysis of Contingency
    # Tables", ch. 8: a = 59 + 6 of 161, b = 59 + 16. Newcombe: −0.0621 (−0.1186 to −0.0046);
    # transformed Wilson odds ratio 0.3750 (0.1514 to 0.9287).
    a, b = pairs(n11=59, n10=6, n01=16, n00=80)
    difference = paired_proportion_difference(a, b)
    assert difference.difference == pytest.approx(-10 / 161)
    assert (difference.low, difference.high) == pytest.approx((-0.1186, -0.0046), abs=1e-4)
    assert difference.n == 161
    odds = discordant_odds_ratio(a, b)
    assert odds.odds_ratio == pytest.approx(0.375)
    assert (odds.low, odds.high) == pytest.approx((0.1514, 0.9287), abs=1e-4)
    assert (odds.b01, odds.b10) == (16, 6)


def test_odds_ratio_by_hand_from_the_wilson_interval():
    a, b = pairs(n11=10, n10=8, n01=2, n00=10)
    low_q, high_q = wilson_interval(8, 10)
    odds = discordant_odds_ratio(a, b)
    assert odds.odds_ratio == 4.0
    assert odds.low == pytest.approx(low_q / (1 - low_q))
    assert odds.high == pytest.approx(high_q / (1 - high_q))
    assert discordant_odds_ratio(*pairs(3, 2, 0, 1)).odds_ratio == math.inf


# ------------------------------------------------------------------ Wilcoxon


def test_rank_biserial_by_hand():
    # Differences 1, 2, −3, 4: ranks 1, 2, 3, 4; T+ = 7, T− = 3, r = (7 − 3)/10 = 0.4.
    result = wilcoxon_signed_rank([1.0, 2.0, -3.0, 4.0], [0.0, 0.0, 0.0, 0.0])
    assert result.effect_size == pytest.approx(0.4)
    assert result.statistic == 3.0  # min(T+, T−)
    # Exact null distribution for n = 4 (16 sign patterns): T ≤ 3 for the positive-rank sets
    # {}, {1}, {2}, {3}, {1, 2}, so p = 2 · 5/16.
    assert result.p_value == pytest.approx(2 * 5 / 16)
    assert result.n == 4
    flipped = wilcoxon_signed_rank([0.0] * 4, [1.0, 2.0, -3.0, 4.0])
    assert flipped.effect_size == pytest.approx(-0.4)


def test_wilcoxon_matches_scipy_on_a_hand_example():
    # Integer data, so that tied differences are exactly tied.
    b = np.array([11.0, 10.0, 10.0, 12.0, 10.0, 11.0, 12.0, 9.0, 12.0, 10.0])
    a = b + np.array([3.0, -1.0, 4.0, 3.0, 2.0, 6.0, -2.0, 2.0, 8.0, 5.0])
    expected = stats.wilcoxon(a - b)
    result = wilcoxon_signed_rank(a, b)
    assert result.statistic == pytest.approx(expected.statistic)
    assert result.p_value == pytest.approx(expected.pvalue)
    d = a - b
    ranks = stats.rankdata(np.abs(d))
    t_plus, t_minus = ranks[d > 0].sum(), ranks[d < 0].sum()
    assert result.effect_size == pytest.approx((t_plus - t_minus) / (t_plus + t_minus))
    # |d| ranks: 1 → 1; 2, 2, 2 → 3 each; ...; the negatives −1 and −2 hold ranks 1 and 3, so
    # T− = 4, T+ = 55 − 4 and r = 1 − 2·4/55.
    assert result.effect_size == pytest.approx(1 - 2 * 4 / 55)


def test_wilcoxon_zeros_and_nans():
    a = np.array([3.0, 1.0, 2.0, 5.0, np.nan, 4.0])
    b = np.array([1.0, 1.0, 5.0, 1.0, 2.0, np.nan])
    # Pairs used: d = 2, 0, −3, 4. "wilcox" drops the zero: ranks of 2, 3, 4 are 1, 2, 3.
    result = wilcoxon_signed_rank(a, b)
    assert result.n == 4
    assert result.effect_size == pytest.approx((1 + 3 - 2) / 6)
    expected = stats.wilcoxon([2.0, 0.0, -3.0, 4.0], zero_method="wilcox")
    assert result.p_value == pytest.approx(expected.pvalue)
    # "pratt" ranks the zero too (rank 1), then drops it: T+ = 2 + 4, T− = 3.
    pratt = wilcoxon_signed_rank(a, b, zero_method="pratt")
    assert pratt.effect_size == pytest.approx((6 - 3) / 9)
    assert pratt.p_value == pytest.approx(
        stats.wilcoxon([2.0, 0.0, -3.0, 4.0], zero_method="pratt").pvalue
    )
    assert wilcoxon_signed_rank([1.0, 2.0], [1.0, 2.0]) == (0.0, 1.0, 0.0, 2)


# ------------------------------------------------------------------ Holm


def test_holm_by_hand():
    # Sorted 0.005, 0.01, 0.03, 0.04 times 4, 3, 2, 1 = 0.02, 0.03, 0.06, 0.04 → running max
    # 0.02, 0.03, 0.06, 0.06.
    result = holm([0.01, 0.04, 0.03, 0.005])
    np.testing.assert_allclose(result.adjusted, [0.03, 0.06, 0.06, 0.02])
    np.testing.assert_array_equal(result.reject, [True, False, False, True])
    # NaN stays outside the family (m = 2).
    result = holm([0.6, math.nan, 0.02])
    np.testing.assert_allclose(result.adjusted, [0.6, math.nan, 0.04])
    np.testing.assert_array_equal(result.reject, [False, False, True])
    np.testing.assert_allclose(holm([0.4, 0.5, 0.3]).adjusted, [0.9, 0.9, 0.9])
    # 0.4·3 = 1.2 is capped at 1.
    np.testing.assert_allclose(holm([0.4, 0.5, 0.45]).adjusted, [1.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="p_values"):
        holm([1.5])


# ------------------------------------------------------------------ Pareto


DIRECTIONS = {"success": "max", "collision": "min", "time": "min"}


def test_pareto_front_with_ties_and_mixed_directions():
    table = {
        "a": {"success": 0.9, "collision": 0.10, "time": 40.0},
        "b": {"success": 0.9, "collision": 0.10, "time": 45.0},  # a is as good, faster: dominated
        "c": {"success": 0.8, "collision": 0.05, "time": 50.0},  # fewest collisions: front
        "d": {"success": 0.9, "collision": 0.10, "time": 40.0},  # identical to a: both stay
        "e": {"success": 0.7, "collision": 0.20, "time": 60.0},  # dominated by everyone
        "f": {"success": 0.95, "collision": 0.30, "time": 70.0},  # best success: front
    }
    assert pareto_front(table, DIRECTIONS) == ["a", "c", "d", "f"]
    assert dominated_by(table, DIRECTIONS) == {"b": ["a", "d"], "e": ["a", "b", "c", "d"]}
    # Only success counts: a, b, d tie below f, which alone is on the front.
    assert pareto_front(table, {"success": "max"}) == ["f"]
    # Flip a direction: more time is now better; b now dominates a and d, and e joins the front.
    flipped = DIRECTIONS | {"time": "max"}
    assert pareto_front(table, flipped) == ["b", "c", "e", "f"]
    assert dominated_by(table, flipped) == {"a": ["b"], "d": ["b"]}


def test_pareto_front_rejects_bad_tables():
    with pytest.raises(ValueError, match="'max' or 'min'"):
        pareto_front({"a": {"success": 1.0}}, {"success": "up"})
    with pytest.raises(ValueError, match="no value for time"):
        pareto_front({"a": {"success": 1.0}}, {"success": "max", "time": "min"})
    with pytest.raises(ValueError, match="NaN for time"):
        pareto_front({"a": {"time": math.nan}}, {"time": "min"})
