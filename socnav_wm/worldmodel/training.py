"""Training, evaluation, checkpoints and figures of the world model (VAE, then latent LSTM).

Plain-argument functions (no config objects), so the CLI stages, the sweep and the tests all call
the same code. Everything takes a ``device``; nothing is hard-wired to CUDA.

Latents: the world model works on the VAE *mean* mu, which is deterministic, both to train the
LSTM and (in the agents) to act. The paper's code used sampled z (paper_spec §8.5), which made
the RL state stochastic.
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from socnav_wm.data.windows import Windows
from socnav_wm.io import atomic_path, first_line, load_saved
from socnav_wm.worldmodel.lstm import LatentLSTM
from socnav_wm.worldmodel.vae import VAE, vae_loss

EpochCallback = Callable[[int, dict[str, float]], None]
"""Called after each epoch with (epoch number from 1, that epoch's metrics)."""

CHECKPOINT_FORMAT = "socnav-wm-model"
CHECKPOINT_FORMAT_VERSION = 1
EVAL_CHUNK = 65_536
"""Rows (or windows) per forward pass in evaluation: bounds memory on large datasets."""


class ModelFileError(ValueError):
    """A model file is missing, unreadable, or not the expected kind (one-line message)."""


class NonFiniteTrainingError(ValueError):
    """A training loss or the weights became NaN or infinite; training stopped (one line)."""


def _check_finite_loss(what: str, loss: float, epoch: int, batch: int | None = None) -> None:
    """Stop training at the first non-finite training (``batch`` given) or validation loss."""
    if math.isfinite(loss):
        return
    where = f"epoch {epoch}" + ("" if batch is None else f" (batch {batch})")
    kind = "training" if batch is not None else "validation"
    raise NonFiniteTrainingError(
        f"{what} training stopped: {kind} loss became {loss} at {where}; no model was written"
    )


def _check_finite_weights(what: str, model: torch.nn.Module, epoch: int) -> None:
    """Stop training when any weight is NaN or infinite at the end of an epoch."""
    for name, parameter in model.named_parameters():
        if not bool(torch.isfinite(parameter).all()):
            raise NonFiniteTrainingError(
                f"{what} training stopped: weight {name} became non-finite at epoch {epoch}; "
                "no model was written"
            )


def resolve_device(device: torch.device | str) -> torch.device:
    """``torch.device`` from a device or a name; ``"auto"`` picks CUDA when available.

    Raises:
        ValueError: CUDA is asked for and this PyTorch has no CUDA device to give.
    """
    if isinstance(device, str) and device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    resolved = torch.device(device)
    if resolved.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(
            f"device {str(device)!r}: CUDA is not available here (torch {torch.__version__}); "
            "use auto or cpu"
        )
    return resolved


def _as_tensor(array: np.ndarray | torch.Tensor, device: torch.device) -> torch.Tensor:
    """float32 tensor on ``device``; tensors are moved, never round-tripped through numpy."""
    if isinstance(array, torch.Tensor):
        return array.to(device=device, dtype=torch.float32)
    return torch.as_tensor(np.asarray(array, dtype=np.float32), device=device)


@dataclass
class VAETrainResult:
    """Outcome of :func:`train_vae`.

    Attributes:
        model: the VAE with the weights of the best validation epoch, in eval mode, on the
            training device.
        history: one dict per epoch: epoch, train_loss, val_loss, val_recon_mse, val_kl, seconds.
        metrics: final validation metrics of the restored model (see :func:`evaluate_vae`) plus
            best_epoch and epochs_run.
    """

    model: VAE
    history: list[dict[str, float]] = field(default_factory=list)
    metrics: dict[str, float] = field(default_factory=dict)


@dataclass
class LSTMTrainResult:
    """Outcome of :func:`train_lstm`.

    Attributes:
        model: the LSTM with the weights of the best validation epoch, in eval mode.
        history: one dict per epoch: epoch, train_loss, val_loss, seconds.
        metrics: val_loss (teacher-forced masked MSE per latent dim), best_epoch, epochs_run.
    """

    model: LatentLSTM
    history: list[dict[str, float]] = field(default_factory=list)
    metrics: dict[str, float] = field(default_factory=dict)


class _EarlyStopping:
    """Keeps the best weights (by validation loss) and says when patience has run out."""

    def __init__(self, patience: int) -> None:
        self.patience = patience
        self.best_loss = math.inf
        self.best_epoch = 0
        self.best_state: dict[str, torch.Tensor] | None = None
        self.epochs_without_improvement = 0

    def update(self, epoch: int, val_loss: float, model: torch.nn.Module) -> bool:
        """Record an epoch; return True when training should stop."""
        if val_loss < self.best_loss:
            self.best_loss, self.best_epoch = val_loss, epoch
            self.best_state = copy.deepcopy(model.state_dict())
            self.epochs_without_improvement = 0
        else:
            self.epochs_without_improvement += 1
        return self.epochs_without_improvement >= self.patience

    def restore(self, model: torch.nn.Module) -> None:
        if self.best_state is not None:
            model.load_state_dict(self.best_state)


# -- VAE ---------------------------------------------------------------------------------------


@torch.no_grad()
def evaluate_vae(
    model: VAE, obs: np.ndarray | torch.Tensor, kl_weight: float = 1.0
) -> dict[str, float]:
    """Validation metrics of a VAE on raw observations (n, input_dim), decoding z = mu.

    Returns:
        ``val_loss`` (the training objective with z = mu), ``val_recon_mse`` (per feature, in
        standardised units), ``val_recon_mse_raw`` (per feature, raw units), ``val_kl`` (nats per
        sample), ``baseline_mse`` / ``baseline_mse_raw`` (the same errors for the trivial
        predictor "the training mean"), and ``recon_to_baseline_ratio`` (standardised) /
        ``recon_to_baseline_ratio_raw``. Constant features add 0 to every error.
    """
    model.eval()
    device = model.obs_mean.device
    obs_t = _as_tensor(obs, device)
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


def train_vae(
    train_obs: np.ndarray,
    val_obs: np.ndarray,
    *,
    latent_dim: int,
    hidden_dim: int,
    kl_weight: float,
    learning_rate: float,
    batch_size: int,
    max_epochs: int,
    patience: int,
    seed: int,
    device: torch.device | str,
    on_epoch: EpochCallback | None = None,
) -> VAETrainResult:
    """Train a VAE on raw observations with Adam and early stopping on the validation loss.

    The standardisation (per-feature mean and floored std) comes from ``train_obs`` only. Each
    epoch shuffles with a seeded ``torch.Generator``; ``torch.manual_seed(seed)`` fixes the
    initial weights, and a separate seeded generator draws the reparameterisation noise, so two
    runs with the same seed on the CPU give identical weights.

    Args:
        train_obs, val_obs: raw observations, (n_train, input_dim) and (n_val, input_dim).
        latent_dim, hidden_dim: VAE sizes (16 and 256 in the paper).
        kl_weight: β, the weight of the KL term (1 = plain ELBO).
        learning_rate, batch_size, max_epochs: Adam step size, rows per step, epoch bound.
        patience: stop after this many epochs without a lower validation loss.
        seed: seed of initialisation, shuffling and sampling.
        device: where to train.
        on_epoch: optional progress/logging callback ``(epoch, metrics)``.

    Returns:
        :class:`VAETrainResult` with the best-validation weights restored.

    Raises:
        NonFiniteTrainingError: a training or validation loss, or a weight at the end of an
            epoch, is NaN or infinite (before ``on_epoch`` sees that epoch).
    """
    device = resolve_device(device)
    train_obs = np.asarray(train_obs, dtype=np.float32)
    if train_obs.ndim != 2 or len(train_obs) == 0 or len(val_obs) == 0:
        raise ValueError("train_vae needs non-empty (n, input_dim) train and validation arrays")
    torch.manual_seed(seed)
    model = VAE(train_obs.shape[1], hidden_dim, latent_dim)
    model.fit_normalization(train_obs)
    model.to(device)
    train_x = _as_tensor(train_obs, device)
    val_x = _as_tensor(val_obs, device)
    shuffle_generator = torch.Generator().manual_seed(seed)
    noise_generator = torch.Generator(device=device).manual_seed(seed + 1)
    optimizer = torch.optim.Adam(model.parameters(), lr=learning_rate)
    stopping = _EarlyStopping(patience)
    history: list[dict[str, float]] = []

    for epoch in range(1, max_epochs + 1):
        started = time.perf_counter()
        model.train()
        loss_sum = 0.0
        order = torch.randperm(len(train_x), generator=shuffle_generator).to(device)
        for batch_number, index in enumerate(order.split(batch_size), start=1):
            obs = train_x[index]
            recon, mu, logvar = model(obs, sample=True, generator=noise_generator)
            total, _, _ = vae_loss(recon, model.standardize(obs), mu, logvar, kl_weight)
            loss_value = float(total.detach())
            _check_finite_loss("VAE", loss_value, epoch, batch_number)
            optimizer.zero_grad(set_to_none=True)
            total.backward()
            optimizer.step()
            loss_sum += loss_value * len(index)
        _check_finite_weights("VAE", model, epoch)
        val = evaluate_vae(model, val_x, kl_weight)
        _check_finite_loss("VAE", val["val_loss"], epoch)
        row = {
            "epoch": float(epoch),
            "train_loss": loss_sum / len(train_x),
            "val_loss": val["val_loss"],
            "val_recon_mse": val["val_recon_mse"],
            "val_kl": val["val_kl"],
            "seconds": time.perf_counter() - started,
        }
        history.append(row)
        if on_epoch is not None:
            on_epoch(epoch, dict(row))
        if stopping.update(epoch, val["val_loss"], model):
            break

    stopping.restore(model)
    metrics = evaluate_vae(model, val_x, kl_weight)
    metrics["best_epoch"] = float(stopping.best_epoch)
    metrics["epochs_run"] = float(len(history))
    model.eval()
    return VAETrainResult(model=model, history=history, metrics=metrics)


@torch.no_grad()
def encode_observations(model: VAE, obs: np.ndarray, *, batch_size: int = EVAL_CHUNK) -> np.ndarray:
    """Raw observations (n, input_dim) → latent means mu (n, latent_dim), float32 numpy.

    Uses mu, not a sample: the world model's latents are deterministic (module docstring).
    """
    model.eval()
    device = model.obs_mean.device
    parts = [
        model.encode(_as_tensor(chunk, device))[0].cpu().numpy()
        for chunk in np.array_split(np.asarray(obs), max(1, math.ceil(len(obs) / batch_size)))
    ]
    return np.concatenate(parts).astype(np.float32, copy=False)


# -- LSTM --------------------------------------------------------------------------------------


def masked_mse(prediction: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mean squared error per latent dim over the unmasked steps.

    Args:
        prediction, target: (batch, seq, latent).
        mask: (batch, seq) bool; padding (False) contributes nothing.
    """
    per_step = (prediction - target).pow(2).mean(dim=-1)
    weights = mask.to(per_step.dtype)
    return (per_step * weights).sum() / weights.sum().clamp_min(1.0)


@torch.no_grad()
def _lstm_val_loss(model: LatentLSTM, windows: Windows, batch_size: int) -> float:
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


def train_lstm(
    train_windows: Windows,
    val_windows: Windows,
    *,
    hidden_dim: int,
    learning_rate: float,
    batch_size: int,
    max_epochs: int,
    patience: int,
    seed: int,
    device: torch.device | str,
    on_epoch: EpochCallback | None = None,
    num_actions: int = 4,
) -> LSTMTrainResult:
    """Train the latent LSTM on windows (teacher forcing, zero initial state per window).

    Loss: MSE per latent dim on the unmasked steps (the paper used L1 and trained on zero
    padding; we mask it). Adam, gradient-norm clipping at 1.0, early stopping on the validation
    loss with the best weights restored. Deterministic for a seed on the CPU.

    Args:
        train_windows, val_windows: from :func:`socnav_wm.data.windows.make_windows`.
        hidden_dim: LSTM hidden size (256 in the paper).
        learning_rate, batch_size, max_epochs: Adam step size, windows per step, epoch bound.
        patience: stop after this many epochs without a lower validation loss.
        seed: seed of initialisation and shuffling.
        device: where to train.
        on_epoch: optional progress/logging callback ``(epoch, metrics)``.
        num_actions: size of the discrete action set.

    Returns:
        :class:`LSTMTrainResult` with the best-validation weights restored.

    Raises:
        NonFiniteTrainingError: a training or validation loss, or a weight at the end of an
            epoch, is NaN or infinite (before ``on_epoch`` sees that epoch).
    """
    device = resolve_device(device)
    if train_windows.num_windows == 0 or val_windows.num_windows == 0:
        raise ValueError("train_lstm needs non-empty train and validation windows")
    torch.manual_seed(seed)
    model = LatentLSTM(train_windows.inputs_z.shape[-1], num_actions, hidden_dim).to(device)
    train = train_windows.to(device)
    shuffle_generator = torch.Generator().manual_seed(seed)
    optimizer = torch.optim.Adam(model.parameters(), lr=learning_rate)
    stopping = _EarlyStopping(patience)
    history: list[dict[str, float]] = []

    for epoch in range(1, max_epochs + 1):
        started = time.perf_counter()
        model.train()
        error_sum, steps = 0.0, 0.0
        order = torch.randperm(train.num_windows, generator=shuffle_generator).to(device)
        for batch_number, index in enumerate(order.split(batch_size), start=1):
            batch = train.select(index)
            prediction, _ = model(batch.inputs_z, batch.actions)
            loss = masked_mse(prediction, batch.targets, batch.mask)
            loss_value = float(loss.detach())
            _check_finite_loss("LSTM", loss_value, epoch, batch_number)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(model.parameters(), max_norm=1.0)
            optimizer.step()
            count = float(batch.mask.sum())
            error_sum += loss_value * count
            steps += count
        _check_finite_weights("LSTM", model, epoch)
        val_loss = _lstm_val_loss(model, val_windows, EVAL_CHUNK // 16)
        _check_finite_loss("LSTM", val_loss, epoch)
        row = {
            "epoch": float(epoch),
            "train_loss": error_sum / max(steps, 1.0),
            "val_loss": val_loss,
            "seconds": time.perf_counter() - started,
        }
        history.append(row)
        if on_epoch is not None:
            on_epoch(epoch, dict(row))
        if stopping.update(epoch, val_loss, model):
            break

    stopping.restore(model)
    model.eval()
    metrics = {
        "val_loss": _lstm_val_loss(model, val_windows, EVAL_CHUNK // 16),
        "best_epoch": float(stopping.best_epoch),
        "epochs_run": float(len(history)),
    }
    return LSTMTrainResult(model=model, history=history, metrics=metrics)


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


# -- checkpoints -------------------------------------------------------------------------------


def _plain(value: Any) -> Any:
    """``extra`` as plain Python values, so ``torch.load(weights_only=True)`` accepts it."""
    if isinstance(value, Mapping):
        return {str(key): _plain(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(item) for item in value]
    if isinstance(value, Path):
        return str(value)
    if hasattr(value, "tolist"):  # numpy scalars/arrays, tensors
        return value.tolist()
    return value


def _save_model(path: str | Path, kind: str, model: torch.nn.Module, extra: Any) -> None:
    payload = {
        "format": CHECKPOINT_FORMAT,
        "format_version": CHECKPOINT_FORMAT_VERSION,
        "kind": kind,
        "hyperparameters": model.hyperparameters(),  # type: ignore[operator]
        "state_dict": {key: value.detach().cpu() for key, value in model.state_dict().items()},
        "extra": _plain(extra or {}),
    }
    with atomic_path(path) as tmp:
        torch.save(payload, tmp)


def load_checkpoint(path: str | Path, kind: str) -> dict[str, Any]:
    """Read and check a model file of ``kind`` (``"vae"`` or ``"lstm"``); return its dict.

    The dict holds ``format``, ``format_version``, ``kind``, ``hyperparameters``,
    ``state_dict`` (CPU tensors) and ``extra``.

    Raises:
        ModelFileError: one line naming the file when it is missing, unreadable, not a
            socnav-wm model, of another format version, or of another kind.
    """
    payload = load_saved(
        path, "model file", CHECKPOINT_FORMAT, CHECKPOINT_FORMAT_VERSION, ModelFileError
    )
    if payload.get("kind") != kind:
        raise ModelFileError(
            f"{path}: holds a {payload.get('kind')!r} model, expected a {kind!r} model"
        )
    return payload


def _build(path: Path, payload: dict[str, Any], model_type: type, device: torch.device | str):
    try:
        model = model_type(**payload["hyperparameters"])
        model.load_state_dict(payload["state_dict"])
    except (KeyError, TypeError, RuntimeError) as exc:
        raise ModelFileError(f"{path}: weights do not fit the model ({first_line(exc)})") from exc
    return model.to(resolve_device(device)).eval()


def save_vae(
    path: str | Path, model: VAE | VAETrainResult, extra: Mapping[str, Any] | None = None
) -> None:
    """Write a VAE (weights, normalisation buffers, sizes, ``extra``) to ``path`` atomically.

    ``extra`` holds plain values (numbers, strings, lists, dicts; numpy values are converted),
    e.g. the validation metrics and the data it was trained on.
    """
    vae = model.model if isinstance(model, VAETrainResult) else model
    _save_model(path, "vae", vae, extra)


def load_vae(path: str | Path, device: torch.device | str = "cpu") -> VAE:
    """Load a VAE written by :func:`save_vae`, in eval mode on ``device``."""
    return _build(Path(path), load_checkpoint(path, "vae"), VAE, device)


def save_lstm(
    path: str | Path,
    model: LatentLSTM | LSTMTrainResult,
    extra: Mapping[str, Any] | None = None,
) -> None:
    """Write a latent LSTM (weights, sizes, ``extra``) to ``path`` atomically."""
    lstm = model.model if isinstance(model, LSTMTrainResult) else model
    _save_model(path, "lstm", lstm, extra)


def load_lstm(path: str | Path, device: torch.device | str = "cpu") -> LatentLSTM:
    """Load a latent LSTM written by :func:`save_lstm`, in eval mode on ``device``."""
    return _build(Path(path), load_checkpoint(path, "lstm"), LatentLSTM, device)


# -- figures -----------------------------------------------------------------------------------


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
    mu, _ = model.encode(_as_tensor(obs, device))
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
    z = _as_tensor(latents, device)
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
