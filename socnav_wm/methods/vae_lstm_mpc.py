"""``vae-lstm-mpc``: model-predictive control on the paper's world model (VAE + LSTM)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from socnav_wm.env.params import EnvParams
from socnav_wm.methods import Method, PolicyFactory
from socnav_wm.methods.planners import planner_policies
from socnav_wm.planning.params import PlanningParams
from socnav_wm.planning.vae_lstm import VaeLstmModel
from socnav_wm.worldmodel.files import load_vae_lstm


def build(
    method: Method,
    env_params: EnvParams,
    *,
    files: Mapping[str, Path],
    planning: PlanningParams,
    transfer: bool,
) -> PolicyFactory:
    """The VAE ``files["vae"]`` and LSTM ``files["lstm"]`` (refused in one line when they were
    trained for other scenarios than ``env_params`` (in another world: unless ``transfer``), or
    do not fit together), a fresh copy for every batch."""
    vae, lstm = load_vae_lstm(files["vae"], files["lstm"], env_params=env_params, transfer=transfer)
    return planner_policies(method, env_params, planning, lambda: VaeLstmModel(vae, lstm))
