"""Confidence intervals of a method's mean: one run, clustered, or crossed seeds × scenarios.

Pure functions of plain arrays; nothing here knows about methods, files or MLflow. The paired
tests, Holm and the Pareto front are in :mod:`socnav_wm.evaluation.stats`.

Which interval for which number
-------------------------------
The evaluation runs every method on the same ``S`` test scenarios; each learned method has ``G``
training seeds (a baseline has one "seed": it is deterministic). A metric is then a ``G × S``
table per method, crossed: every seed meets every scenario.

* One run, one seed (a baseline, or one trained agent): :func:`mean_ci`. Wilson for 0/1 metrics
  (success, collisions, max-steps), Student t otherwise (``method="auto"`` picks).
* The method's table row, "over scenarios and training seeds": :func:`mean_ci_crossed`, a
  two-way ("pigeonhole") bootstrap that resamples seeds and scenarios independently. Both are
  random draws the claim should generalise over: another training run and other rooms. The
  one-way alternatives each drop one of them: clustering on seeds (:func:`mean_ci_clustered`
  with ``clusters=seeds``) conditions on the 500 scenarios, because every seed saw the same ones,
  so their noise is common to all seed means and never shows in their spread; clustering on
  scenarios conditions on the trained networks. With one seed, the crossed bootstrap is the
  scenario bootstrap. With a handful of seeds (3–5) the seed component is estimated poorly by any
  method, bootstrap included (its variance is biased low by (G − 1)/G): report the per-seed means
  beside the interval.
* Method vs reference on the same scenarios (:mod:`socnav_wm.evaluation.stats`):
  :func:`~socnav_wm.evaluation.stats.mcnemar` (0/1 metrics) with
  :func:`~socnav_wm.evaluation.stats.paired_proportion_difference` or
  :func:`~socnav_wm.evaluation.stats.discordant_odds_ratio` as the effect size, and
  :func:`~socnav_wm.evaluation.stats.wilcoxon_signed_rank` (others), then
  :func:`~socnav_wm.evaluation.stats.holm` over the family of comparisons.
  These pair episode by episode (same scenario, and same seed index when both have seeds), so
  they answer "do these trained policies behave differently on this scenario distribution" and
  condition on the trained networks; seed-to-seed variation is what the crossed interval shows.

NaN means "not defined for this episode" (``time_to_reach_goal`` of a failure) and is dropped,
with the number of values used reported; ±inf is kept and makes the mean infinite.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Literal, NamedTuple

import numpy as np
from scipy import stats

__all__ = [
    "MeanCI",
    "as_values",
    "check_confidence",
    "is_binary",
    "mean_ci",
    "mean_ci_clustered",
    "mean_ci_crossed",
    "wilson_interval",
]

CIMethod = Literal["auto", "t", "wilson", "bootstrap"]

DEFAULT_BOOTSTRAP_RESAMPLES = 4000


class MeanCI(NamedTuple):
    """A mean with its confidence interval.

    ``low``/``high`` are NaN when the interval is undefined (fewer than 2 values for a t or
    bootstrap interval); all three are NaN with ``n == 0``.
    """

    mean: float
    low: float
    high: float
    n: int
    """Number of (non-NaN) values used."""
    method: str
    """The interval actually computed: "t", "wilson", "bootstrap", "cluster-t",
    "cluster-bootstrap" or "crossed-bootstrap"."""


# --------------------------------------------------------------------------------------------
# Confidence intervals
# --------------------------------------------------------------------------------------------


def as_values(values: Sequence[float] | np.ndarray, name: str = "values") -> np.ndarray:
    array = np.asarray(values, dtype=np.float64)
    if array.ndim != 1:
        raise ValueError(f"{name}: expected a 1-d array, got shape {array.shape}")
    return array


def check_confidence(confidence: float) -> None:
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence: must be in (0, 1), got {confidence!r}")


def is_binary(values: Sequence[float] | np.ndarray) -> bool:
    """Whether every non-NaN value is 0 or 1 (and there is at least one)."""
    array = as_values(values)
    array = array[~np.isnan(array)]
    return array.size > 0 and bool(np.all((array == 0.0) | (array == 1.0)))


def wilson_interval(successes: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval for a binomial proportion ``successes / n``.

    (p + z²/2n ± z·sqrt(p(1−p)/n + z²/4n²)) / (1 + z²/n), z the normal quantile; unlike the
    Wald interval it stays inside [0, 1] and is not degenerate at 0 or n successes.
    """
    check_confidence(confidence)
    if n <= 0:
        return math.nan, math.nan
    if not 0 <= successes <= n:
        raise ValueError(f"successes: must be in 0..{n}, got {successes}")
    z = float(stats.norm.ppf(0.5 + confidence / 2.0))
    p = successes / n
    denominator = 1.0 + z * z / n
    centre = (p + z * z / (2.0 * n)) / denominator
    half = z / denominator * math.sqrt(p * (1.0 - p) / n + z * z / (4.0 * n * n))
    # Clamp rounding (e.g. 1 + 1e-17) so that 0/n and n/n give exactly 0 and 1.
    return max(0.0, centre - half), min(1.0, centre + half)


