"""Every method's name, by kind: a light module (no torch, no robot controller).

The configuration checks method names here (``report.reference``), and so do the command line
and the report, without importing what runs a method; :mod:`socnav_wm.methods` is the registry
of what each method needs and how its policy is built.
"""

from __future__ import annotations

from socnav_wm.agents.params import VARIANT_NAMES
from socnav_wm.planning.params import PLANNER_NAMES

__all__ = [
    "BASELINE_NAMES",
    "METHOD_NAMES",
    "PAPER_METHOD_NAMES",
    "PLANNER_NAMES",
    "REPORTED_METHOD_NAMES",
    "VARIANT_NAMES",
    "check_method",
]

BASELINE_NAMES: tuple[str, ...] = ("orca", "sfm")
"""The two classic robot controllers evaluated next to the agents
(:mod:`socnav_wm.agents.baselines`, parameters in ``params.yaml``'s ``baselines``)."""

PAPER_METHOD_NAMES: tuple[str, ...] = (*VARIANT_NAMES, *BASELINE_NAMES)
"""The paper's seven methods: the agents (paper order), then the baselines."""

METHOD_NAMES: tuple[str, ...] = (*PAPER_METHOD_NAMES, *PLANNER_NAMES)
"""Every evaluated method: the paper's seven, then the planners (:mod:`socnav_wm.planning`)."""

REPORTED_METHOD_NAMES: tuple[str, ...] = tuple(m for m in METHOD_NAMES if m != "wm-mpc-q")
"""The methods the paper's pipeline (``dvc.yaml``) evaluates and its report looks for: every
method but ``wm-mpc-q``, which is evaluated where its critic is trained, in a scenario preset
(``scenarios/dvc.yaml``), and whose absence from the paper's room is no gap in its report."""


def check_method(name: str, label: str | None = None) -> str:
    """``name`` if it is a method's, else a one-line ValueError naming the choices: ``{label}:
    unknown 'name'; …``, or ``unknown method 'name'; …`` without a label."""
    if name not in METHOD_NAMES:
        what = f"{label}: unknown" if label else "unknown method"
        raise ValueError(f"{what} {name!r}; expected one of {', '.join(METHOD_NAMES)}")
    return name
