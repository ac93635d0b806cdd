"""The report's figures: training curves (paper Fig. 6), metric histograms (Figs. 7–8), means
with confidence intervals, and an animated GIF of test scenarios for every method side by side.

Plain functions of arrays and recorded episodes, each writing one file atomically. matplotlib is
used through :class:`~matplotlib.figure.Figure` (never pyplot), so nothing depends on a display
or on global state, and every method keeps one colour in every figure (:data:`METHOD_COLORS`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from socnav_wm.evaluation.results import smooth
from socnav_wm.io import atomic_path
from socnav_wm.metrics import METRIC_UNITS

__all__ = [
    "METHOD_COLORS",
    "histograms_figure",
    "means_figure",
    "training_curves_figure",
]


METHOD_COLORS: dict[str, str] = {
    "dueling-dqn": "#1f77b4",
    "wm-dueling-dqn": "#ff7f0e",
    "2stepahead": "#2ca02c",
    "maspm": "#9467bd",
    "2stepahead-maspm": "#d62728",
    "orca": "#7f7f7f",
    "sfm": "#8c564b",
    "cv-mpc": "#17becf",
    "wm-mpc": "#bcbd22",
    "vae-lstm-mpc": "#e377c2",
    "oracle-mpc": "#000000",
}
"""One colour per method, the same in every figure."""

_FALLBACK_COLORS = ("#aec7e8", "#ffbb78", "#98df8a")


def _color(method: str, index: int) -> str:
    return METHOD_COLORS.get(method, _FALLBACK_COLORS[index % len(_FALLBACK_COLORS)])


def _save(figure: Figure, path: str | Path, dpi: int = 110) -> None:
    with atomic_path(path) as tmp:
        figure.savefig(tmp, dpi=dpi, bbox_inches="tight")


# --------------------------------------------------------------------------------------------
# Training curves
# --------------------------------------------------------------------------------------------


def training_curves_figure(
    returns: Mapping[str, Mapping[int, np.ndarray]],
    path: str | Path,
    *,
    window: int,
    paper_plateaus: Mapping[str, float] | None = None,
) -> None:
    """Smoothed return per training episode, one line per variant (the paper's Fig. 6).

    Each seed's returns are smoothed with :func:`smooth`; the line is the mean over seeds and
    the band their minimum–maximum, over the episodes every seed reached. The paper's plateaus
    are drawn as dotted lines in the variant's colour when given.

    Args:
        returns: variant → training seed → (E,) episode returns, in episode order.
        path: the PNG to write.
        window: rolling-mean window, episodes.
        paper_plateaus: variant → the paper's final smoothed return.
    """
    figure = Figure(figsize=(8.0, 4.8))
    axes = figure.add_subplot()
    for index, (variant, seeds) in enumerate(returns.items()):
        curves = [smooth(r, window) for r in seeds.values() if len(r)]
        if not curves:
            continue
        length = min(c.size for c in curves)
        stacked = np.stack([c[:length] for c in curves])
        episodes = np.arange(1, length + 1)
        color = _color(variant, index)
        label = f"{variant} ({len(curves)} seed{'s' if len(curves) > 1 else ''})"
        axes.plot(episodes, stacked.mean(axis=0), color=color, label=label, linewidth=1.5)
        if len(curves) > 1:
            axes.fill_between(
                episodes, stacked.min(axis=0), stacked.max(axis=0), color=color, alpha=0.2
            )
        if paper_plateaus and variant in paper_plateaus:
            axes.axhline(paper_plateaus[variant], color=color, linestyle=":", linewidth=1.0)
    axes.set_xlabel("training episode")
    axes.set_ylabel(f"return, rolling mean of {window} episodes")
    title = "Smoothed training return: mean over seeds, band = min–max"
    if paper_plateaus:
        title += "\n(dotted: the paper's plateaus, Fig. 6)"
    axes.set_title(title)
    axes.grid(alpha=0.3)
    if axes.lines:
        axes.legend(loc="lower right", fontsize="small")
    _save(figure, path)


# --------------------------------------------------------------------------------------------
# Test metrics
# --------------------------------------------------------------------------------------------


def _bin_edges(values: Sequence[np.ndarray], binary: bool, bins: int) -> np.ndarray:
    if binary:
        return np.array([-0.5, 0.5, 1.5])
    finite = np.concatenate([v[np.isfinite(v)] for v in values]) if values else np.zeros(0)
    if finite.size == 0:
        return np.array([-0.5, 0.5])
    low, high = float(finite.min()), float(finite.max())
    if low == high:
        return np.array([low - 0.5, high + 0.5])
    return np.linspace(low, high, bins + 1)


def histograms_figure(
    values: Mapping[str, Mapping[str, np.ndarray]],
    metrics: Sequence[str],
    path: str | Path,
    *,
    bins: int = 15,
    columns: int = 3,
) -> None:
    """One histogram panel per metric, the methods' bars side by side (the paper's Figs. 7–8).

    Bars show the fraction of a method's episodes in each bin (a method with five training
    seeds has five times the episodes of a baseline, so counts would not compare). Bins are
    shared by the methods of a panel; 0/1 metrics get the two bins 0 and 1. Unlike the paper's
    figures, no value is cut off. NaN values (undefined for that episode) are left out.

    Args:
        values: method → metric → (n,) per-episode values.
        metrics: the panels, in order.
        path: the PNG to write.
        bins: bins of a continuous metric.
        columns: panels per row.
    """
    rows = max(1, math.ceil(len(metrics) / columns))
    figure = Figure(figsize=(4.2 * columns, 3.0 * rows + 0.6))
    methods = list(values)
    for panel, metric in enumerate(metrics):
        axes = figure.add_subplot(rows, columns, panel + 1)
        data = [np.asarray(values[m][metric], dtype=np.float64) for m in methods]
        data = [d[~np.isnan(d)] for d in data]
        binary = METRIC_UNITS.get(metric) == "0/1"
        edges = _bin_edges(data, binary, bins)
        widths = np.diff(edges)
        slot = widths / (len(methods) + 1)
        for index, (method, column) in enumerate(zip(methods, data, strict=True)):
            if column.size == 0:
                continue
            # Clip ±inf into the outer bins so they are counted, not dropped.
            counts, _ = np.histogram(np.clip(column, edges[0], edges[-1]), bins=edges)
            axes.bar(
                edges[:-1] + slot * (index + 0.5),
                counts / column.size,
                width=slot,
                align="edge",
                color=_color(method, index),
                label=method,
            )
        if binary:
            axes.set_xticks([0, 1])
        unit = METRIC_UNITS.get(metric, "")
        axes.set_title(f"{metric} ({unit})" if unit else metric, fontsize="medium")
        axes.set_ylabel("fraction of episodes", fontsize="small")
        axes.tick_params(labelsize="small")
        axes.grid(axis="y", alpha=0.3)
    handles, labels = figure.axes[0].get_legend_handles_labels() if figure.axes else ([], [])
    if handles:
        figure.legend(handles, labels, loc="upper center", ncol=len(labels), fontsize="small")
    figure.subplots_adjust(top=1.0 - 0.6 / (3.0 * rows + 0.6), hspace=0.45, wspace=0.3)
    _save(figure, path)


def means_figure(
    summaries: Mapping[str, Mapping[str, Mapping[str, float]]],
    metrics: Sequence[str],
    path: str | Path,
    *,
    columns: int = 3,
) -> None:
    """Each method's mean and 95% interval, one panel per metric (a forest plot).

    Args:
        summaries: method → metric → ``{"mean", "low", "high"}`` (as from ``summarise``).
        metrics: the panels, in order.
        path: the PNG to write.
    """
    methods = list(summaries)
    rows = max(1, math.ceil(len(metrics) / columns))
    figure = Figure(figsize=(4.2 * columns, (0.35 * len(methods) + 1.0) * rows))
    for panel, metric in enumerate(metrics):
        axes = figure.add_subplot(rows, columns, panel + 1)
        for index, method in enumerate(methods):
            entry = summaries[method].get(metric)
            if entry is None or not math.isfinite(entry["mean"]):
                continue
            mean, low, high = entry["mean"], entry["low"], entry["high"]
            color = _color(method, index)
            if math.isfinite(low) and math.isfinite(high):
                axes.plot([low, high], [index, index], color=color, linewidth=2.0)
            axes.plot([mean], [index], "o", color=color)
        axes.set_yticks(range(len(methods)))
        axes.set_yticklabels(methods if panel % columns == 0 else [""] * len(methods))
        axes.set_ylim(len(methods) - 0.5, -0.5)
        unit = METRIC_UNITS.get(metric, "")
        axes.set_title(f"{metric} ({unit})" if unit else metric, fontsize="medium")
        axes.tick_params(labelsize="small")
        axes.grid(axis="x", alpha=0.3)
    figure.suptitle("Mean and 95% interval (bootstrap over scenarios × training seeds)")
    figure.subplots_adjust(hspace=0.6, wspace=0.15)
    _save(figure, path)


PREDICTION_FLOOR_M = 1e-4
"""Errors below this (the exact ego-motion of the goal) are drawn at it on the log axis."""


PREDICTOR_COLORS: dict[str, str] = {
    "copy-last": "#7f7f7f",
    "static": "#2ca02c",
    "constant-velocity": "#d62728",
    "vae-lstm": "#1f77b4",
}
"""One colour per predictor in the prediction figure."""


def prediction_figure(errors: Mapping[str, object], path: str | Path) -> None:
    """k-step prediction error (m, log scale) against k: one row per policy, goal and humans
    side by side, every predictor with its 95% interval (from
    :func:`socnav_wm.worldmodel.prediction.evaluate_prediction`)."""
    policies = errors["policies"]  # type: ignore[index]
    figure = Figure(figsize=(10, 3.4 * len(policies)))
    for row, (policy, result) in enumerate(policies.items()):  # type: ignore[union-attr]
        for column, part in enumerate(("goal", "humans")):
            axes = figure.add_subplot(len(policies), 2, 2 * row + column + 1)
            for index, (name, values) in enumerate(result["predictors"].items()):
                mean = np.maximum(np.asarray(values[part], dtype=float), PREDICTION_FLOOR_M)
                band = np.maximum(np.asarray(values[f"{part}_ci"], dtype=float), PREDICTION_FLOOR_M)
                color = PREDICTOR_COLORS.get(name, _color(name, index))
                axes.plot(result["k"], mean, "o-", color=color, markersize=3, label=name)
                axes.fill_between(result["k"], band[:, 0], band[:, 1], color=color, alpha=0.2)
            axes.set_yscale("log")
            axes.set_xlabel("steps ahead k (1 s each)")
            axes.set_ylabel(f"{part} error (m)")
            axes.set_title(f"{part}, {policy} policy", fontsize="medium")
            axes.grid(alpha=0.3, which="both")
            if row == 0 and column == 1:
                axes.legend(fontsize="small")
    figure.suptitle("Open-loop prediction error in the robot frame (mean and 95% interval)")
    figure.subplots_adjust(hspace=0.45)
    _save(figure, path)