def _t_interval(values: np.ndarray, confidence: float) -> tuple[float, float]:
    n = values.size
    mean = float(np.mean(values))
    if n < 2:
        return math.nan, math.nan
    t = float(stats.t.ppf(0.5 + confidence / 2.0, n - 1))
    half = t * float(np.std(values, ddof=1)) / math.sqrt(n)
    return mean - half, mean + half


def _percentile(samples: np.ndarray, confidence: float) -> tuple[float, float]:
    samples = samples[~np.isnan(samples)]
    if samples.size == 0:
        return math.nan, math.nan
    low, high = np.quantile(samples, [0.5 - confidence / 2.0, 0.5 + confidence / 2.0])
    return float(low), float(high)


def mean_ci(
    values: Sequence[float] | np.ndarray,
    confidence: float = 0.95,
    method: CIMethod = "auto",
    *,
    n_resamples: int = DEFAULT_BOOTSTRAP_RESAMPLES,
    seed: int = 0,
) -> MeanCI:
    """Mean of ``values`` (NaN dropped) with a two-sided confidence interval.

    Args:
        values: (n,) one value per episode.
        confidence: coverage of the interval, e.g. 0.95.
        method: ``"t"``: Student t (mean ± t·s/√n), for continuous metrics; ``"wilson"``: Wilson
            score interval, for 0/1 metrics (the values must be 0 or 1); ``"bootstrap"``:
            percentile bootstrap of the mean (``n_resamples`` resamples from ``seed``), for
            skewed metrics; ``"auto"``: Wilson when the values are all 0/1, else t.
        n_resamples: bootstrap resamples.
        seed: seed of the bootstrap's generator (the interval is reproducible).

    Returns:
        ``MeanCI(mean, low, high, n, method)``.
    """
    check_confidence(confidence)
    array = as_values(values)
    array = array[~np.isnan(array)]
    n = int(array.size)
    if method == "auto":
        method = "wilson" if is_binary(array) else "t"
    if method not in ("t", "wilson", "bootstrap"):
        raise ValueError(f"method: expected auto, t, wilson or bootstrap, got {method!r}")
    if n == 0:
        return MeanCI(math.nan, math.nan, math.nan, 0, method)
    mean = float(np.mean(array))
    if method == "wilson":
        if not is_binary(array):
            raise ValueError("method 'wilson' needs 0/1 values")
        low, high = wilson_interval(int(array.sum()), n, confidence)
    elif method == "t":
        low, high = _t_interval(array, confidence)
    else:
        if n < 2:
            low, high = math.nan, math.nan
        else:
            rng = np.random.default_rng(seed)
            # Resample counts instead of indices: (B, n) multinomial weights, one matmul.
            counts = rng.multinomial(n, np.full(n, 1.0 / n), size=n_resamples)
            low, high = _percentile(counts @ array / n, confidence)
    return MeanCI(mean, float(low), float(high), n, method)


