"""``vae-lstm-mpc``'s model: the paper's frozen VAE + LSTM as a :class:`~.models.PlanningModel`.

Along the real trajectory the VAE encodes every observation (its mean) and the LSTM is
teacher-forced with the real latents and actions, so its state summarises the episode so far.
To imagine, the latent and the LSTM state of the present are repeated once per candidate, the
LSTM is fed its own predicted latents with the candidates' actions, all candidates in one
batched call per step, and the VAE decodes each predicted latent into an observation, whose
goal and human positions (robot frame) the planner scores. The networks run in float32 without
gradients.
"""

from __future__ import annotations

import copy

import numpy as np
import torch

from socnav_wm.planning.models import Rollout
from socnav_wm.worldmodel.ego import positions
from socnav_wm.worldmodel.lstm import LatentLSTM
from socnav_wm.worldmodel.vae import VAE


class _LatentRollout:
    def __init__(self, model: VaeLstmModel, latent: torch.Tensor, state) -> None:
        self.model, self.latent, self.state = model, latent, state

    def step(self, actions: np.ndarray) -> np.ndarray:
        a = torch.as_tensor(np.asarray(actions, dtype=np.int64))
        with torch.no_grad():
            self.latent, self.state = self.model.lstm.step(self.latent, a, self.state)
            return self.model.decode(self.latent)


class VaeLstmModel:
    """Follows the episodes with the VAE + LSTM and imagines in latent space (module docstring).

    Args:
        vae: the trained VAE (its normalisation included).
        lstm: the trained latent LSTM.
    """

    def __init__(self, vae: VAE, lstm: LatentLSTM) -> None:
        self.vae = copy.deepcopy(vae).float().eval()
        self.lstm = copy.deepcopy(lstm).float().eval()
        self._latent = torch.zeros(0)
        self._state = None

    def _encode(self, obs: np.ndarray) -> torch.Tensor:
        return self.vae.encode(torch.as_tensor(np.asarray(obs, dtype=np.float32)))[0]

    def decode(self, latent: torch.Tensor) -> np.ndarray:
        """Robot-frame positions (B, 1 + H, 2) of the decoded latents (B, latent_dim)."""
        return positions(self.vae.destandardize(self.vae.decode(latent)).numpy()).astype(np.float64)

    def reset(self, obs: np.ndarray) -> None:
        with torch.no_grad():
            self._latent = self._encode(obs)
        self._state = None

    def observe(self, obs: np.ndarray, actions: np.ndarray) -> None:
        a = torch.as_tensor(np.asarray(actions, dtype=np.int64))
        with torch.no_grad():
            _, self._state = self.lstm.step(self._latent, a, self._state)
            self._latent = self._encode(obs)

    def rollout(
        self, repeats: int, pose: np.ndarray | None = None, rows: np.ndarray | None = None
    ) -> Rollout:
        chosen = slice(None) if rows is None else torch.as_tensor(rows, dtype=torch.long)
        state = None
        if self._state is not None:
            state = tuple(x[chosen].repeat_interleave(repeats, dim=0) for x in self._state)
        latent = self._latent[chosen].repeat_interleave(repeats, dim=0)
        return _LatentRollout(self, latent, state)
