"""The ``train-vae`` and ``train-lstm`` stages as library functions: rollouts in, models out.

Both split the rollouts by episode with the same seed and fraction, so the LSTM is validated on
episodes the VAE never saw either (when the two fractions are equal). Both refuse rollouts (and
the LSTM a VAE) made for other scenarios than the params' ``env``, and record those scenarios in
the model they train.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from socnav_wm.data.compatibility import made_with
from socnav_wm.data.shards import column_to_numpy, read_rollouts
from socnav_wm.data.windows import Windows, make_windows, split_episodes
from socnav_wm.devices import resolve_device
from socnav_wm.env.params import EnvParams
from socnav_wm.worldmodel.evaluation import encode_observations, evaluate_lstm
from socnav_wm.worldmodel.figures import plot_latent_predictions, plot_reconstruction
from socnav_wm.worldmodel.files import load_vae
from socnav_wm.worldmodel.fitting import EpochCallback
from socnav_wm.worldmodel.params import LstmParams, VaeParams
from socnav_wm.worldmodel.training import LSTMTrainResult, VAETrainResult, train_lstm, train_vae


@dataclass
class FittedVAE:
    result: VAETrainResult
    data: dict[str, Any]  # sizes of the splits, for the record
    val_sample: np.ndarray  # a few validation observations, for the reconstruction figure

    def figure(self) -> Any:
        return plot_reconstruction(self.result.model, self.val_sample)


@dataclass
class FittedLSTM:
    result: LSTMTrainResult
    metrics: dict[str, float]  # evaluate_lstm on validation windows
    data: dict[str, Any]
    episode: tuple[np.ndarray, np.ndarray, np.ndarray]  # one validation episode, for the figure

    def figure(self) -> Any:
        latents, actions, next_latents = self.episode
        return plot_latent_predictions(
            self.result.model, latents, actions, next_latents, reset_every=None
        )


def fit_vae(
    rollouts: str | Path,
    env_params: EnvParams,
    params: VaeParams,
    *,
    seed: int,
    on_epoch: EpochCallback | None = None,
) -> FittedVAE:
    """Train the VAE on every observation of the training episodes of ``rollouts`` (collected
    in the scenarios of ``env_params``)."""
    table = read_rollouts(rollouts, columns=["episode_id", "obs"], env_params=env_params)
    ids = column_to_numpy(table, "episode_id")
    obs = column_to_numpy(table, "obs")
    train, val = split_episodes(ids, params.val_fraction, seed)
    result = train_vae(obs[train], obs[val], params, seed=seed, on_epoch=on_epoch)
    result.env = made_with(env_params)
    data = {
        "train_rows": int(train.sum()),
        "val_rows": int(val.sum()),
        "val_episodes": int(np.unique(ids[val]).size),
    }
    return FittedVAE(result=result, data=data, val_sample=obs[val][:4])


def fit_lstm(
    rollouts: str | Path,
    vae_path: str | Path,
    env_params: EnvParams,
    params: LstmParams,
    *,
    seed: int,
    on_epoch: EpochCallback | None = None,
) -> FittedLSTM:
    """Encode the rollouts with the frozen VAE (its mean), then train the latent LSTM; the
    rollouts and the VAE must be of the scenarios of ``env_params``."""
    torch_device = resolve_device(params.device)
    vae = load_vae(vae_path, torch_device, env_params)
    columns = ["episode_id", "obs", "action", "next_obs"]
    table = read_rollouts(rollouts, columns=columns, env_params=env_params)
    ids = column_to_numpy(table, "episode_id")
    actions = column_to_numpy(table, "action").astype(np.int64)
    latents = encode_observations(vae, column_to_numpy(table, "obs"))
    next_latents = encode_observations(vae, column_to_numpy(table, "next_obs"))
    train, val = split_episodes(ids, params.val_fraction, seed)

    def windows(mask: np.ndarray) -> Windows:
        return make_windows(
            latents[mask], actions[mask], ids[mask], next_latents[mask], params.seq_len
        )

    train_windows, val_windows = windows(train), windows(val)
    result = train_lstm(train_windows, val_windows, params, seed=seed, on_epoch=on_epoch)
    result.env = made_with(env_params)
    metrics = evaluate_lstm(result.model, val_windows)
    # The longest validation episode, for the predicted-vs-true figure.
    val_ids = ids[val]
    episode_ids, counts = np.unique(val_ids, return_counts=True)
    longest = val & (ids == episode_ids[np.argmax(counts)])
    data = {
        "train_windows": int(train_windows.num_windows),
        "val_windows": int(val_windows.num_windows),
        "val_episodes": int(episode_ids.size),
    }
    return FittedLSTM(
        result=result,
        metrics=metrics,
        data=data,
        episode=(latents[longest], actions[longest], next_latents[longest]),
    )
