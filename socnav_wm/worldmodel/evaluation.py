"""How good the VAE and the latent LSTM are on held-out data: the validation metrics of
training and of the stages' metric files, each against its no-learning baseline.

Latents: the world model works on the VAE *mean* mu, which is deterministic, both to train the
LSTM and (in the agents) to act. The paper's code used sampled z (paper_spec §8.5), which made
the RL state stochastic.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from socnav_wm.data.windows import Windows
from socnav_wm.devices import as_tensor
from socnav_wm.worldmodel.lstm import LatentLSTM, masked_mse
from socnav_wm.worldmodel.vae import VAE, vae_loss

EVAL_CHUNK = 65_536
"""Rows (or windows) per forward pass in evaluation: bounds memory on large datasets."""


@torch.no_grad()
def evaluate_vae(model: VAE, obs: np.ndarray | torch.Tensor, kl_weight: float) -> dict[str, float]:
    """Validation metrics of a VAE on raw observations (n, input_dim), decoding z = mu.

    Returns:
        ``val_loss`` (the training objective with z = mu, β = ``kl_weight``),
        ``val_recon_mse`` (per feature, in standardised units), ``val_recon_mse_raw`` (per
        feature, raw units), ``val_kl`` (nats per sample), ``baseline_mse`` /
        ``baseline_mse_raw`` (the same errors for the trivial predictor "the training mean"),
        and ``recon_to_baseline_ratio`` (standardised) / ``recon_to_baseline_ratio_raw``.
        Constant features add 0 to every error.
    """
    model.eval()
    device = model.obs_mean.device
    obs_t = as_tensor(obs, device)
    if obs_t.shape[0] == 0:
        raise ValueError("evaluate_vae needs at least one observation")
    sums = dict.fromkeys(("loss", "recon", "recon_raw", "kl", "base", "base_raw"), 0.0)
    for chunk in obs_t.split(EVAL_CHUNK):
        mu, logvar = model.encode(chunk)
        recon = model.decode(mu)
        target = model.standardize(chunk)
        total, recon_mse, kl = vae_loss(recon, target, mu, logvar, kl_weight)
        rows = chunk.shape[0]
        sums["loss"] += float(total) * rows
        sums["recon"] += float(recon_mse) * rows
        sums["kl"] += float(kl) * rows
        sums["recon_raw"] += float((model.destandardize(recon) - chunk).pow(2).mean()) * rows
        # The mean predictor is 0 in standardised units and obs_mean in raw units.
        sums["base"] += float(target.pow(2).mean()) * rows
        sums["base_raw"] += float((chunk - model.obs_mean).pow(2).mean()) * rows
    n = obs_t.shape[0]
    metrics = {
        "val_loss": sums["loss"] / n,
        "val_recon_mse": sums["recon"] / n,
        "val_recon_mse_raw": sums["recon_raw"] / n,
        "val_kl": sums["kl"] / n,
        "baseline_mse": sums["base"] / n,
        "baseline_mse_raw": sums["base_raw"] / n,
    }
    metrics["recon_to_baseline_ratio"] = _ratio(metrics["val_recon_mse"], metrics["baseline_mse"])
    metrics["recon_to_baseline_ratio_raw"] = _ratio(
        metrics["val_recon_mse_raw"], metrics["baseline_mse_raw"]
    )
    return metrics


def _ratio(numerator: float, denominator: float) -> float:
    return numerator / denominator if denominator > 0 else math.nan


@torch.no_grad()
def encode_observations(model: VAE, obs: np.ndarray, *, batch_size: int = EVAL_CHUNK) -> np.ndarray:
    """Raw observations (n, input_dim) → latent means mu (n, latent_dim), float32 numpy.

    Uses mu, not a sample: the world model's latents are deterministic (module docstring).
    """
    model.eval()
    device = model.obs_mean.device
    parts = [
        model.encode(as_tensor(chunk, device))[0].cpu().numpy()
        for chunk in np.array_split(np.asarray(obs), max(1, math.ceil(len(obs) / batch_size)))
    ]
    return np.concatenate(parts).astype(np.float32, copy=False)


@torch.no_grad()
def lstm_val_loss(model: LatentLSTM, windows: Windows, batch_size: int = EVAL_CHUNK // 16) -> float:
    """The LSTM's training loss (teacher-forced masked MSE per latent dim) on ``windows``."""
    model.eval()
    device = model.head.weight.device
    error_sum, steps = 0.0, 0.0
    for start in range(0, windows.num_windows, batch_size):
        chunk = windows.select(slice(start, start + batch_size)).to(device)
        prediction, _ = model(chunk.inputs_z, chunk.actions)
        count = float(chunk.mask.sum())
        error_sum += float(masked_mse(prediction, chunk.targets, chunk.mask)) * count
        steps += count
    return error_sum / max(steps, 1.0)


