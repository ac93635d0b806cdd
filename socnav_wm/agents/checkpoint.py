"""Checkpoint files of a training run: which run a checkpoint belongs to, where it lives, and
one save and one load of the whole training state (:class:`socnav_wm.agents.training.TrainState`).
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

from socnav_wm.agents.features import VARIANTS
from socnav_wm.agents.params import AgentParams
from socnav_wm.env.params import EnvParams
from socnav_wm.io import atomic_path, load_saved, torch_bytes

CHECKPOINT_FORMAT = "socnav-wm-agent-checkpoint"
CHECKPOINT_FORMAT_VERSION = 5
"""5: the optimiser's state is one flat tensor over all parameters (4: the training state as
one object, an autograd learner with one tensor per parameter)."""


def _file_digest(path: str | Path | None) -> str | None:
    if path is None:
        return None
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return None  # loading the world model reports the missing file


def run_identity(
    variant: str,
    params: AgentParams,
    env_params: EnvParams,
    seed: int,
    vae_path: str | Path | None = None,
    lstm_path: str | Path | None = None,
) -> dict[str, Any]:
    """What makes two training runs the same run: a checkpoint resumes only its own run.

    ``params`` are resolved for the variant (``agent.per_variant`` applied); the world model
    enters by the content of its files, so retraining the VAE or LSTM invalidates checkpoints.
    The checkpoint format version is part of it too: a checkpoint written by an older version
    of this code has another file name, and a run started by newer code begins afresh.
    """
    p = params.resolved(variant)  # checks the variant's name
    world = VARIANTS[variant].needs_world_model
    return {
        "checkpoint_format": CHECKPOINT_FORMAT_VERSION,
        "variant": variant,
        "params": p.to_dict(),
        "env_params": env_params.to_dict(),
        "seed": seed,
        "world_model": {
            "vae": _file_digest(vae_path) if world else None,
            "lstm": _file_digest(lstm_path) if world else None,
        },
    }


def checkpoint_file(directory: str | Path, identity: dict[str, Any]) -> Path:
    """``{directory}/{variant}/seed-{seed}-{digest}.ckpt``: one file per distinct run, so a
    changed parameter never resumes (or overwrites) another run's checkpoint."""
    digest = hashlib.sha256(json.dumps(identity, sort_keys=True).encode()).hexdigest()[:12]
    return Path(directory) / identity["variant"] / f"seed-{identity['seed']}-{digest}.ckpt"


def save_checkpoint(path: str | Path, identity: dict[str, Any], state: dict[str, Any]) -> None:
    """Write a run's training state (``TrainState.state_dict()``) atomically."""
    payload = {
        "format": CHECKPOINT_FORMAT,
        "format_version": CHECKPOINT_FORMAT_VERSION,
        "run": identity,
        "state": state,
    }
    with atomic_path(path) as tmp:
        tmp.write_bytes(torch_bytes(payload))


class UnreadableCheckpoint(ValueError):
    """A checkpoint file that cannot be read (truncated, damaged, another format)."""


def set_aside(path: str | Path) -> Path:
    """Rename an unreadable checkpoint to ``<name>.unreadable-<n>`` (kept for inspection, never
    resumed) and return the new path."""
    path = Path(path)
    n = 0
    while (aside := path.with_name(f"{path.name}.unreadable-{n}")).exists():
        n += 1
    path.rename(aside)
    return aside


def load_checkpoint(path: str | Path, identity: dict[str, Any]) -> dict[str, Any]:
    """The training state saved at ``path``, after checking that it is the run ``identity``.

    Raises:
        UnreadableCheckpoint: the file cannot be read as a checkpoint of this format.
        ValueError: it is the checkpoint of another run.
    """
    payload = load_saved(
        path, "agent checkpoint", CHECKPOINT_FORMAT, CHECKPOINT_FORMAT_VERSION, UnreadableCheckpoint
    )
    saved = payload["run"]
    for key in ("variant", "seed", "params", "env_params", "world_model"):
        if saved.get(key) != identity[key]:
            differing = key
            if isinstance(saved.get(key), dict):
                names = sorted(k for k in identity[key] if saved[key].get(k) != identity[key][k])
                differing = ", ".join(f"{key}.{name}" for name in names)
            raise ValueError(
                f"{path}: checkpoint of a different run ({differing} differs); "
                "delete it or train without --resume"
            )
    return payload["state"]
