"""The world models in the form MLflow serves: one tensor in, one tensor out.

MLflow's PyTorch flavour hands ``mlflow.pyfunc.load_model(uri).predict(array)`` to ``forward``
as one tensor and takes one tensor back, so each model a training logs (:mod:`socnav_wm.tracking`)
is wrapped here (the planning model in :mod:`socnav_wm.worldmodel.served_planning`, so that
the VAE and LSTM stages do not depend on its code); the wrapped model itself is an attribute
(``.vae``, ``.lstm``, ``.model``), unchanged, for ``mlflow.pytorch.load_model`` users who want
all of it.
"""

from __future__ import annotations

import torch
from torch import nn

from socnav_wm.worldmodel.lstm import LatentLSTM
from socnav_wm.worldmodel.vae import VAE


class ServedVAE(nn.Module):
    """The VAE's encoder: raw observations (batch, input_dim) → their latents, the VAE mean
    (batch, latent_dim), what the LSTM and the agents read."""

    def __init__(self, vae: VAE) -> None:
        super().__init__()
        self.vae = vae

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.vae.encode(obs)[0]


class ServedLSTM(nn.Module):
    """The LSTM world model over sequences from a zero state: (batch, steps, latent_dim + 1),
    each step's latent followed by the action then taken (0 to num_actions − 1, as a number) →
    the predicted next latents (batch, steps, latent_dim)."""

    def __init__(self, lstm: LatentLSTM) -> None:
        super().__init__()
        self.lstm = lstm

    def forward(self, sequences: torch.Tensor) -> torch.Tensor:
        actions = sequences[..., -1].round().to(torch.int64)
        return self.lstm(sequences[..., :-1], actions)[0]
