"""``socnav-wm models``: the trained models a clone ships (what ``make models`` checks)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from socnav_wm.cli.application import command
from socnav_wm.cli.options import SharedOptions, shared_options


@command()
@shared_options("params", "set", "overlay")
def models(
    options: SharedOptions,
    lock: Annotated[Path, typer.Option(help="The dvc.lock to compare with.")] = Path("dvc.lock"),
    dvc_status: Annotated[
        bool, typer.Option(help="Also say what `dvc status dvc.yaml` says.")
    ] = True,
) -> None:
    """Check the trained models that the repository ships (the VAE, the LSTM, the planning
    models, every agent of `experiment`): each is there, loads, and is the file dvc.lock
    records; then what `dvc status` says. Exit status 1 when one is missing or broken."""
    params = options.load_or_defaults()
    from socnav_wm.methods.model_files import check_model_files

    found = check_model_files(params.experiment, params.planning_model, params.env, lock)
    for model in found:
        state = model.problem or f"{model.what}; {model.size / 1e6:.1f} MB; {model.lock}"
        typer.echo(f"{model.path.as_posix():40} {state}")
    broken = [model for model in found if model.problem]
    total = sum(model.size for model in found) / 1e6
    states = [model.lock for model in found]
    if broken:
        typer.echo(
            f"models: {len(broken)} of {len(found)} model files are missing or do not load; "
            "`make run` trains every model"
        )
    else:
        counts = {state: states.count(state) for state in ("matches", "differs", "not in dvc.lock")}
        locked = ", ".join(f"{n} {state}" for state, n in counts.items() if n)
        locked = (
            "each matches dvc.lock" if counts["matches"] == len(found) else f"dvc.lock: {locked}"
        )
        typer.echo(f"models: all {len(found)} model files in place ({total:.1f} MB), {locked}")
    if dvc_status:
        for line in dvc_status_lines():
            typer.echo(line)
    if broken:
        raise typer.Exit(code=1)


def dvc_status_lines() -> list[str]:
    """What ``dvc status dvc.yaml`` says, in a few lines: the stages up to date, those that
    only miss their data (``data/``: DVC's outputs, which a clone does not have), and the
    others with their changes."""
    dvc = shutil.which("dvc", path=str(Path(sys.executable).parent)) or shutil.which("dvc")
    if dvc is None:
        return ["dvc status: dvc is not installed (pip install -e '.[pipeline]')"]
    listed = subprocess.run(
        [dvc, "stage", "list", "--name-only", "dvc.yaml"], capture_output=True, text=True
    )
    result = subprocess.run([dvc, "status", "--json", "dvc.yaml"], capture_output=True, text=True)
    try:
        text = result.stdout
        changed: dict[str, Any] = json.loads(text[text.index("{") : text.rindex("}") + 1])
        if listed.returncode != 0:
            raise ValueError(listed.stderr)
    except ValueError:
        problem = (listed.stderr + result.stderr or result.stdout).strip().splitlines()
        return [f"dvc status: failed ({problem[-1] if problem else result.returncode})"]
    current = sorted(set(listed.stdout.split()) - set(changed))
    data_only = sorted(stage for stage, changes in changed.items() if _only_missing_data(changes))
    lines = [f"dvc status: up to date: {', '.join(current) or 'none'}"]
    if data_only:
        lines.append(
            f"dvc status: only their data is absent ({len(data_only)} stages; data/ is DVC's, "
            f"not in a clone: `make run` rebuilds it): {', '.join(data_only)}"
        )
    for stage, changes in sorted(changed.items()):
        if stage not in data_only:
            lines.append(f"dvc status: changed: {stage}: {_changes(changes)}")
    return lines


MISSING = ("deleted", "not in cache")
"""What ``dvc status`` says of a DVC output that is not in the workspace or not in the cache."""


def _only_missing_data(changes: list[Any]) -> bool:
    for change in changes:
        if not isinstance(change, dict):
            return False
        for kind, paths in change.items():
            if kind not in ("changed deps", "changed outs") or not isinstance(paths, dict):
                return False
            if any(not p.startswith("data/") or s not in MISSING for p, s in paths.items()):
                return False
    return True


def _changes(changes: list[Any]) -> str:
    """A stage's changes in a line: per kind, the first paths and how many more."""
    shown = []
    for change in changes:
        if not isinstance(change, dict):
            shown.append(str(change))
            continue
        for kind, paths in change.items():
            if not isinstance(paths, dict):
                shown.append(f"{kind} {paths}")
                continue
            if kind == "changed params":  # {file: {param: state}}
                paths = {k: v for entries in paths.values() for k, v in entries.items()}
            items = [f"{path} ({state})" for path, state in paths.items()]
            more = f" and {len(items) - 3} more" if len(items) > 3 else ""
            shown.append(f"{kind} {', '.join(items[:3])}{more}")
    return "; ".join(shown)
