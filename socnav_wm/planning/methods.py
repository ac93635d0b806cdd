"""The planning methods by name: what each one plans with, and the files it needs.

:func:`planner_policy` gives the policy that :func:`socnav_wm.env.rollout.run_episodes` runs for
a batch of episodes that start together; the evaluation, the render command and the examples
all build planners here.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from socnav_wm.env.params import EnvParams
from socnav_wm.planning.params import PLANNER_NAMES, PlanningParams

MODEL_FILES: dict[str, dict[str, Path]] = {
    "cv-mpc": {},
    "wm-mpc": {"planning_model": Path("models/planning/seed-0.pt")},
    "vae-lstm-mpc": {"vae": Path("models/vae.pt"), "lstm": Path("models/lstm.pt")},
    "oracle-mpc": {},
}
"""The model files each planner reads, by role, at their pipeline paths (the defaults of
``socnav-wm evaluate``'s ``--planning-model``, ``--vae`` and ``--lstm``)."""

_MAKES = {
    "planning_model": "socnav-wm train-planning-model --seed 0",
    "vae": "socnav-wm train-vae",
    "lstm": "socnav-wm train-lstm",
}


def model_files(method: str, overrides: Mapping[str, str | Path] | None = None) -> dict[str, Path]:
    """``method``'s model files: :data:`MODEL_FILES`'s, replaced by ``overrides`` (by role).

    Raises:
        ValueError: an unknown planner, or an override of a role the planner does not have.
        FileNotFoundError: a file that is not there (naming the command that makes it).
    """
    if method not in PLANNER_NAMES:
        raise ValueError(f"unknown planner {method!r}; expected one of {', '.join(PLANNER_NAMES)}")
    files = dict(MODEL_FILES[method])
    for role, path in (overrides or {}).items():
        if role not in files:
            expected = ", ".join(files) or "none"
            raise ValueError(f"planner {method!r} reads no {role} file (it reads: {expected})")
        files[role] = Path(path)
    for role, path in files.items():
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such {role} file (make it: {_MAKES[role]})")
    return files


def planner_policy(
    method: str,
    env_params: EnvParams,
    planning: PlanningParams,
    files: Mapping[str, Path] | None = None,
) -> tuple[Callable[[Any], Any], bool]:
    """A fresh policy of planner ``method`` for one batch of episodes, and whether it reads the
    simulator (``oracle-mpc``) rather than the observations.

    Args:
        method: one of :data:`~socnav_wm.planning.params.PLANNER_NAMES`.
        env_params: the scenarios' parameters.
        planning: the ``planning`` section (its ``per_method`` entry for ``method`` applied
            here).
        files: the model files (:func:`model_files`); default: the pipeline's.
    """
    from socnav_wm.planning.mpc import Planner

    planning = planning.resolved(method)

    files = model_files(method) if files is None else dict(files)
    if method == "oracle-mpc":
        from socnav_wm.planning.oracle import OraclePlanner

        return OraclePlanner(planning, env_params).act, True
    if method == "cv-mpc":
        from socnav_wm.planning.models import ConstantVelocityModel

        model: Any = ConstantVelocityModel(env_params)
    elif method == "wm-mpc":
        from socnav_wm.worldmodel.residual import ResidualPlanningModel, load_residual

        model = ResidualPlanningModel(load_residual(files["planning_model"]), env_params)
    elif method == "vae-lstm-mpc":
        from socnav_wm.planning.vae_lstm import VaeLstmModel
        from socnav_wm.worldmodel.training import load_lstm, load_vae

        model = VaeLstmModel(load_vae(files["vae"]), load_lstm(files["lstm"]))
    else:
        raise ValueError(f"unknown planner {method!r}; expected one of {', '.join(PLANNER_NAMES)}")
    planner = Planner(model, planning, env_params)
    return planner.policy(), planner.reads_simulator
