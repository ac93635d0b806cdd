"""Stage ``predict``: the world model's k-step prediction errors in metres
(:mod:`socnav_wm.worldmodel.prediction`), under the random policy and a trained agent's ε-greedy
one, for the paper's VAE + LSTM and the planning world model's seeds, to
``metrics/prediction.json``, MLflow and a figure of error against k."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from socnav_wm.agents.agent_file import load_agent
from socnav_wm.config import STAGE_SECTIONS, Params, params_dict, select_sections
from socnav_wm.evaluation.figures import prediction_figure
from socnav_wm.io import check_writable, outputs_together, write_json_atomic
from socnav_wm.stages.train_planning_model import model_path
from socnav_wm.tracking import stage_run
from socnav_wm.worldmodel.prediction import evaluate_prediction
from socnav_wm.worldmodel.residual import load_residual
from socnav_wm.worldmodel.training import load_lstm, load_vae


def run(
    params: Params,
    *,
    vae: Path,
    lstm: Path,
    agent: Path | None,
    planning_models: list[Path] | None = None,
    out: Path,
    figure: Path,
    tracking: bool = True,
) -> dict[str, Any]:
    """Measure with the ``prediction`` section's settings, write ``out`` and ``figure``
    together, log to MLflow; returns the errors. ``planning_models`` defaults to every seed of
    ``planning_model.seeds`` at its pipeline path."""
    check_writable(out, figure)
    if planning_models is None:
        planning_models = [model_path(seed) for seed in params.planning_model.seeds]
    settings = {
        **select_sections(params_dict(params), STAGE_SECTIONS["predict"]),
        "files": {
            "agent": str(agent) if agent else None,
            "planning_models": [str(path) for path in planning_models],
        },
    }
    p = params.prediction
    with stage_run("predict", settings, enabled=tracking) as mlflow_run:
        result = evaluate_prediction(
            params.env,
            world_model=(load_vae(vae), load_lstm(lstm)),
            agent=load_agent(agent) if agent is not None else None,
            episodes=p.episodes,
            scenario_seed=p.scenario_seed,
            warmup=p.warmup,
            horizon=p.horizon,
            epsilon=p.epsilon,
            planning_models=[load_residual(path) for path in planning_models],
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
