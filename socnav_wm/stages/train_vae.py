"""Stage ``train_vae``: the VAE (23-d observation → latent) on the rollouts."""

from __future__ import annotations

from functools import partial
from pathlib import Path
from typing import Any, Unpack

import torch

from socnav_wm.config import Params
from socnav_wm.stages.common import WorldModelOutputs, log_torch_model, world_model_stage
from socnav_wm.worldmodel.files import save_vae
from socnav_wm.worldmodel.fit import fit_vae
from socnav_wm.worldmodel.served import ServedVAE


def run(params: Params, *, rollouts: Path, **outputs: Unpack[WorldModelOutputs]) -> str:
    with world_model_stage("train_vae", "train-vae", params, outputs, (rollouts,)) as stage:
        p = params.vae
        fit = partial(fit_vae, rollouts, params.env, p, seed=params.seed)
        fitted = stage.fit(p.max_epochs, fit)
        result = fitted.result
        summary: dict[str, Any] = {**result.metrics, **fitted.data}
        extra = {"metrics": summary, "params": p.model_dump()}
        stage.publish(lambda path: save_vae(path, result, extra=extra), summary, result.history)
        stage.run.log_figure(fitted.figure(), "figures/reconstruction.png")
        m = result.metrics
        stage.run.log_headline(
            {"best_val_loss": m["val_loss"], "val_recon_mse": m["val_recon_mse"]}
        )
        vae = result.model
        obs = torch.zeros(1, vae.input_dim, dtype=vae.mu_head.weight.dtype)
        served = ServedVAE(vae)
        log_torch_model(stage.run, served, obs, ("obs", "latent"), name="vae", model_type="vae")
    return (
        f"wrote {stage.model}: validation reconstruction MSE {result.metrics['val_recon_mse']:.4f} "
        f"vs {result.metrics['baseline_mse']:.4f} for the training mean"
    )
