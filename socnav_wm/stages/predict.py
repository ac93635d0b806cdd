"""Stage ``predict``: the world model's k-step prediction errors in metres
(:mod:`socnav_wm.worldmodel.prediction`), under the random policy and a trained agent's ε-greedy
one, for the paper's VAE + LSTM and the planning world model's seeds, to
``metrics/prediction.json``, MLflow and a figure of error against k."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from socnav_wm.agents.agent_file import load_agent
from socnav_wm.config import STAGE_SECTIONS, Params, params_dict, select_sections
from socnav_wm.data.collect import PlannerFactory
from socnav_wm.evaluation.figures import prediction_figure
from socnav_wm.io import check_writable, outputs_together, write_json_atomic
from socnav_wm.tracking import stage_run
from socnav_wm.worldmodel.files import load_vae_lstm
from socnav_wm.worldmodel.planning_file import load_residual
from socnav_wm.worldmodel.prediction import error_table, evaluate_prediction


def run(
    params: Params,
    *,
    vae: Path | None,
    lstm: Path | None,
    agent: Path | None,
    planning_models: list[Path],
    out: Path,
    figure: Path,
    tracking: bool = True,
    transfer: bool = False,
    planner: tuple[str, PlannerFactory] | None = None,
) -> dict[str, Any]:
    """Measure with the ``prediction`` section's settings, write ``out`` and ``figure``
    together, log to MLflow; returns the errors. ``planning_models``: one file per training seed
    of the planning world model; ``vae`` and ``lstm`` None: without the paper's world model (a
    preset that has none of its own). Every model is loaded first, and refused in one line when it
    was made for other scenarios than ``params.env`` (in another world, unless ``transfer``:
    then the errors say how the models transfer). ``planner``: a planner's name and policies,
    to measure under its ε-greedy policy too (what a planning model meets when it plans)."""
    check_writable(out, figure)
    planners = [load_residual(path, params.env, transfer=transfer) for path in planning_models]
    world_model = None
    if vae is not None and lstm is not None:
        world_model = load_vae_lstm(vae, lstm, env_params=params.env, transfer=transfer)
    elif vae is not None or lstm is not None:
        raise ValueError("the world model needs both --vae and --lstm")
    policy = (
        load_agent(agent, env_params=params.env, transfer=transfer) if agent is not None else None
    )
    settings = {
        "transfer": transfer,
        "planner": None if planner is None else planner[0],
        **select_sections(params_dict(params), STAGE_SECTIONS["predict"]),
        "files": {
            "agent": str(agent) if agent else None,
            "planning_models": [str(path) for path in planning_models],
        },
    }
    with stage_run("predict", settings, enabled=tracking) as mlflow_run:
        result = evaluate_prediction(
            params.env,
            params.prediction,
            world_model=world_model,
            agent=policy,
            planner=planner,
            planning_models=planners,
        )
        with outputs_together(out, figure) as (out_tmp, figure_tmp):
            write_json_atomic(out_tmp, result)
            prediction_figure(result, figure_tmp)
        for policy, errors in result["policies"].items():
            for name, values in errors["predictors"].items():
                for k, goal, humans in zip(
                    errors["k"], values["goal"], values["humans"], strict=True
                ):
                    mlflow_run.log_metrics(
                        {f"{policy}.{name}.goal_m": goal, f"{policy}.{name}.humans_m": humans},
                        step=k,
                    )
        mlflow_run.log_artifact(out)
        mlflow_run.log_artifact(figure)
    return result


Table = tuple[str, list[dict[str, Any]], dict[str, str]]
"""A table to print: its title, its rows, and the format of each numeric column."""


def tables(result: Mapping[str, Any], ks: Sequence[int]) -> list[Table]:
    """The errors of :func:`run`'s ``result`` at ``ks`` steps ahead as tables, per policy: every
    predictor's mean error, the humans' error by whether they drew a new goal, and the planning
    model against constant velocity (the last two where the result has them)."""
    found: list[Table] = []
    for policy, errors in result["policies"].items():
        table = error_table(errors, ks)
        formats = {c: ".3f" for c in table[0] if c not in ("k", "n")} if table else {}
        found.append(
            (f"{policy} policy: mean error (m) k steps ahead", table, {"n": "d", **formats})
        )
        change = errors.get("goal_change")
        if change:
            rows = []
            for i, k in enumerate(errors["k"]):
                if k not in ks:
                    continue
                row: dict[str, Any] = {"k": k, "new goal": change["changed_share"][i]}
                for name, values in change["predictors"].items():
                    if name in ("constant-velocity", "planning-model"):
                        row[f"{name}: kept"] = values["kept"][i]
                        row[f"{name}: new"] = values["changed"][i]
                rows.append(row)
            found.append(
                (
                    f"{policy} policy: humans' error (m) by whether they drew a new goal",
                    rows,
                    {c: ".3f" for c in rows[0] if c != "k"} if rows else {},
                )
            )
        split = errors.get("interactions")
        if split:
            found.append(_interaction_table(policy, errors["k"], split, ks))
        versus = errors.get("planning_model")
        if versus:
            rows = [
                {"k": k, "difference": d, "low": ci[0], "high": ci[1], "verdict": v}
                for k, d, ci, v in zip(
                    errors["k"],
                    versus["difference"],
                    versus["difference_ci"],
                    versus["verdict"],
                    strict=True,
                )  # fmt: skip
                if k in ks
            ]
            found.append(
                (
                    f"{policy} policy: planning model − constant velocity, humans (m), "
                    f"{versus['seeds']} seeds",
                    rows,
                    {"difference": "+.4f", "low": "+.4f", "high": "+.4f"},
                )
            )
    return found


def _interaction_table(
    policy: str, all_ks: Sequence[int], split: Mapping[str, Any], ks: Sequence[int]
) -> Table:
    """The humans' error by what they met (``split``: a result's ``"interactions"``): the
    share who met it, constant velocity's and the planning model's error, and their paired
    difference with its interval where there is a planning model."""
    versus = split.get("planning_model", {})
    rows = []
    for k in ks:
        if k not in all_ks:
            continue
        i = all_ks.index(k)
        for name, share in split["share"].items():
            if not share[i]:
                continue
            row: dict[str, Any] = {"k": k, "met": name, "share": share[i]}
            for predictor in ("constant-velocity", "planning-model"):
                if predictor in split["predictors"]:
                    row[predictor] = split["predictors"][predictor][name][i]
            if name in versus:
                row["difference"] = versus[name]["difference"][i]
                row["low"], row["high"] = versus[name]["difference_ci"][i]
            rows.append(row)
    formats = {"share": ".3f", "constant-velocity": ".3f", "planning-model": ".3f"}
    formats.update({"difference": "+.4f", "low": "+.4f", "high": "+.4f"})
    title = (
        f"{policy} policy: humans' error (m) by what they met within "
        f"{split['distance']:g} m (a human may meet several)"
    )
    return title, rows, formats
