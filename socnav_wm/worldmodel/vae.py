"""The observation VAE: 23-d robot-frame observation ⇄ 16-d latent (paper_spec §4).

Architecture as in the paper's code; two deliberate differences, both documented there as bugs:
the encoder's second head is a true log-variance and the KL term uses it as such (the original
passed sigma = exp(head) where log-variance was expected), and inputs are standardised inside
the module, so callers always pass raw observations.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

DEFAULT_STD_FLOOR = 1e-2
"""Smallest per-feature std used for standardisation, in the feature's raw unit (m, m/s, rad/s,
or unitless). Keeps constant features (the human radius, 0.36 m) from dividing by zero; every
varying observation feature has a std far above it."""


class VAE(nn.Module):
    """Gaussian VAE over observations, with input standardisation built in.

    ``encode`` takes raw observations (batch, input_dim) and standardises them with the
    ``obs_mean`` / ``obs_std`` buffers (set from the training split by :meth:`set_normalization`
    and saved with the weights). ``decode`` returns reconstructions in *standardised* units;
    :meth:`destandardize` maps them back to raw units.
    """

    obs_mean: torch.Tensor
    obs_std: torch.Tensor

    def __init__(self, input_dim: int = 23, hidden_dim: int = 256, latent_dim: int = 16) -> None:
        super().__init__()
        self.input_dim = input_dim
        self.hidden_dim = hidden_dim
        self.latent_dim = latent_dim
        self.encoder = nn.Sequential(
            nn.Linear(input_dim, hidden_dim),
            nn.ReLU(),
            nn.Linear(hidden_dim, hidden_dim),
            nn.ReLU(),
            nn.Linear(hidden_dim, hidden_dim),
            nn.ReLU(),
        )
        self.mu_head = nn.Linear(hidden_dim, latent_dim)
        self.logvar_head = nn.Linear(hidden_dim, latent_dim)
        self.decoder = nn.Sequential(
            nn.Linear(latent_dim, hidden_dim),
            nn.ReLU(),
            nn.Linear(hidden_dim, hidden_dim),
            nn.ReLU(),
            nn.Linear(hidden_dim, input_dim),
        )
        self.register_buffer("obs_mean", torch.zeros(input_dim))
        self.register_buffer("obs_std", torch.ones(input_dim))

    def hyperparameters(self) -> dict[str, int]:
        """Constructor arguments, as saved in checkpoints."""
        return {
            "input_dim": self.input_dim,
            "hidden_dim": self.hidden_dim,
            "latent_dim": self.latent_dim,
        }

    @torch.no_grad()
    def set_normalization(
        self,
        mean: np.ndarray | torch.Tensor,
        std: np.ndarray | torch.Tensor,
        std_floor: float = DEFAULT_STD_FLOOR,
    ) -> None:
        """Set the per-feature standardisation (raw units), flooring std at ``std_floor``."""
        mean_t = torch.as_tensor(np.asarray(mean, dtype=np.float32))
        std_t = torch.as_tensor(np.asarray(std, dtype=np.float32)).clamp_min(std_floor)
        if mean_t.shape != (self.input_dim,) or std_t.shape != (self.input_dim,):
            raise ValueError(f"mean and std must have shape ({self.input_dim},)")
        self.obs_mean.copy_(mean_t)
        self.obs_std.copy_(std_t)

    def fit_normalization(self, obs: np.ndarray, std_floor: float = DEFAULT_STD_FLOOR) -> None:
        """Set the standardisation from raw observations (n, input_dim), in float64 for accuracy.

        float64 keeps the mean of a constant float32 feature exactly equal to its value, so the
        standardised constant is exactly 0.
        """
        obs64 = np.asarray(obs, dtype=np.float64)
        self.set_normalization(obs64.mean(axis=0), obs64.std(axis=0), std_floor)

    def standardize(self, obs: torch.Tensor) -> torch.Tensor:
        """Raw observations (..., input_dim) → standardised, same shape."""
        return (obs - self.obs_mean) / self.obs_std

    def destandardize(self, x: torch.Tensor) -> torch.Tensor:
        """Standardised features (..., input_dim) → raw units, same shape."""
        return x * self.obs_std + self.obs_mean

    def encode(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Raw observations (batch, input_dim) → (mu, logvar), each (batch, latent_dim)."""
        hidden = self.encoder(self.standardize(obs))
        return self.mu_head(hidden), self.logvar_head(hidden)

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        """Latents (batch, latent_dim) → reconstruction (batch, input_dim), standardised units."""
        return self.decoder(z)

    @staticmethod
    def reparameterize(
        mu: torch.Tensor, logvar: torch.Tensor, generator: torch.Generator | None = None
    ) -> torch.Tensor:
        """Sample z = mu + exp(logvar / 2)·ε, ε ~ N(0, I); shapes (batch, latent_dim)."""
        noise = torch.randn(mu.shape, generator=generator, device=mu.device, dtype=mu.dtype)
        return mu + torch.exp(0.5 * logvar) * noise

    def forward(
        self,
        obs: torch.Tensor,
        sample: bool = True,
        generator: torch.Generator | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Raw observations (batch, input_dim) → (recon, mu, logvar).

        ``recon`` is (batch, input_dim) in standardised units; mu and logvar (batch, latent_dim).
        With ``sample=False`` the decoder gets z = mu (deterministic).
        """
        mu, logvar = self.encode(obs)
        z = self.reparameterize(mu, logvar, generator) if sample else mu
        return self.decode(z), mu, logvar


def kl_divergence(mu: torch.Tensor, logvar: torch.Tensor) -> torch.Tensor:
    """KL(N(mu, exp(logvar)) ‖ N(0, I)) per sample: −½ Σ_j (1 + logvar − mu² − exp(logvar)).

    Args:
        mu, logvar: (batch, latent_dim); ``logvar`` is the log-variance (not sigma).

    Returns:
        (batch,) KL in nats.
    """
    return -0.5 * torch.sum(1.0 + logvar - mu.pow(2) - logvar.exp(), dim=-1)


def vae_loss(
    recon: torch.Tensor,
    target: torch.Tensor,
    mu: torch.Tensor,
    logvar: torch.Tensor,
    kl_weight: float,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The VAE objective, averaged over the batch.

    ``total = mean_batch[Σ_features (recon − target)²] + kl_weight · mean_batch[KL]`` — the
    paper's "sum-MSE + KLD", per sample; both terms are summed over their dimensions so their
    balance does not depend on the batch size.

    Args:
        recon, target: (batch, input_dim), both in standardised units.
        mu, logvar: (batch, latent_dim), the encoder's outputs (logvar = log-variance).
        kl_weight: weight of the KL term (β; 1 in the paper).

    Returns:
        (total, recon_mse, kl): scalars; ``recon_mse`` is the mean squared error per feature
        (mean over batch and features), ``kl`` the mean KL per sample (nats).
    """
    squared_error = (recon - target).pow(2)
    recon_sum = squared_error.sum(dim=-1).mean()
    kl = kl_divergence(mu, logvar).mean()
    return recon_sum + kl_weight * kl, squared_error.mean(), kl
