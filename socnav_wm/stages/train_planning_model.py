"""Stage ``train_planning_model``: the planning world model (constant velocity, the robot's own
motion exact, plus a learned correction of each human's velocity) on the rollouts, one seed."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from socnav_wm.config import Params
from socnav_wm.io import check_writable
from socnav_wm.layout import planning_model_file
from socnav_wm.progress import progress
from socnav_wm.stages.common import (
    config_path,
    epoch_logger,
    log_torch_model,
    open_stage,
    world_model_outputs,
)
from socnav_wm.worldmodel.residual import fit_residual, save_residual


def run(
    params: Params,
    *,
    seed: int,
    rollouts: Path,
    out_dir: Path,
    metrics_dir: Path,
    tracking: bool = True,
    quiet: bool = True,
) -> str:
    p = params.planning_model
    if seed not in p.seeds:
        raise ValueError(f"seed {seed} is not in planning_model.seeds {p.seeds}")
    out = planning_model_file(out_dir, seed)
    metrics = metrics_dir / f"seed-{seed}.json"
    history = metrics_dir / f"seed-{seed}_history.json"
    check_writable(out, config_path(out), metrics, history)
    run_name = f"train-planning-model/seed-{seed}"
    with open_stage("train_planning_model", run_name, params, tracking=tracking) as run:
        with progress(p.max_epochs, run_name, quiet=quiet, unit="epochs") as bar:
            result = fit_residual(
                rollouts,
                params.env,
                p,
                seed=seed,
                on_epoch=epoch_logger(run, bar),
            )
        summary: dict[str, Any] = {"seed": seed, **result.metrics}
        settings = {"seed": seed, **p.to_dict()}
        world_model_outputs(
            "train_planning_model", run, params,
            lambda path: save_residual(path, result, settings),
            out, metrics, history, summary, result.history,
        )  # fmt: skip
        points = torch.zeros(1, 1 + result.model.num_humans, 2)
        speeds = {"v": torch.zeros(1), "omega": torch.zeros(1)}
        motion = {"points": points, "velocity": points, **speeds}
        if p.room:
            motion["pose"] = torch.zeros(1, 3)
        log_torch_model(run, result.model, motion, ("velocity_change",))
    m = result.metrics
    return (
        f"wrote {out}: {m['train_samples']} training samples; best epoch {m['best_epoch']} of "
        f"{m['epochs']}: validation error {m['val_loss']:.4f} m "
        f"(constant velocity {m['val_loss_constant_velocity']:.4f} m), "
        f"{m['cpu_seconds']:.0f} CPU-s"
    )
