"""Figures of the world model: the VAE's reconstructions and the latent LSTM's predictions
(drawn on an Agg canvas, without pyplot: no global state, no display, safe in workers)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from socnav_wm.devices import as_tensor
from socnav_wm.worldmodel.lstm import LatentLSTM
from socnav_wm.worldmodel.vae import VAE


def observation_feature_names(num_features: int) -> list[str]:
    """Names of the observation features (paper_spec §2), or ``f0, f1, …`` for other layouts."""
    if num_features < 2 or (num_features - 2) % 7:
        return [f"f{index}" for index in range(num_features)]
    names = ["goal_x", "goal_y"]
    for human in range((num_features - 2) // 7):
        names += [
            f"h{human}_{name}" for name in ("x", "y", "sin", "cos", "radius", "speed", "omega")
        ]
    return names


def _new_figure(width: float, height: float) -> Figure:
    # An Agg canvas, not pyplot: no global state, no display needed, safe in worker processes.
    figure = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(figure)
    return figure


@torch.no_grad()
def plot_reconstruction(model: VAE, obs_sample: np.ndarray, max_observations: int = 4) -> Figure:
    """True vs reconstructed (decoded from mu) raw features for a few observations.

    Args:
        model: the VAE.
        obs_sample: (k, input_dim) raw observations; the first ``max_observations`` are drawn.
    """
    model.eval()
    obs = np.asarray(obs_sample, dtype=np.float32)[:max_observations]
    device = model.obs_mean.device
    mu, _ = model.encode(as_tensor(obs, device))
    recon = model.destandardize(model.decode(mu)).cpu().numpy()
    names = observation_feature_names(obs.shape[1])
    figure = _new_figure(10, 2.2 * len(obs) + 0.6)
    axes = figure.subplots(len(obs), 1, sharex=True, squeeze=False)[:, 0]
    positions = np.arange(obs.shape[1])
    for row, axis in enumerate(axes):
        axis.plot(positions, obs[row], "o", label="observation", color="tab:blue")
        axis.plot(positions, recon[row], "x", label="reconstruction", color="tab:red")
        axis.set_ylabel(f"obs {row} (raw)")
        axis.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize="small")
    axes[-1].set_xticks(positions, names, rotation=90, fontsize="small")
    figure.suptitle("VAE reconstruction (decoded from mu), raw units")
    return figure


@torch.no_grad()
def plot_latent_predictions(
    model: LatentLSTM,
    latents: np.ndarray,
    actions: np.ndarray,
    next_latents: np.ndarray | None = None,
    dims: Sequence[int] = (0, 1, 2),
    reset_every: int | None = None,
) -> Figure:
    """Predicted vs true latent trajectory of one episode, for a few latent dims.

    The LSTM runs step by step over the episode with real latents in (teacher forcing), from a
    zero state, reset every ``reset_every`` steps when given (use the training ``seq_len`` to see
    what training optimised; None runs the whole episode, as the agents do).

    Args:
        model: the LSTM.
        latents: (T, latent) latents z_t of the episode's observations.
        actions: (T,) actions a_t.
        next_latents: (T, latent) latents of the observations after each step; by default
            ``latents[1:]`` (then only T − 1 predictions are compared).
        dims: latent dimensions to draw, one panel each.
        reset_every: state reset period in steps, or None.
    """
    model.eval()
    device = model.head.weight.device
    z = as_tensor(latents, device)
    a = torch.as_tensor(np.asarray(actions, dtype=np.int64), device=device)
    truth = np.asarray(latents[1:] if next_latents is None else next_latents, dtype=np.float32)
    steps = len(truth)
    predictions = []
    state = None
    for t in range(steps):
        if reset_every is not None and t % reset_every == 0:
            state = None
        prediction, state = model.step(z[t : t + 1], a[t : t + 1], state)
        predictions.append(prediction[0].cpu().numpy())
    predicted = np.stack(predictions) if predictions else np.zeros_like(truth)
    time_axis = np.arange(1, steps + 1)
    figure = _new_figure(10, 2.2 * len(dims) + 0.6)
    axes = figure.subplots(len(dims), 1, sharex=True, squeeze=False)[:, 0]
    for axis, dim in zip(axes, dims, strict=True):
        axis.plot(time_axis, truth[:, dim], label="true z_{t+1}", color="tab:blue")
        axis.plot(time_axis, predicted[:, dim], "--", label="LSTM prediction", color="tab:red")
        axis.set_ylabel(f"z[{dim}]")
        axis.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize="small")
    axes[-1].set_xlabel("step t + 1")
    figure.suptitle("Latent LSTM one-step predictions (teacher forced)")
    return figure
