"""`dvc repro` of the whole pipeline in a temporary copy of the repository, tiny params."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from tests.conftest import tiny_params

ROOT = Path(__file__).resolve().parents[1]


def _project_files() -> list[str]:
    """Tracked files plus untracked ones git does not ignore (a work tree under development)."""
    listed = subprocess.run(
        ["git", "ls-files", "--cached", "--others", "--exclude-standard"],
        cwd=ROOT, check=True, capture_output=True, text=True,
    ).stdout.split()  # fmt: skip
    return [name for name in listed if (ROOT / name).is_file()]


@pytest.fixture
def repo(tmp_path: Path) -> Path:
    if shutil.which("git") is None:
        pytest.fail("git is required for the DVC test")
    copy = tmp_path / "repo"
    for name in _project_files():
        target = copy / name
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / name, target)
    # DVC needs every params section a stage lists to be present in the file.
    (copy / "params.yaml").write_text(yaml.safe_dump({**tiny_params(), "env": {"num_humans": 3}}))
    git = ["git", "-c", "user.name=test", "-c", "user.email=test@example.com"]
    subprocess.run([*git, "init", "-q"], cwd=copy, check=True)
    subprocess.run([*git, "add", "-A"], cwd=copy, check=True)
    subprocess.run([*git, "commit", "-q", "-m", "copy"], cwd=copy, check=True)
    return copy


def _run(repo: Path, *command: str) -> str:
    """Run ``command`` in ``repo`` with this environment's ``dvc`` and ``socnav-wm`` on PATH."""
    env = dict(os.environ)
    bin_dir = str(Path(sys.executable).parent)
    env["PATH"] = bin_dir + os.pathsep + env.get("PATH", "")
    env["MLFLOW_TRACKING_URI"] = _tracking_uri(repo)
    env["DVC_NO_ANALYTICS"] = "1"
    result = subprocess.run(command, cwd=repo, env=env, capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr
    return result.stdout + result.stderr


def _dvc(repo: Path, *args: str) -> str:
    return _run(repo, str(Path(sys.executable).parent / "dvc"), *args)


def _tracking_uri(repo: Path) -> str:
    return f"sqlite:///{repo / 'mlflow.db'}"


def test_dvc_repro_runs_the_pipeline_and_reruns_only_what_changed(repo: Path) -> None:
    _dvc(repo, "repro", "train_lstm")
    for path in ("data/rollouts", "models/vae.pt", "models/lstm.pt", "metrics/lstm.json"):
        assert (repo / path).exists(), path
    lock = yaml.safe_load((repo / "dvc.lock").read_text())
    assert {"collect", "train_vae", "train_lstm"} <= set(lock["stages"])
    assert (repo / "mlflow.db").exists()

    # Compiled-kernel and bytecode caches appearing next to the code change no stage.
    cache = repo / "socnav_wm/env/__pycache__"
    cache.mkdir(exist_ok=True)
    (cache / "core.step-1.py311.nbi").write_bytes(b"numba index")
    (cache / "core.cpython-311.pyc").write_bytes(b"bytecode")
    assert "Data and pipelines are up to date" in _dvc(repo, "repro", "train_lstm")

    params = yaml.safe_load((repo / "params.yaml").read_text())
    params["lstm"]["max_epochs"] = 2
    (repo / "params.yaml").write_text(yaml.safe_dump(params))
    status = _dvc(repo, "status")
    stale = {line.rstrip(":") for line in status.splitlines() if not line.startswith("\t")}
    assert "train_lstm" in stale and "collect" not in stale and "train_vae" not in stale
    output = _dvc(repo, "repro", "train_lstm")
    assert "Running stage 'train_lstm'" in output
    assert "Running stage 'collect'" not in output and "Running stage 'train_vae'" not in output

    shown = _dvc(repo, "metrics", "show")
    assert "one_step_mse" in shown and "val_recon_mse" in shown

    # The whole pipeline as `make run` runs it: the agent trainings as two concurrent
    # `dvc repro` jobs, then the evaluations and the report.
    if shutil.which("make") is None:
        pytest.fail("make is required for the DVC test")
    output = _run(repo, "make", "repro", "JOBS=2")
    runs = [(v, s) for v in ("dueling-dqn", "2stepahead-maspm") for s in (0, 1)]
    trainings = [f"train_agent@{v}-{s}" for v, s in runs]
    for stage in trainings:  # each ran once: the final `dvc repro` found it up to date
        assert output.count(f"Running stage '{stage}'") == 1, stage
    # The jobs' bookkeeping did not clobber one another: every training is in dvc.lock, and
    # each has one finished MLflow run.
    lock = yaml.safe_load((repo / "dvc.lock").read_text())
    assert set(trainings) <= set(lock["stages"])
    # The paper's pipeline is up to date; the studies (a pipeline of their own) never ran.
    assert "Data and pipelines are up to date" in _dvc(repo, "status", "dvc.yaml")
    assert "studies/dvc.yaml:study_seeds" in _dvc(repo, "status")
    from mlflow.tracking import MlflowClient

    client = MlflowClient(tracking_uri=_tracking_uri(repo))
    experiment = client.get_experiment_by_name("socnav-wm")
    mlflow_runs = client.search_runs([experiment.experiment_id], "tags.stage LIKE 'train-agent/%'")
    names = sorted(f"train-agent/{v}/seed-{s}" for v, s in runs)
    assert sorted(run.info.run_name for run in mlflow_runs) == names
    assert {run.info.status for run in mlflow_runs} == {"FINISHED"}
    assert "Running stage 'evaluate_baseline@sfm'" in output
    outputs = (
        "models/agents/dueling-dqn/seed-0.pt",
        "data/training/dueling-dqn/seed-1.parquet",
        "data/eval/2stepahead-maspm.parquet",
        "data/eval/orca-trajectories.parquet",
        "reports/summary.md",
        "reports/figures/histograms.png",
        "metrics/report.json",
    )
    for path in outputs:
        assert (repo / path).exists(), path
    shown = _dvc(repo, "metrics", "show")
    assert "metrics/eval/orca.json" in shown and "greedy_success_rate" in shown
    _dvc(repo, "plots", "show", "--out", str(repo / "plots"))
    assert (repo / "plots" / "index.html").is_file()

    # A test-scenario parameter reruns the evaluations and the report, never the training.
    params = yaml.safe_load((repo / "params.yaml").read_text())
    params["eval"]["episodes"] = 4
    (repo / "params.yaml").write_text(yaml.safe_dump(params))
    output = _dvc(repo, "repro")
    assert "Running stage 'evaluate@dueling-dqn'" in output and "Running stage 'report'" in output
    assert "Running stage 'train_agent" not in output
    # ... and the README's results block says so (the rest of the README is untouched).
    readme = (repo / "README.md").read_text()
    assert "on the same 4 test scenarios" in readme and "| `orca` |" in readme
    assert readme.endswith((ROOT / "README.md").read_text().split("<!-- /socnav-wm:results -->")[1])
    assert "on the same 4 test scenarios" in (repo / "docs/evaluation.md").read_text()

    # An edit of the reward makes every stage that can execute it stale: the data, every
    # training, every evaluation, the baselines' included (their import closure has it).
    reward = repo / "socnav_wm/env/reward.py"
    reward.write_text(reward.read_text() + "# an edit\n")
    output = _dvc(repo, "status", "--json")
    stale = set(json.loads(output[output.index("{") : output.rindex("}") + 1]))
    expected = {"collect", "evaluate_baseline@orca", "evaluate_baseline@sfm"}
    expected |= {f"train_agent@{v}-{s}" for v, s in runs}
    expected |= {f"evaluate@{v}" for v in ("dueling-dqn", "2stepahead-maspm")}
    assert expected <= stale, sorted(expected - stale)


def test_a_queued_experiment_keeps_its_mlflow_runs(repo: Path) -> None:
    """`dvc exp run --queue` runs the stage in a temporary workspace that DVC deletes after:
    with the default tracking URI the runs still land in the repository's own mlflow.db."""
    import time

    env = dict(os.environ)
    env.pop("MLFLOW_TRACKING_URI", None)
    env["PATH"] = str(Path(sys.executable).parent) + os.pathsep + env.get("PATH", "")
    env["DVC_NO_ANALYTICS"] = "1"
    dvc = str(Path(sys.executable).parent / "dvc")

    def run(*args: str) -> str:
        result = subprocess.run([dvc, *args], cwd=repo, env=env, capture_output=True, text=True)
        assert result.returncode == 0, result.stdout + result.stderr
        return result.stdout

    run("exp", "run", "--queue", "collect", "--name", "queued-collect")
    run("queue", "start", "--jobs", "1")
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline:
        status = run("queue", "status")
        if "Success" in status or "Failed" in status:
            break
        time.sleep(2)
    run("queue", "stop", "--kill")
    assert "Success" in status, status + run("queue", "logs", "queued-collect")
    from mlflow.tracking import MlflowClient

    client = MlflowClient(tracking_uri=f"sqlite:///{repo / 'mlflow.db'}")
    experiment = client.get_experiment_by_name("socnav-wm")
    runs = client.search_runs([experiment.experiment_id])
    assert [run.data.tags["stage"] for run in runs] == ["collect"]
    assert runs[0].data.tags["dvc_exp_name"] == "queued-collect"
    assert runs[0].info.status == "FINISHED"


def test_a_parameter_changed_by_dvc_exp_run_is_tracked_and_one_set_by_set_is_not(
    repo: Path,
) -> None:
    """The README's rule: `--set` is for quick runs outside DVC's tracking; `dvc exp run -S`
    changes params.yaml, so `dvc params diff` (and `dvc exp show`) see it."""
    _run(repo, "socnav-wm", "collect", "--set", "collect.episodes=6", "--no-tracking", "--quiet")
    assert "collect.episodes" not in _dvc(repo, "params", "diff")
    _dvc(repo, "exp", "run", "-S", "collect.episodes=12", "collect")
    diff = _dvc(repo, "params", "diff")
    assert re.search(r"collect\.episodes\s+40\s+12", diff), diff
    assert "collect.episodes" in _dvc(repo, "exp", "show", "--csv")
