"""``vae-lstm-mpc``: model-predictive control on the paper's world model (VAE + LSTM)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from socnav_wm.env.params import EnvParams
from socnav_wm.methods import Method, PolicyFactory
from socnav_wm.methods.planners import planner_policies
from socnav_wm.planning.params import PlanningParams
from socnav_wm.planning.vae_lstm import VaeLstmModel
from socnav_wm.worldmodel.files import load_lstm, load_vae


def build(
    method: Method, env_params: EnvParams, *, files: Mapping[str, Path], planning: PlanningParams
) -> PolicyFactory:
    """The VAE ``files["vae"]`` and LSTM ``files["lstm"]``, loaded for every batch."""
    vae, lstm = files["vae"], files["lstm"]
    return planner_policies(
        method, env_params, planning, lambda: VaeLstmModel(load_vae(vae), load_lstm(lstm))
    )