def _group_sums(
    values: np.ndarray, labels: np.ndarray, name: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-label sums and counts of the non-NaN values, and each value's label index."""
    labels = np.asarray(labels)
    if labels.shape != values.shape:
        raise ValueError(
            f"{name}: expected shape {values.shape} (one label per value), got {labels.shape}"
        )
    _, index = np.unique(labels, return_inverse=True)
    index = index.reshape(-1)
    present = ~np.isnan(values)
    sums = np.bincount(index[present], weights=values[present], minlength=index.max() + 1)
    counts = np.bincount(index[present], minlength=index.max() + 1).astype(np.float64)
    return sums, counts, index


def mean_ci_clustered(
    values: Sequence[float] | np.ndarray,
    clusters: Sequence[object] | np.ndarray,
    confidence: float = 0.95,
    method: Literal["bootstrap", "t"] = "bootstrap",
    *,
    n_resamples: int = DEFAULT_BOOTSTRAP_RESAMPLES,
    seed: int = 0,
) -> MeanCI:
    """Mean with a confidence interval that treats whole clusters as the independent units.

    Values in one cluster (one training seed, or one scenario across seeds) are correlated; the
    interval comes from the spread between clusters. The mean is the pooled mean of all non-NaN
    values (equal to the mean of cluster means for a balanced design).

    Args:
        values: (n,) one value per episode.
        clusters: (n,) the cluster label of each value (e.g. the training seed).
        method: ``"bootstrap"``: resample clusters with replacement (percentile interval of the
            pooled mean); ``"t"``: cluster-robust standard error of the pooled mean,
            sqrt(G/(G−1)·Σ_g (S_g − mean·n_g)²)/N, with a t quantile on G − 1 degrees of freedom,
            which is the safer choice for few clusters (G < 10).
        n_resamples: bootstrap resamples.
        seed: seed of the bootstrap's generator.

    Returns:
        ``MeanCI``; ``low``/``high`` are NaN with fewer than 2 non-empty clusters.
    """
    check_confidence(confidence)
    array = as_values(values)
    sums, counts, _ = _group_sums(array, clusters, "clusters")
    keep = counts > 0
    sums, counts = sums[keep], counts[keep]
    n = int(counts.sum())
    name = f"cluster-{method}"
    if method not in ("bootstrap", "t"):
        raise ValueError(f"method: expected bootstrap or t, got {method!r}")
    if n == 0:
        return MeanCI(math.nan, math.nan, math.nan, 0, name)
    mean = float(sums.sum() / n)
    g = sums.size
    if g < 2:
        return MeanCI(mean, math.nan, math.nan, n, name)
    if method == "t":
        se = math.sqrt(g / (g - 1) * float(np.sum((sums - mean * counts) ** 2))) / n
        half = float(stats.t.ppf(0.5 + confidence / 2.0, g - 1)) * se
        return MeanCI(mean, mean - half, mean + half, n, name)
    rng = np.random.default_rng(seed)
    weights = rng.multinomial(g, np.full(g, 1.0 / g), size=n_resamples).astype(np.float64)
    low, high = _percentile((weights @ sums) / (weights @ counts), confidence)
    return MeanCI(mean, low, high, n, name)


def mean_ci_crossed(
    values: Sequence[float] | np.ndarray,
    scenarios: Sequence[object] | np.ndarray,
    seeds: Sequence[object] | np.ndarray,
    confidence: float = 0.95,
    *,
    n_resamples: int = DEFAULT_BOOTSTRAP_RESAMPLES,
    seed: int = 0,
) -> MeanCI:
    """Mean over scenarios × training seeds with a two-way (crossed) bootstrap interval.

    The interval the report should use for a method's row (see the module docstring): seeds
    and scenarios are resampled independently with replacement, and each resample's mean is the
    pooled mean of the cells (seed, scenario) drawn, a cell drawn k times by seeds and l times by
    scenarios counting k·l times (Owen 2007, "the pigeonhole bootstrap"). It accounts for the
    variance of both random factors and their interaction, conservatively. With one seed it is
    the ordinary bootstrap over scenarios; with one scenario, over seeds.

    Args:
        values: (n,) one value per episode.
        scenarios: (n,) scenario id of each value.
        seeds: (n,) training seed of each value (any constant for a baseline).
        n_resamples: bootstrap resamples.
        seed: seed of the bootstrap's generator.

    Returns:
        ``MeanCI`` with method "crossed-bootstrap"; ``low``/``high`` are NaN when there is only
        one (seed, scenario) cell with data.
    """
    check_confidence(confidence)
    array = as_values(values)
    for name, labels in (("scenarios", scenarios), ("seeds", seeds)):
        if np.asarray(labels).shape != array.shape:
            raise ValueError(
                f"{name}: expected shape {array.shape} (one label per value), got "
                f"{np.asarray(labels).shape}"
            )
    _, scenario_index = np.unique(np.asarray(scenarios), return_inverse=True)
    _, seed_index = np.unique(np.asarray(seeds), return_inverse=True)
    scenario_index, seed_index = scenario_index.reshape(-1), seed_index.reshape(-1)
    num_scenarios = int(scenario_index.max()) + 1 if array.size else 0
    num_seeds = int(seed_index.max()) + 1 if array.size else 0
    present = ~np.isnan(array)
    n = int(present.sum())
    if n == 0:
        return MeanCI(math.nan, math.nan, math.nan, 0, "crossed-bootstrap")
    # (seeds, scenarios) tables of sums and counts: duplicates of a cell are pooled.
    cell_sums = np.zeros((num_seeds, num_scenarios))
    cell_counts = np.zeros((num_seeds, num_scenarios))
    np.add.at(cell_sums, (seed_index[present], scenario_index[present]), array[present])
    np.add.at(cell_counts, (seed_index[present], scenario_index[present]), 1.0)
    mean = float(cell_sums.sum() / n)
    if np.count_nonzero(cell_counts) < 2:
        return MeanCI(mean, math.nan, math.nan, n, "crossed-bootstrap")
    rng = np.random.default_rng(seed)
    seed_weights = rng.multinomial(
        num_seeds, np.full(num_seeds, 1.0 / num_seeds), size=n_resamples
    ).astype(np.float64)
    scenario_weights = rng.multinomial(
        num_scenarios, np.full(num_scenarios, 1.0 / num_scenarios), size=n_resamples
    ).astype(np.float64)
    numerator = np.einsum("bg,gs,bs->b", seed_weights, cell_sums, scenario_weights)
    denominator = np.einsum("bg,gs,bs->b", seed_weights, cell_counts, scenario_weights)
    with np.errstate(invalid="ignore", divide="ignore"):
        # A resample that drew only empty cells has no mean; it is left out (NaN).
        resampled = numerator / denominator
    low, high = _percentile(resampled, confidence)
    return MeanCI(mean, low, high, n, "crossed-bootstrap")
