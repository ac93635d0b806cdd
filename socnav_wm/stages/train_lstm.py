"""Stage ``train_lstm``: the LSTM world model on VAE latents of the rollouts (VAE frozen)."""

from __future__ import annotations

from functools import partial
from pathlib import Path
from typing import Any, Unpack

import torch

from socnav_wm.config import Params
from socnav_wm.stages.common import WorldModelOutputs, log_torch_model, world_model_stage
from socnav_wm.worldmodel.files import save_lstm
from socnav_wm.worldmodel.fit import fit_lstm
from socnav_wm.worldmodel.served import ServedLSTM


def run(params: Params, *, rollouts: Path, vae: Path, **outputs: Unpack[WorldModelOutputs]) -> str:
    with world_model_stage("train_lstm", "train-lstm", params, outputs, (rollouts, vae)) as stage:
        p = params.lstm
        fit = partial(fit_lstm, rollouts, vae, params.env, p, seed=params.seed)
        fitted = stage.fit(p.max_epochs, fit)
        result = fitted.result
        summary: dict[str, Any] = {**result.metrics, **fitted.metrics, **fitted.data}
        extra = {"metrics": summary, "params": p.model_dump()}
        stage.publish(lambda path: save_lstm(path, result, extra=extra), summary, result.history)
        stage.run.log_figure(fitted.figure(), "figures/latent_predictions.png")
        stage.run.log_headline(
            {
                "best_val_loss": result.metrics["val_loss"],
                "one_step_mse": fitted.metrics["one_step_mse"],
                "copy_last_one_step_mse": fitted.metrics["copy_last_one_step_mse"],
            }
        )
        lstm = result.model
        sequences = torch.zeros(1, p.seq_len, lstm.latent_dim + 1, dtype=lstm.head.weight.dtype)
        log_torch_model(
            stage.run,
            ServedLSTM(lstm),
            sequences,
            ("latent_and_action", "next_latent"),
            name="lstm",
            model_type="lstm",
            variable_axes=2,
        )
    m = fitted.metrics
    return (
        f"wrote {stage.model}: 1-step latent MSE {m['one_step_mse']:.4g} "
        f"(copy-last {m['copy_last_one_step_mse']:.4g}); 2-step {m['two_step_mse']:.4g} "
        f"(copy-last {m['copy_last_two_step_mse']:.4g})"
    )
