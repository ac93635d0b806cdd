"""The trained models a clone ships (`make models`): git tracks models/ (dvc.yaml's model
outputs have `cache: false`), so a fresh clone, which has no data/ and no DVC cache, evaluates
and runs agents without training. Real git, DVC and make, on tiny models in a temporary copy."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from tests.conftest import tiny_params
from tests.test_dvc import _dvc, _project_files, _run

ROOT = Path(__file__).resolve().parents[1]
VENV = Path(sys.executable).parent.parent
GIT = ["git", "-c", "user.name=test", "-c", "user.email=test@example.com"]


def test_the_readme_names_make_models() -> None:
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert re.search(r"^make models\b", readme, re.MULTILINE)
    assert re.search(r"^models: \$\(STAMP\)$", (ROOT / "Makefile").read_text(), re.MULTILINE)


@pytest.fixture
def trained(tmp_path: Path) -> Path:
    """A copy of the repository whose tiny pipeline trained one agent and one planning model,
    committed as a release would be."""
    if shutil.which("git") is None or shutil.which("make") is None:
        pytest.fail("git and make are required for this test")
    repo = tmp_path / "repo"
    for name in _project_files():
        if not name.startswith("models/") or name == "models/.gitkeep":
            (repo / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, repo / name)
    tiny = tiny_params()
    tiny["experiment"] = {"variants": ["dueling-dqn"], "seeds": [0]}
    tiny["planning_model"]["seeds"] = [0]
    (repo / "params.yaml").write_text(yaml.safe_dump({**tiny, "env": {"num_humans": 3}}))
    subprocess.run([*GIT, "init", "-q"], cwd=repo, check=True)
    _dvc(repo, "repro", "train_agent@dueling-dqn-0", "train_planning_model@0")
    subprocess.run([*GIT, "add", "-A"], cwd=repo, check=True)
    subprocess.run([*GIT, "commit", "-q", "-m", "trained"], cwd=repo, check=True)
    return repo


def _make_models(clone: Path) -> subprocess.CompletedProcess[str]:
    """`make models` with this environment's venv (-o: never reinstall it)."""
    env = {**os.environ, "DVC_NO_ANALYTICS": "1", "MLFLOW_TRACKING_URI": "sqlite:///x.db"}
    command = ["make", "-o", f"{VENV}/.installed", "models", f"VENV={VENV}"]
    return subprocess.run(command, cwd=clone, env=env, capture_output=True, text=True)


def test_a_fresh_clone_has_its_models_and_make_models_checks_them(
    trained: Path, tmp_path: Path
) -> None:
    tracked = subprocess.run(
        ["git", "ls-files", "models"], cwd=trained, check=True, capture_output=True, text=True
    ).stdout.split()
    shipped = ("vae.pt", "vae.params.yaml", "lstm.pt", "planning/seed-0.pt",
               "agents/dueling-dqn/seed-0.pt", "agents/dueling-dqn/seed-0.params.yaml")  # fmt: skip
    assert {f"models/{name}" for name in shipped} <= set(tracked)
    assert not any(name.startswith("data/rollouts") for name in tracked)  # still DVC's

    clone = tmp_path / "clone"
    subprocess.run(["git", "clone", "-q", str(trained), str(clone)], check=True)
    assert not (clone / "data/rollouts").exists() and not (clone / ".dvc/cache").exists()
    done = _make_models(clone)
    out = done.stdout + done.stderr
    assert done.returncode == 0, out
    assert "models: all 4 model files in place" in out and "each matches dvc.lock" in out
    assert "agent dueling-dqn, greedy validation success" in out
    absent = next(line for line in out.splitlines() if "only their data is absent" in line)
    assert "collect" in absent and "train_vae" in absent and "train_agent@dueling-dqn-0" in absent
    # What the README promises a clone, with no training: an evaluation on the shipped
    # planning model, an agent step by step.
    _run(clone, "socnav-wm", "evaluate", "--method", "wm-mpc", "--no-tracking", "--quiet")
    agent = "models/agents/dueling-dqn/seed-0.pt"
    shown = _run(clone, sys.executable, "examples/run_agent.py", agent, "--episodes", "2")
    assert "dueling-dqn" in shown

    (clone / "models/lstm.pt").unlink()
    done = subprocess.run(
        [str(VENV / "bin/socnav-wm"), "models", "--no-dvc-status"],
        cwd=clone, capture_output=True, text=True,
    )  # fmt: skip
    assert done.returncode == 1
    assert "models/lstm.pt" in done.stdout and "missing" in done.stdout
    assert "models: 1 of 4 model files are missing or do not load" in done.stdout
