"""Stage ``train_lstm``: the LSTM world model on VAE latents of the rollouts (VAE frozen)."""

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
from socnav_wm.worldmodel.files import save_lstm
from socnav_wm.worldmodel.fit import fit_lstm


def run(
    params: Params,
    *,
    rollouts: Path,
    vae: Path,
    out: Path,
    metrics: Path,
    history: Path,
    tracking: bool = True,
    quiet: bool = True,
) -> str:
    check_writable(out, config_path(out), metrics, history)
    with open_stage("train_lstm", "train-lstm", params, tracking=tracking) as run:
        with progress(params.lstm.max_epochs, "train-lstm", quiet=quiet, unit="epochs") as bar:
            fitted = fit_lstm(
                rollouts,
                vae,
                params.lstm,
                seed=params.seed,
                on_epoch=epoch_logger(run, bar),
            )
        result = fitted.result
        summary: dict[str, Any] = {**result.metrics, **fitted.metrics, **fitted.data}
        extra = {"metrics": summary, "params": params.lstm.model_dump()}
        world_model_outputs(
            "train_lstm", run, params, lambda path: save_lstm(path, result, extra=extra),
            out, metrics, history, summary, result.history,
        )  # fmt: skip
        run.log_figure(fitted.figure(), "figures/latent_predictions.png")
        lstm = result.model
        seq = params.lstm.seq_len
        z = torch.zeros(1, seq, lstm.latent_dim, dtype=lstm.head.weight.dtype)
        actions = torch.zeros(1, seq, dtype=torch.int64)
        log_torch_model(run, lstm, {"z": z, "actions": actions}, ("z_next",))
    m = fitted.metrics
    return (
        f"wrote {out}: 1-step latent MSE {m['one_step_mse']:.4g} "
        f"(copy-last {m['copy_last_one_step_mse']:.4g}); 2-step {m['two_step_mse']:.4g} "
        f"(copy-last {m['copy_last_two_step_mse']:.4g})"
    )
