"""The planning world model's file (:mod:`socnav_wm.worldmodel.residual`): what a trained model is
written as, and read back from.

A ``torch.save`` of plain values: ``format`` :data:`PLANNING_MODEL_FORMAT` and its version, the
sizes that rebuild the model, its CPU weights, the training ``settings`` and ``metrics``, and
``env``: the scenarios it was trained for. It is read with PyTorch's weights-only unpickler
(:func:`socnav_wm.io.load_torch_file`), never arbitrary objects. Given the params' ``env``,
:func:`load_residual` refuses a model made for other scenarios
(:func:`socnav_wm.data.compatibility.check_made_with`); a file written before ``env`` was
recorded (and before its format version) is judged by its number of humans and, for a model
that knows the room, the area where it expects the goals.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from socnav_wm.data.compatibility import check_made_with
from socnav_wm.env.params import EnvParams
from socnav_wm.io import ModelFileError, check_format, first_line, load_torch_file, torch_bytes
from socnav_wm.worldmodel.residual import ResidualDynamics

PLANNING_MODEL_FORMAT = "socnav-wm residual-cv"
PLANNING_MODEL_FORMAT_VERSION = 1
WHAT = "planning model"


@dataclass
class ResidualTrainResult:
    """A trained planning model as :func:`save_residual` writes it
    (:func:`socnav_wm.worldmodel.residual_training.train_residual` makes one)."""

    model: ResidualDynamics
    history: list[dict[str, float]]
    metrics: dict[str, float]
    env: dict[str, Any] | None = None
    """The scenarios it was trained for (:func:`socnav_wm.data.compatibility.made_with`)."""


def save_residual(path: Any, result: ResidualTrainResult, settings: dict[str, Any]) -> None:
    """The model's weights, what rebuilds it and the scenarios it was trained for
    (torch.save)."""
    payload = {
        "format": PLANNING_MODEL_FORMAT,
        "format_version": PLANNING_MODEL_FORMAT_VERSION,
        "state_dict": result.model.state_dict(),
        "num_humans": result.model.num_humans,
        "hidden_dim": result.model.net[0].out_features,
        "dt": result.model.dt,
        "max_speed": result.model.max_speed,
        "room_half": result.model.room_half,
        # Only a model that sees its K nearest records it: the others' payload stays what it
        # was before the option existed.
        **({"neighbours": result.model.neighbours} if result.model.neighbours else {}),
        **({"holonomic": True} if result.model.holonomic else {}),
        "settings": settings,
        "metrics": result.metrics,
        "env": result.env,
    }
    Path(path).write_bytes(torch_bytes(payload))


def _made_with(data: dict[str, Any]) -> dict[str, Any] | None:
    """What the file records of its scenarios: its ``env``, or (an older file) its number of
    humans and the half-size of the goals' area of a model that knows the room."""
    if isinstance(data.get("env"), dict):
        return data["env"]
    made = {"num_humans": data.get("num_humans")}
    if data.get("room_half") is not None:
        made["spawn_half_size"] = data["room_half"]
    return made


def load_residual(
    path: str | Path, env_params: EnvParams | None = None, *, transfer: bool = False
) -> ResidualDynamics:
    """A model written by :func:`save_residual`, in eval mode on the CPU.

    Raises:
        ModelFileError: one line naming the file when it is missing, unreadable (truncated,
            or holding objects other than tensors and plain values), not a planning model, of
            another format version, made for other scenarios than ``env_params`` (None: not
            checked), or when its weights do not fit.
    """
    path = Path(path)
    if not path.is_file():
        raise ModelFileError(f"{path}: no such {WHAT}")
    data = load_torch_file(path, WHAT, ModelFileError)
    if isinstance(data, dict) and "format_version" not in data:  # written before it had one
        data = {**data, "format_version": PLANNING_MODEL_FORMAT_VERSION}
    check_format(
        data, path, WHAT, PLANNING_MODEL_FORMAT, PLANNING_MODEL_FORMAT_VERSION, ModelFileError
    )
    check_made_with(path, _made_with(data), env_params, error=ModelFileError, transfer=transfer)
    try:
        model = ResidualDynamics(
            data["num_humans"],
            data["hidden_dim"],
            data["dt"],
            data.get("max_speed"),
            data.get("room_half"),
            data.get("neighbours"),
            bool(data.get("holonomic", False)),
        )
        model.load_state_dict(data["state_dict"])
    except (KeyError, TypeError, RuntimeError) as exc:
        raise ModelFileError(f"{path}: weights do not fit the model ({first_line(exc)})") from exc
    return model.eval()
