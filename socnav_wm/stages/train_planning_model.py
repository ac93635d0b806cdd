"""Stage ``train_planning_model``: the planning world model (constant velocity, the robot's own
motion exact, plus a learned correction of each human's velocity) on the rollouts, one seed."""

from __future__ import annotations

from functools import partial
from pathlib import Path
from typing import Any, Unpack

import torch

from socnav_wm.config import Params
from socnav_wm.layout import planning_model_file
from socnav_wm.stages.common import (
    StageOptions,
    WorldModelOutputs,
    log_torch_model,
    world_model_stage,
)
from socnav_wm.worldmodel.planning_file import save_residual
from socnav_wm.worldmodel.residual_training import fit_residual
from socnav_wm.worldmodel.served_planning import ServedPlanningModel


def run(
    params: Params,
    *,
    seed: int,
    rollouts: Path,
    out_dir: Path,
    metrics_dir: Path,
    **options: Unpack[StageOptions],
) -> str:
    p = params.planning_model
    if seed not in p.seeds:
        raise ValueError(f"seed {seed} is not in planning_model.seeds {p.seeds}")
    out = planning_model_file(out_dir, seed)
    outputs = WorldModelOutputs(
        out=out,
        metrics=metrics_dir / f"seed-{seed}.json",
        history=metrics_dir / f"seed-{seed}_history.json",
        **options,
    )
    run_name = f"train-planning-model/seed-{seed}"
    with world_model_stage("train_planning_model", run_name, params, outputs, (rollouts,)) as stage:
        result = stage.fit(p.max_epochs, partial(fit_residual, rollouts, params.env, p, seed=seed))
        summary: dict[str, Any] = {"seed": seed, **result.metrics}
        # An option left unset (None) is not recorded, so that the files of the models trained
        # before it existed (the paper preset's) stay byte-identical.
        settings = {"seed": seed, **{k: v for k, v in p.to_dict().items() if v is not None}}
        stage.publish(lambda path: save_residual(path, result, settings), summary, result.history)
        stage.run.log_headline(
            {
                "best_val_loss": result.metrics["val_loss"],
                "val_loss_constant_velocity": result.metrics["val_loss_constant_velocity"],
            },
            units={"best_val_loss": "m", "val_loss_constant_velocity": "m"},
        )
        served = ServedPlanningModel(result.model)
        log_torch_model(
            stage.run,
            served,
            torch.zeros(1, served.input_dim),
            ("scene", "velocity_change"),
            name=f"planning-model-seed-{seed}",
            model_type="planning-model",
        )
    m = result.metrics
    return (
        f"wrote {out}: {m['train_samples']} training samples; best epoch {m['best_epoch']} of "
        f"{m['epochs']}: validation error {m['val_loss']:.4f} m "
        f"(constant velocity {m['val_loss_constant_velocity']:.4f} m), "
        f"{m['cpu_seconds']:.0f} CPU-s"
    )
