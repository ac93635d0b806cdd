"""The paper's world model's files: what a trained VAE or latent LSTM is written as,
and read back from.

A VAE or LSTM file is a ``torch.save`` of plain values (``format`` :data:`CHECKPOINT_FORMAT`,
its version, the model's kind, its hyperparameters, CPU weights, ``extra`` and ``env``: the
scenarios of the data it was trained on), written atomically and read with
``weights_only=True``. Given the params' ``env``, the loaders refuse a model made for other
scenarios (:func:`socnav_wm.data.compatibility.check_made_with`; a file written before ``env``
was recorded: a VAE by the size of its observations, an LSTM not at all).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch

from socnav_wm.data.compatibility import check_made_with, observation_record
from socnav_wm.devices import resolve_device
from socnav_wm.env.params import EnvParams
from socnav_wm.io import ModelFileError, atomic_path, first_line, load_saved, torch_bytes
from socnav_wm.worldmodel.lstm import LatentLSTM
from socnav_wm.worldmodel.training import LSTMTrainResult, VAETrainResult
from socnav_wm.worldmodel.vae import VAE

CHECKPOINT_FORMAT = "socnav-wm-model"
CHECKPOINT_FORMAT_VERSION = 1


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


def _save_model(
    path: str | Path,
    kind: str,
    model: torch.nn.Module,
    extra: Any,
    env: Mapping[str, Any] | None,
) -> None:
    payload = {
        "format": CHECKPOINT_FORMAT,
        "format_version": CHECKPOINT_FORMAT_VERSION,
        "kind": kind,
        "hyperparameters": model.hyperparameters(),  # type: ignore[operator]
        "state_dict": {key: value.detach().cpu() for key, value in model.state_dict().items()},
        "extra": _plain(extra or {}),
        "env": _plain(env) if env is not None else None,
    }
    with atomic_path(path) as tmp:
        tmp.write_bytes(torch_bytes(payload))


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
    e.g. the validation metrics and the data it was trained on. A :class:`VAETrainResult`'s
    ``env`` is saved with it.
    """
    if isinstance(model, VAETrainResult):
        _save_model(path, "vae", model.model, extra, model.env)
    else:
        _save_model(path, "vae", model, extra, None)


def load_vae(
    path: str | Path,
    device: torch.device | str = "cpu",
    env_params: EnvParams | None = None,
    *,
    transfer: bool = False,
) -> VAE:
    """Load a VAE written by :func:`save_vae`, in eval mode on ``device``; refused when it was
    trained for other scenarios than ``env_params`` (None: not checked)."""
    payload = load_checkpoint(path, "vae")
    made = payload.get("env")
    if not isinstance(made, dict):  # written before the scenarios were recorded
        input_dim = (payload.get("hyperparameters") or {}).get("input_dim")
        made = observation_record(input_dim) if isinstance(input_dim, int) else None
    check_made_with(path, made, env_params, error=ModelFileError, transfer=transfer)
    return _build(Path(path), payload, VAE, device)


def save_lstm(
    path: str | Path,
    model: LatentLSTM | LSTMTrainResult,
    extra: Mapping[str, Any] | None = None,
) -> None:
    """Write a latent LSTM (weights, sizes, ``extra``, an :class:`LSTMTrainResult`'s ``env``) to
    ``path`` atomically."""
    if isinstance(model, LSTMTrainResult):
        _save_model(path, "lstm", model.model, extra, model.env)
    else:
        _save_model(path, "lstm", model, extra, None)


def load_lstm(
    path: str | Path,
    device: torch.device | str = "cpu",
    env_params: EnvParams | None = None,
    *,
    transfer: bool = False,
) -> LatentLSTM:
    """Load a latent LSTM written by :func:`save_lstm`, in eval mode on ``device``; refused when
    it was trained for other scenarios than ``env_params`` (None, or a file that does not
    record them: not checked)."""
    payload = load_checkpoint(path, "lstm")
    made = payload.get("env") if isinstance(payload.get("env"), dict) else None
    check_made_with(path, made, env_params, error=ModelFileError, transfer=transfer)
    return _build(Path(path), payload, LatentLSTM, device)


def load_vae_lstm(
    vae_path: str | Path,
    lstm_path: str | Path,
    device: torch.device | str = "cpu",
    env_params: EnvParams | None = None,
    *,
    transfer: bool = False,
) -> tuple[VAE, LatentLSTM]:
    """The paper's world model: :func:`load_vae` and :func:`load_lstm`, and the LSTM must
    predict the latents the VAE encodes (ModelFileError naming both files otherwise)."""
    vae = load_vae(vae_path, device, env_params, transfer=transfer)
    lstm = load_lstm(lstm_path, device, env_params, transfer=transfer)
    if lstm.latent_dim != vae.latent_dim:
        raise ModelFileError(
            f"{lstm_path}: predicts {lstm.latent_dim}-d latents, the VAE {vae_path} encodes "
            f"{vae.latent_dim}-d ones"
        )
    return vae, lstm
