"""Stage ``train_vae``: the VAE (23-d observation → latent) on the rollouts."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from socnav_wm.config import Params
from socnav_wm.io import check_writable
from socnav_wm.progress import progress
from socnav_wm.stages.common import (
    config_path,
    epoch_logger,
    log_torch_model,
    open_stage,
    world_model_outputs,
)
from socnav_wm.worldmodel.files import save_vae
from socnav_wm.worldmodel.fit import fit_vae


def run(
    params: Params,
    *,
    rollouts: Path,
    out: Path,
    metrics: Path,
    history: Path,
    tracking: bool = True,
    quiet: bool = True,
) -> str:
    check_writable(out, config_path(out), metrics, history)
    with open_stage("train_vae", "train-vae", params, tracking=tracking) as run:
        with progress(params.vae.max_epochs, "train-vae", quiet=quiet, unit="epochs") as bar:
            fitted = fit_vae(
                rollouts,
                params.vae,
                seed=params.seed,
                on_epoch=epoch_logger(run, bar),
            )
        result = fitted.result
        summary: dict[str, Any] = {**result.metrics, **fitted.data}
        extra = {"metrics": summary, "params": params.vae.model_dump()}
        world_model_outputs(
            "train_vae", run, params, lambda path: save_vae(path, result, extra=extra),
            out, metrics, history, summary, result.history,
        )  # fmt: skip
        run.log_figure(fitted.figure(), "figures/reconstruction.png")
        vae = result.model
        obs = torch.zeros(1, vae.input_dim, dtype=vae.mu_head.weight.dtype)
        log_torch_model(run, vae, {"obs": obs}, ("recon", "mu", "logvar"))
    return (
        f"wrote {out}: validation reconstruction MSE {result.metrics['val_recon_mse']:.4f} "
        f"vs {result.metrics['baseline_mse']:.4f} for the training mean"
    )
