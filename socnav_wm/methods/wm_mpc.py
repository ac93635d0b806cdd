"""``wm-mpc``: model-predictive control on the learned planning model."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from socnav_wm.env.params import EnvParams
from socnav_wm.methods import Method, PolicyFactory
from socnav_wm.methods.planners import planner_policies
from socnav_wm.planning.params import PlanningParams
from socnav_wm.planning.residual import ResidualPlanningModel
from socnav_wm.worldmodel.planning_file import load_residual


def build(
    method: Method,
    env_params: EnvParams,
    *,
    files: Mapping[str, Path],
    planning: PlanningParams,
    transfer: bool,
) -> PolicyFactory:
    """The planning model ``files["planning_model"]`` (refused in one line when it was trained
    for other scenarios than ``env_params``; in another world, unless ``transfer``), a fresh
    copy for every batch."""
    model = load_residual(files["planning_model"], env_params, transfer=transfer)
    return planner_policies(
        method, env_params, planning, lambda: ResidualPlanningModel(model, env_params)
    )
