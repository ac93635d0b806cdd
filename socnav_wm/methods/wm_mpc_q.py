"""``wm-mpc-q``: ``wm-mpc`` with a trained agent as its critic (its value at the horizon, its
greedy actions among the candidates; :mod:`socnav_wm.planning.critic`)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from socnav_wm.agents.agent_file import load_agent
from socnav_wm.env.params import EnvParams
from socnav_wm.methods import Method, PolicyFactory
from socnav_wm.methods.planners import planner_policies
from socnav_wm.planning.critic import AgentCritic
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
    """The planning model ``files["planning_model"]`` and the agent ``files["critic"]`` (a
    ``dueling-dqn`` file, on the CPU), each refused in one line when trained for other scenarios
    than ``env_params`` (in another world, unless ``transfer``)."""
    model = load_residual(files["planning_model"], env_params, transfer=transfer)
    path = files["critic"]
    critic = AgentCritic(load_agent(path, "cpu", env_params, transfer=transfer), env_params, path)
    return planner_policies(
        method, env_params, planning, lambda: ResidualPlanningModel(model, env_params), critic
    )
