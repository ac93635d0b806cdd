"""How the report writes numbers and tables: metric values, intervals, p-values, Markdown.

Shared by the report's text (:mod:`~socnav_wm.evaluation.rendering`,
:mod:`~socnav_wm.evaluation.model_sections`) and the claims' evidence
(:mod:`~socnav_wm.evaluation.claims`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

from socnav_wm.evaluation import paper
from socnav_wm.metrics import METRIC_DIRECTIONS, METRIC_UNITS

__all__ = ["direction_mark", "fmt_ci", "fmt_p", "fmt_value", "markdown_table"]


def fmt_value(metric: str, value: float) -> str:
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


def fmt_ci(metric: str, entry: Mapping[str, float]) -> str:
    """A ``{"mean", "low", "high"}`` entry as ``mean [low, high]`` (the mean alone without one)."""
    mean = fmt_value(metric, entry["mean"])
    if not (math.isfinite(entry["low"]) and math.isfinite(entry["high"])):
        return mean
    return f"{mean} [{fmt_value(metric, entry['low'])}, {fmt_value(metric, entry['high'])}]"


def fmt_p(p: float) -> str:
    """A p-value to two significant digits, ``<0.001`` below that, ``–`` when undefined."""
    if not math.isfinite(p):
        return "–"
    return f"{p:.2g}" if p >= 0.001 else "<0.001"


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    """A Markdown table's lines."""
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return lines


def direction_mark(metric: str) -> str:
    """``↑`` for a metric where higher is better, ``↓`` otherwise."""
    return "↑" if METRIC_DIRECTIONS[metric] == "max" else "↓"
