"""The ``studies`` section of ``params.yaml``: named grids of agent runs (no torch, no Ray).

:mod:`socnav_wm.config` composes it into :class:`~socnav_wm.config.Params`; the rest of
:mod:`socnav_wm.studies` plans and runs them.
"""

from __future__ import annotations

from typing import Annotated, Any, ClassVar

from pydantic import AfterValidator, BeforeValidator, Field, field_validator

from socnav_wm.agents.params import VARIANT_NAMES, known_distinct_variants
from socnav_wm.section import Section, distinct_non_negative

__all__ = ["GridValue", "StudyParams", "default_studies"]

GridValue = bool | int | float | str


def _seed_range(value: Any) -> Any:
    """``"0-4"`` → ``[0, 1, 2, 3, 4]`` (the CLI's spelling); lists pass through."""
    if isinstance(value, str):
        first, sep, last = value.partition("-")
        if not (sep and first.isdigit() and last.isdigit() and int(first) <= int(last)):
            raise ValueError(f"expected a list of seeds or a range like '0-4', got {value!r}")
        return list(range(int(first), int(last) + 1))
    return value


class StudyParams(Section):
    """One study: the agent runs ``variants`` × ``seeds`` × every combination of ``grid``'s
    values, each exactly ``socnav-wm train-agent --variant V --seed S --set KEY=VALUE …``
    followed by ``socnav-wm evaluate`` (``socnav-wm sweep --study NAME`` runs it)."""

    SECTION: ClassVar[str] = "studies.<name>"

    variants: Annotated[list[str], AfterValidator(known_distinct_variants)] = Field(min_length=1)
    """Agent variants of every grid point."""
    seeds: Annotated[
        list[int], BeforeValidator(_seed_range), AfterValidator(distinct_non_negative)
    ] = Field(min_length=1)
    """Training seeds of every grid point (a list, or a range such as ``0-4``)."""
    grid: dict[str, list[GridValue]] = Field(default_factory=dict)
    """Dotted ``params.yaml`` key → the values it takes (any key ``--set`` accepts); every
    combination is one grid point. Empty: the shipped parameters only."""
    overrides: list[str] = Field(default_factory=list)
    """``--set`` overrides applied to every run of the study before the grid's values."""

    @field_validator("grid")
    @classmethod
    def _non_empty_values(cls, value: dict[str, list[GridValue]]) -> dict[str, list[GridValue]]:
        for key, values in value.items():
            if not values:
                raise ValueError(f"{key}: lists no values")
            if len(set(map(repr, values))) != len(values):
                raise ValueError(f"{key}: a value is listed twice in {values}")
        return value


def default_studies() -> dict[str, StudyParams]:
    """The shipped studies (``params.yaml``'s ``studies:``, which a test compares)."""
    return {
        "horizon": StudyParams(
            variants=["2stepahead", "2stepahead-maspm"],
            seeds=[0, 1, 2, 3, 4],
            grid={"agent.horizon": [2, 4, 8, 16]},
        ),
        "seeds": StudyParams(variants=list(VARIANT_NAMES), seeds=[0, 1, 2, 3, 4]),
        "sort_humans": StudyParams(
            variants=["dueling-dqn"], seeds=[0, 1, 2], grid={"agent.sort_humans": [True, False]}
        ),
        # scenarios/dvc.yaml's scenario_dqn: the paper's question in a scenario preset.
        "presets": StudyParams(variants=list(VARIANT_NAMES), seeds=[0, 1, 2]),
    }
