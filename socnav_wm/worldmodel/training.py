"""Training of the paper's world model: the VAE, then the latent LSTM on its latents.

Each takes its section of ``params.yaml`` (:class:`~socnav_wm.worldmodel.params.VaeParams`,
:class:`~socnav_wm.worldmodel.params.LstmParams`) and runs the shared loop of
:mod:`socnav_wm.worldmodel.fitting` (Adam, early stopping on the validation loss, the best
weights restored), supplying its own batch loss and validation. Everything runs on the
section's ``device``; nothing is hard-wired to CUDA.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from socnav_wm.data.windows import Windows
from socnav_wm.devices import as_tensor, resolve_device
from socnav_wm.resources import build_trainable
from socnav_wm.worldmodel.evaluation import evaluate_vae, lstm_val_loss
from socnav_wm.worldmodel.fitting import EpochCallback, Fit, fit
from socnav_wm.worldmodel.lstm import LatentLSTM, masked_mse
from socnav_wm.worldmodel.params import LstmParams, VaeParams
from socnav_wm.worldmodel.vae import VAE, vae_loss


@dataclass
class VAETrainResult:
    """Outcome of :func:`train_vae`.

    Attributes:
        model: the VAE with the weights of the best validation epoch, in eval mode, on the
            training device.
        history: one dict per epoch: epoch, train_loss, val_loss, val_recon_mse, val_kl, seconds.
        metrics: final validation metrics of the restored model (see
            :func:`~socnav_wm.worldmodel.evaluation.evaluate_vae`) plus best_epoch and
            epochs_run.
        env: the scenarios of the data it was trained on
            (:func:`socnav_wm.data.compatibility.made_with`), saved with it; None: unknown.
    """

    model: VAE
    history: list[dict[str, float]] = field(default_factory=list)
    metrics: dict[str, float] = field(default_factory=dict)
    env: dict[str, Any] | None = None


@dataclass
class LSTMTrainResult:
    """Outcome of :func:`train_lstm`.

    Attributes:
        model: the LSTM with the weights of the best validation epoch, in eval mode.
        history: one dict per epoch: epoch, train_loss, val_loss, seconds.
        metrics: val_loss (teacher-forced masked MSE per latent dim), best_epoch, epochs_run.
        env: the scenarios of the data it was trained on, saved with it; None: unknown.
    """

    model: LatentLSTM
    history: list[dict[str, float]] = field(default_factory=list)
    metrics: dict[str, float] = field(default_factory=dict)
    env: dict[str, Any] | None = None


def train_vae(
    train_obs: np.ndarray,
    val_obs: np.ndarray,
    params: VaeParams,
    *,
    seed: int,
    on_epoch: EpochCallback | None = None,
) -> VAETrainResult:
    """Train a VAE on raw observations with Adam and early stopping on the validation loss.

    The standardisation (per-feature mean and floored std) comes from ``train_obs`` only. Each
    epoch shuffles with a seeded ``torch.Generator``; ``torch.manual_seed(seed)`` fixes the
    initial weights, and a separate seeded generator draws the reparameterisation noise, so two
    runs with the same seed on the CPU give identical weights.

    Args:
        train_obs, val_obs: raw observations, (n_train, input_dim) and (n_val, input_dim).
        params: the sizes, β (``kl_weight``), the optimisation and the device
            (``val_fraction`` is the caller's: the split is already made).
        seed: seed of initialisation, shuffling and sampling.
        on_epoch: optional progress/logging callback ``(epoch, metrics)``.

    Returns:
        :class:`VAETrainResult` with the best-validation weights restored.

    Raises:
        NonFiniteTrainingError: a training or validation loss, or a weight at the end of an
            epoch, is NaN or infinite (before ``on_epoch`` sees that epoch).
    """
    device = resolve_device(params.device)
    train_obs = np.asarray(train_obs, dtype=np.float32)
    if train_obs.ndim != 2 or len(train_obs) == 0 or len(val_obs) == 0:
        raise ValueError("train_vae needs non-empty (n, input_dim) train and validation arrays")
    torch.manual_seed(seed)
    model = build_trainable(
        "vae.hidden_dim",
        f"the VAE (hidden_dim {params.hidden_dim}, latent_dim {params.latent_dim})",
        lambda: VAE(train_obs.shape[1], params.hidden_dim, params.latent_dim),
    )
    model.fit_normalization(train_obs)
    model.to(device)
    train_x = as_tensor(train_obs, device)
    val_x = as_tensor(val_obs, device)
    shuffle_generator = torch.Generator().manual_seed(seed)
    noise_generator = torch.Generator(device=device).manual_seed(seed + 1)
    kl_weight = params.kl_weight

    def batch_loss(index: torch.Tensor) -> tuple[torch.Tensor, float]:
        obs = train_x[index]
        recon, mu, logvar = model(obs, sample=True, generator=noise_generator)
        total, _, _ = vae_loss(recon, model.standardize(obs), mu, logvar, kl_weight)
        return total, len(index)

    def validate() -> dict[str, float]:
        val = evaluate_vae(model, val_x, kl_weight)
        return {key: val[key] for key in ("val_loss", "val_recon_mse", "val_kl")}

    task = Fit(
        name="VAE",
        model=model,
        optimizer=torch.optim.Adam(model.parameters(), lr=params.learning_rate),
        rows=len(train_x),
        batch_size=params.batch_size,
        generator=shuffle_generator,
        device=device,
        batch_loss=batch_loss,
        validate=validate,
    )
    fitted = fit(task, max_epochs=params.max_epochs, patience=params.patience, on_epoch=on_epoch)
    metrics = evaluate_vae(model, val_x, kl_weight)
    metrics["best_epoch"] = float(fitted.best_epoch)
    metrics["epochs_run"] = float(len(fitted.history))
    model.eval()
    return VAETrainResult(model=model, history=fitted.history, metrics=metrics)


def train_lstm(
    train_windows: Windows,
    val_windows: Windows,
    params: LstmParams,
    *,
    seed: int,
    on_epoch: EpochCallback | None = None,
) -> LSTMTrainResult:
    """Train the latent LSTM on windows (teacher forcing, zero initial state per window).

    Loss: MSE per latent dim on the unmasked steps (the paper used L1 and trained on zero
    padding; we mask it). Adam, gradient-norm clipping at 1.0, early stopping on the validation
    loss with the best weights restored. Deterministic for a seed on the CPU.

    Args:
        train_windows, val_windows: from :func:`socnav_wm.data.windows.make_windows`.
        params: the hidden size, the optimisation and the device (``seq_len`` and
            ``val_fraction`` are the caller's: the windows are already made).
        seed: seed of initialisation and shuffling.
        on_epoch: as for :func:`train_vae`.

    Returns:
        :class:`LSTMTrainResult` with the best-validation weights restored.

    Raises:
        NonFiniteTrainingError: as :func:`train_vae` does.
    """
    device = resolve_device(params.device)
    if train_windows.num_windows == 0 or val_windows.num_windows == 0:
        raise ValueError("train_lstm needs non-empty train and validation windows")
    torch.manual_seed(seed)
    latent_dim = train_windows.inputs_z.shape[-1]
    model = build_trainable(
        "lstm.hidden_dim",
        f"the LSTM (hidden_dim {params.hidden_dim})",
        lambda: LatentLSTM(latent_dim, hidden_dim=params.hidden_dim),  # 4 actions
    ).to(device)
    train = train_windows.to(device)

    def batch_loss(index: torch.Tensor) -> tuple[torch.Tensor, float]:
        batch = train.select(index)
        prediction, _ = model(batch.inputs_z, batch.actions)
        return masked_mse(prediction, batch.targets, batch.mask), float(batch.mask.sum())

    task = Fit(
        name="LSTM",
        model=model,
        optimizer=torch.optim.Adam(model.parameters(), lr=params.learning_rate),
        rows=train.num_windows,
        batch_size=params.batch_size,
        generator=torch.Generator().manual_seed(seed),
        device=device,
        batch_loss=batch_loss,
        validate=lambda: {"val_loss": lstm_val_loss(model, val_windows)},
        max_grad_norm=1.0,
    )
    fitted = fit(task, max_epochs=params.max_epochs, patience=params.patience, on_epoch=on_epoch)
    metrics = {
        "val_loss": lstm_val_loss(model, val_windows),
        "best_epoch": float(fitted.best_epoch),
        "epochs_run": float(len(fitted.history)),
    }
    return LSTMTrainResult(model=model, history=fitted.history, metrics=metrics)
