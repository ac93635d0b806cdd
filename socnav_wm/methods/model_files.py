"""The pipeline's trained models as files: which there are, whether each loads, and whether it
is the one ``dvc.lock`` records.

They are the outputs of ``train_vae``, ``train_lstm``, ``train_planning_model`` and
``train_agent`` (the VAE, the LSTM, a planning model per ``planning_model.seeds``, an agent per
``experiment.variants`` × ``experiment.seeds``), tracked by git (dvc.yaml: ``cache: false``), so
that a clone evaluates, plans and runs agents without training: ``socnav-wm models`` (what
``make models`` runs) checks them with :func:`check_model_files`.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from socnav_wm.agents.params import ExperimentParams
from socnav_wm.env.params import EnvParams
from socnav_wm.io import first_line
from socnav_wm.layout import LAYOUT
from socnav_wm.methods import MAKES
from socnav_wm.worldmodel.params import PlanningModelParams


@dataclass(frozen=True)
class ModelFile:
    """One trained model's file, as found."""

    path: Path
    role: str
    """``vae``, ``lstm``, ``planning_model`` or ``agent``."""
    what: str
    """What it is, in a few words (its sizes; an agent's greedy validation success)."""
    size: int
    """Bytes (0 when missing)."""
    lock: str
    """Against ``dvc.lock``: ``matches``, ``differs`` or ``not in dvc.lock``."""
    problem: str | None = None
    """Why it is not usable (missing, does not load), or None."""


def pipeline_model_files(
    experiment: ExperimentParams, planning_model: PlanningModelParams
) -> list[tuple[str, dict[str, Any], Path]]:
    """Every model the pipeline trains: (role, what names it, path), at ``LAYOUT``'s paths."""
    files: list[tuple[str, dict[str, Any], Path]] = [
        ("vae", {}, LAYOUT.vae),
        ("lstm", {}, LAYOUT.lstm),
    ]
    files += [
        ("planning_model", {"seed": s}, LAYOUT.planning_model(s)) for s in planning_model.seeds
    ]
    files += [
        ("agent", {"variant": v, "seed": s}, LAYOUT.agent(v, s))
        for v in experiment.variants
        for s in experiment.seeds
    ]
    return files


def locked_hashes(lock: Path) -> dict[str, str]:
    """The md5 that ``dvc.lock`` records for each output path (empty without the file)."""
    import yaml

    if not lock.is_file():
        return {}
    stages = (yaml.safe_load(lock.read_text(encoding="utf-8")) or {}).get("stages") or {}
    return {
        out["path"]: out["md5"]
        for stage in stages.values()
        for out in stage.get("outs") or []
        if "md5" in out
    }


def _describe(role: str, path: Path, env_params: EnvParams) -> str:
    if role == "vae":
        from socnav_wm.worldmodel.files import load_vae

        vae = load_vae(path, "cpu", env_params)
        return f"VAE: {vae.input_dim}-d observation → {vae.latent_dim}-d latent"
    if role == "lstm":
        from socnav_wm.worldmodel.files import load_lstm

        lstm = load_lstm(path, "cpu", env_params)
        return f"LSTM world model: {lstm.latent_dim}-d latent, {lstm.hidden_dim} hidden units"
    if role == "planning_model":
        from socnav_wm.worldmodel.planning_file import load_residual

        model = load_residual(path, env_params)
        room = ", knows the room" if model.room_half is not None else ""
        seen = f", sees the {model.neighbours} nearest" if model.neighbours else ""
        return f"planning model: {model.num_humans} humans{seen}{room}"
    from socnav_wm.agents.agent_file import load_agent

    agent = load_agent(path, "cpu", env_params)
    success = (agent.extra.get("metrics") or {}).get("greedy_success_rate")
    shown = f", greedy validation success {success:.1%}" if success is not None else ""
    return f"agent {agent.variant_name}{shown}"


def check_model_files(
    experiment: ExperimentParams,
    planning_model: PlanningModelParams,
    env_params: EnvParams,
    lock: Path = Path("dvc.lock"),
) -> list[ModelFile]:
    """Each of :func:`pipeline_model_files`: loaded with the pipeline's own loader (for the
    scenarios of ``env_params``) and its md5 compared with ``lock``'s."""
    hashes = locked_hashes(lock)
    found = []
    for role, names, path in pipeline_model_files(experiment, planning_model):
        key = path.as_posix()
        if not path.is_file():
            make = MAKES[role].format(**names)
            problem = f"missing (not in this checkout; `{make}` or `make run` trains it)"
            found.append(ModelFile(path, role, "", 0, "", problem))
            continue
        digest = hashlib.md5(path.read_bytes()).hexdigest()  # noqa: S324 - DVC's hash
        state = "not in dvc.lock" if key not in hashes else (
            "matches" if hashes[key] == digest else "differs"
        )  # fmt: skip
        try:
            what, problem = _describe(role, path, env_params), None
        except (ValueError, OSError, RuntimeError, KeyError) as exc:
            what, problem = "", f"does not load ({first_line(exc)})"
        found.append(ModelFile(path, role, what, path.stat().st_size, state, problem))
    return found


def locked_stages(lock: Path) -> set[str]:
    """The stages ``dvc.lock`` records (empty without the file)."""
    import yaml

    if not lock.is_file():
        return set()
    return set((yaml.safe_load(lock.read_text(encoding="utf-8")) or {}).get("stages") or {})
