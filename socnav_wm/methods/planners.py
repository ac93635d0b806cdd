"""The planners' policies: model-predictive control on a prediction model, and the oracle.

:func:`planner_policies` is what every model-predictive planner shares; ``cv-mpc`` plans on
constant velocity (here), ``wm-mpc`` and ``vae-lstm-mpc`` on their learned models (their own
modules, so that only their stages depend on those models' code).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from socnav_wm.env.params import EnvParams
from socnav_wm.methods import Method, Policy, PolicyFactory
from socnav_wm.planning.params import PlanningParams


def planner_policies(
    method: Method,
    env_params: EnvParams,
    planning: PlanningParams,
    model: Callable[[], Any],
    critic: Any = None,
) -> PolicyFactory:
    """Planner ``method.name`` (its ``planning.per_method`` entry applied) on a fresh
    ``model()`` for every batch of episodes, with ``critic`` (``wm-mpc-q``'s agent) if any."""
    resolved = planning.resolved(method.name)
    if resolved.actions != "paper" and method.name != "cv-mpc":
        raise ValueError(
            f"planning.actions: {method.name}'s model imagines the paper's four actions; "
            "a lattice is for cv-mpc and oracle-mpc"
        )

    def fresh() -> tuple[Policy, bool]:
        from socnav_wm.planning.mpc import Planner

        planner = Planner(model(), resolved, env_params, critic)
        return planner.policy(), planner.reads_simulator

    return fresh


def constant_velocity(
    method: Method, env_params: EnvParams, *, files: Mapping[str, Path], planning: PlanningParams
) -> PolicyFactory:
    """``cv-mpc``: every human keeps their velocity."""
    from socnav_wm.planning.models import ConstantVelocityModel

    return planner_policies(method, env_params, planning, lambda: ConstantVelocityModel(env_params))


def oracle(
    method: Method, env_params: EnvParams, *, files: Mapping[str, Path], planning: PlanningParams
) -> PolicyFactory:
    """``oracle-mpc``: imagines with the simulator itself."""
    from socnav_wm.planning.oracle import OraclePlanner

    resolved = planning.resolved(method.name)
    return lambda: (OraclePlanner(resolved, env_params).act, True)