@torch.no_grad()
def evaluate_lstm(
    model: LatentLSTM, windows: Windows, *, batch_size: int = 4096
) -> dict[str, float]:
    """One- and two-step prediction errors on (validation) windows, against copy-last.

    All errors are mean squared errors per latent dim, on real (unmasked) steps only, with the
    state reset to zero at each window start, as in training.

    - ``one_step_mse``: teacher-forced, real z_t and a_t in, ẑ_{t+1} vs z_{t+1}.
      ``copy_last_one_step_mse``: z_t vs z_{t+1}.
    - ``two_step_mse``: from the state after (real z_t, a_t), feed the prediction ẑ_{t+1} with
      the same action a_t again and compare ẑ_{t+2} with the true z_{t+2} — counted only on
      steps where the real a_{t+1} equals a_t (so "the same action repeated" is what happened)
      and t+1 is a real step of the same window. ``copy_last_two_step_mse``: z_t vs z_{t+2} on
      the same steps.
    - ``*_ratio``: model error / copy-last error (below 1 means the model beats copy-last);
      ``one_step_count`` / ``two_step_count``: the number of steps behind each average.

    Args:
        model: the LSTM (its device is used).
        windows: windows of the episodes to evaluate (:func:`make_windows`).
        batch_size: windows per pass.
    """
    model.eval()
    device = model.head.weight.device
    sums = dict.fromkeys(("one", "copy_one", "two", "copy_two", "n_one", "n_two"), 0.0)
    for start in range(0, windows.num_windows, batch_size):
        chunk = windows.select(slice(start, start + batch_size)).to(device)
        z, actions, targets, mask = chunk
        state = None
        for position in range(z.shape[1]):
            prediction, state = model.step(z[:, position], actions[:, position], state)
            valid = mask[:, position]
            sums["one"] += float(_sq(prediction, targets[:, position])[valid].sum())
            sums["copy_one"] += float(_sq(z[:, position], targets[:, position])[valid].sum())
            sums["n_one"] += float(valid.sum())
            if position + 1 >= z.shape[1]:
                continue
            repeated = valid & mask[:, position + 1]
            repeated &= actions[:, position + 1] == actions[:, position]
            if not bool(repeated.any()):
                continue
            two_step, _ = model.step(prediction, actions[:, position], state)
            true_z2 = targets[:, position + 1]
            sums["two"] += float(_sq(two_step, true_z2)[repeated].sum())
            sums["copy_two"] += float(_sq(z[:, position], true_z2)[repeated].sum())
            sums["n_two"] += float(repeated.sum())
    nan = math.nan
    one = sums["one"] / sums["n_one"] if sums["n_one"] else nan
    copy_one = sums["copy_one"] / sums["n_one"] if sums["n_one"] else nan
    two = sums["two"] / sums["n_two"] if sums["n_two"] else nan
    copy_two = sums["copy_two"] / sums["n_two"] if sums["n_two"] else nan
    return {
        "one_step_mse": one,
        "copy_last_one_step_mse": copy_one,
        "one_step_ratio": _ratio(one, copy_one),
        "two_step_mse": two,
        "copy_last_two_step_mse": copy_two,
        "two_step_ratio": _ratio(two, copy_two),
        "one_step_count": sums["n_one"],
        "two_step_count": sums["n_two"],
    }


def _sq(prediction: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Squared error per sample, averaged over the latent dims: (batch, latent) → (batch,)."""
    return (prediction - target).pow(2).mean(dim=-1)
