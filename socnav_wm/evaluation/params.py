"""The ``eval`` and ``report`` sections of ``params.yaml``: a light module (no torch, no pyarrow).

:mod:`socnav_wm.config` validates them into :class:`EvalParams` and :class:`ReportParams`, and
:func:`~socnav_wm.evaluation.evaluate.evaluate_method` and
:func:`~socnav_wm.evaluation.report.build_report` take them as they are.
"""

from __future__ import annotations

from typing import Annotated, ClassVar

from pydantic import Field, field_validator

from socnav_wm.method_names import check_method
from socnav_wm.section import Device, Section, Seed, seed_field

__all__ = ["EvalParams", "ReportParams"]


class EvalParams(Section):
    """The paired test: every method runs the same scenarios ``0..episodes-1``."""

    SECTION: ClassVar[str] = "eval"

    episodes: int = Field(500, gt=0)
    """Test scenarios per method and training seed (the paper: 500)."""
    scenario_seed: Seed = seed_field(1_000_003)
    """Seed of the test scenarios; training scenarios use other seeds (never these)."""
    batch_size: int = Field(500, gt=0)
    """Scenarios simulated together (speed only: results do not depend on it)."""
    device: Device = "auto"
    """Where the agents' networks run."""


class ReportParams(Section):
    """The report: paired tests, figures."""

    SECTION: ClassVar[str] = "report"

    reference: str = "dueling-dqn"
    """The method every other is compared with, scenario by scenario."""
    alpha: float = Field(0.05, gt=0, lt=1, allow_inf_nan=False)
    """Family-wise error rate of the paired tests (Holm-corrected)."""
    smoothing_window: int = Field(100, gt=0)
    """Rolling-mean window of the training curves (episodes)."""
    gif_scenarios: list[Annotated[int, Field(ge=0)]] = Field(default_factory=lambda: [0, 1, 2])
    """Test scenarios shown side by side in reports/figures/scenarios.gif (empty: no GIF)."""

    @field_validator("reference")
    @classmethod
    def _known_method(cls, value: str) -> str:
        return check_method(value)
