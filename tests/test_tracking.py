"""MLflow tracking against a real SQLite store in a temporary directory (no mocks)."""

from __future__ import annotations

import http.server
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from socnav_wm.tracking import TrackingError, check_tracking, stage_run, tracking_uri

mlflow = pytest.importorskip("mlflow")

# MLflow's SQLAlchemy store uses a deprecated loader option; not ours to fix.
pytestmark = pytest.mark.filterwarnings("ignore:The ``noload`` loader strategy")


@pytest.fixture(scope="module")
def store_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    # One database for the module: creating MLflow's schema takes seconds.
    return tmp_path_factory.mktemp("mlflow")


@pytest.fixture
def sqlite_uri(store_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> str:
    uri = f"sqlite:///{store_dir / 'mlflow.db'}"
    monkeypatch.setenv("MLFLOW_TRACKING_URI", uri)
    monkeypatch.delenv("MLFLOW_EXPERIMENT_NAME", raising=False)
    monkeypatch.delenv("DVC_EXP_NAME", raising=False)
    monkeypatch.chdir(tmp_path)  # not a git repository: git_commit is "unknown"
    return uri


def get_run(run_id: str):  # noqa: ANN201 - an mlflow.entities.Run
    client = mlflow.tracking.MlflowClient()
    experiment = client.get_experiment_by_name("socnav-wm")
    runs = client.search_runs([experiment.experiment_id], filter_string=f"run_id = '{run_id}'")
    assert len(runs) == 1
    return runs[0]


def test_stage_run_records_params_metrics_tags_artifacts(
    sqlite_uri: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    monkeypatch.setenv("DVC_EXP_NAME", "lucky-dog")
    artifact = tmp_path / "vae.json"
    artifact.write_text('{"val_loss": 0.5}\n')
    params = {"seed": 3, "vae": {"kl_weight": 0.5, "device": "cpu"}, "note": "x" * 800}

    with stage_run("train-vae", params) as run:
        for step in range(3):
            run.log_metrics({"loss": 1.0 / (step + 1), "kl": 0.1 * step}, step=step)
        run.log_artifact(artifact)
        figure, axes = plt.subplots()
        axes.plot([0, 1], [1, 0])
        run.log_figure(figure, "figures/loss.png")
        plt.close(figure)
        run.log_text("hello", "notes/readme.txt")
        run.set_tag("device", "cpu")

    result = get_run(run.run_id)
    assert result.info.status == "FINISHED"
    assert result.info.run_name == "train-vae"
    assert result.data.params["seed"] == "3"
    assert result.data.params["vae.kl_weight"] == "0.5"
    assert result.data.params["vae.device"] == "cpu"
    assert len(result.data.params["note"]) == 500  # MLflow's historical value limit
    tags = result.data.tags
    assert tags["stage"] == "train-vae"
    assert tags["git_commit"] == "unknown"
    assert tags["dvc_exp_name"] == "lucky-dog"
    assert tags["device"] == "cpu"

    client = mlflow.tracking.MlflowClient()
    history = client.get_metric_history(run.run_id, "loss")
    assert [(m.step, m.value) for m in sorted(history, key=lambda m: m.step)] == [
        (0, 1.0),
        (1, 0.5),
        (2, pytest.approx(1 / 3)),
    ]
    artifacts = {a.path for a in client.list_artifacts(run.run_id)}
    assert {"vae.json", "params.json", "figures", "notes"} <= artifacts
    assert [a.path for a in client.list_artifacts(run.run_id, "figures")] == ["figures/loss.png"]
    # Artifacts live beside the database, not in whatever directory the run started from.
    assert Path(sqlite_uri.removeprefix("sqlite:///")).parent.joinpath("mlruns").is_dir()
    assert not (tmp_path / "mlruns").exists()


def test_many_params_and_metrics_are_sent_in_batches(sqlite_uri: str) -> None:
    params = {"section": {f"key_{i:03d}": i for i in range(250)}}
    with stage_run("bench", params, run_name="batches") as run:
        for step in range(1500):
            run.log_metrics({"a": step, "b": -step}, step=step)
    result = get_run(run.run_id)
    assert result.info.run_name == "batches"
    assert len(result.data.params) == 250
    history = mlflow.tracking.MlflowClient().get_metric_history(run.run_id, "b")
    assert len(history) == 1500


def test_failing_block_marks_the_run_failed(sqlite_uri: str) -> None:
    with pytest.raises(ZeroDivisionError), stage_run("train-lstm", {"seed": 0}) as run:
        run.log_metrics({"loss": 2.0}, step=0)
        _ = 1 / 0
    result = get_run(run.run_id)
    assert result.info.status == "FAILED"
    assert result.data.tags["error"] == "ZeroDivisionError: division by zero"
    assert result.data.metrics["loss"] == 2.0  # buffered metrics are not lost


def test_git_commit_tag_inside_a_repository(
    sqlite_uri: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    git = shutil.which("git")
    if git is None:
        pytest.skip("git is not installed")
    repo = tmp_path / "repo"
    repo.mkdir()
    env_git = [
        git,
        "-c",
        "user.name=t",
        "-c",
        "user.email=t@example.com",
        "-c",
        "init.defaultBranch=main",
    ]
    subprocess.run([*env_git, "init", "-q"], cwd=repo, check=True)
    subprocess.run([*env_git, "commit", "-q", "--allow-empty", "-m", "x"], cwd=repo, check=True)
    head = subprocess.run(
        [git, "rev-parse", "HEAD"], cwd=repo, check=True, capture_output=True, text=True
    ).stdout.strip()
    monkeypatch.chdir(repo)
    with stage_run("collect", {}) as run:
        pass
    assert get_run(run.run_id).data.tags["git_commit"] == head


def test_disabled_run_is_a_no_op_and_never_imports_mlflow(tmp_path: Path) -> None:
    db = tmp_path / "mlflow.db"
    script = f"""
import os, sys
os.environ["MLFLOW_TRACKING_URI"] = "sqlite:///{db}"
from socnav_wm.tracking import stage_run
with stage_run("collect", {{"seed": 1}}, enabled=False) as run:
    run.log_metrics({{"x": 1.0}}, step=0)
    run.log_params({{"y": 2}})
    run.log_artifact("does-not-matter.txt")
    run.log_figure(None, "f.png")
    run.log_text("t", "t.txt")
    run.set_tag("k", "v")
    run.flush()
assert run.run_id is None
assert "mlflow" not in sys.modules, "mlflow was imported"
"""
    subprocess.run([sys.executable, "-c", script], cwd=tmp_path, check=True, env=_env())
    assert list(tmp_path.iterdir()) == []  # no mlflow.db, no mlruns/


def test_importing_the_pipeline_does_not_import_mlflow() -> None:
    script = (
        "import sys, socnav_wm.config, socnav_wm.io, socnav_wm.progress, socnav_wm.tracking\n"
        "assert 'mlflow' not in sys.modules\n"
        "assert 'rich.progress' not in sys.modules\n"
    )
    subprocess.run([sys.executable, "-c", script], check=True, env=_env())


def test_unreachable_server_fails_fast(monkeypatch: pytest.MonkeyPatch) -> None:
    uri = "http://127.0.0.1:9"  # the discard port: nothing listens on loopback
    start = time.monotonic()
    with pytest.raises(TrackingError) as info:
        check_tracking(uri)
    assert time.monotonic() - start < 3.5
    assert str(info.value) == (
        "MLflow tracking server http://127.0.0.1:9 is unreachable (connection refused); "
        "set MLFLOW_TRACKING_URI or pass --no-tracking"
    )
    monkeypatch.setenv("MLFLOW_TRACKING_URI", uri)
    with pytest.raises(TrackingError), stage_run("collect", {}):
        pytest.fail("the stage body must not run")


def test_health_endpoint_is_checked() -> None:
    status = {"code": 200}

    class Health(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:  # noqa: N802 - http.server's naming
            self.send_response(status["code"] if self.path == "/health" else 404)
            self.end_headers()
            self.wfile.write(b"OK")

        def log_message(self, *args: object) -> None:
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Health)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    uri = f"http://127.0.0.1:{server.server_address[1]}"
    try:
        check_tracking(uri)
        check_tracking(uri + "/")
        status["code"] = 503
        with pytest.raises(TrackingError, match=r"answered HTTP 503 on /health; set MLFLOW"):
            check_tracking(uri)
    finally:
        server.shutdown()
        server.server_close()


def test_password_is_not_shown_in_errors() -> None:
    with pytest.raises(TrackingError) as info:
        check_tracking("http://alice:secret@127.0.0.1:9")
    assert "secret" not in str(info.value)
    assert "alice:***@127.0.0.1:9" in str(info.value)


def test_sqlite_in_a_missing_directory_is_an_error(tmp_path: Path) -> None:
    uri = f"sqlite:///{tmp_path / 'nope' / 'mlflow.db'}"
    with pytest.raises(TrackingError, match="does not exist; set MLFLOW_TRACKING_URI"):
        check_tracking(uri)
    check_tracking(f"sqlite:///{tmp_path / 'mlflow.db'}")  # an existing directory is fine
    check_tracking(f"file://{tmp_path / 'new' / 'mlruns'}")  # MLflow creates missing levels
    assert list(tmp_path.iterdir()) == []  # checking creates nothing


def test_default_uri_is_sqlite_at_the_repository_root(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    monkeypatch.delenv("DVC_ROOT", raising=False)
    repo = tmp_path / "repo"
    (repo / "socnav_wm").mkdir(parents=True)
    (repo / "dvc.yaml").write_text("stages: {}\n")
    monkeypatch.chdir(repo / "socnav_wm")  # a command started below the root
    assert tracking_uri() == f"sqlite:///{repo.resolve()}/mlflow.db"
    # Under `dvc exp run --queue/--temp`, DVC_ROOT names the user's repository, not the
    # temporary workspace the stage runs in.
    monkeypatch.setenv("DVC_ROOT", str(tmp_path))
    assert tracking_uri() == f"sqlite:///{tmp_path.resolve()}/mlflow.db"
    monkeypatch.setenv("MLFLOW_TRACKING_URI", "http://example:5000")
    assert tracking_uri() == "http://example:5000"


def _env() -> dict[str, str]:
    import os

    root = str(Path(__file__).resolve().parents[1])
    env = dict(os.environ)
    env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
    return env


def test_an_unwritable_artifact_store_fails_before_the_run_opens(
    sqlite_uri: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The pre-flight checks the experiment's artifact folder, not only the database's."""
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("MLFLOW_EXPERIMENT_NAME", "blocked")
    client = mlflow.tracking.MlflowClient()
    client.create_experiment("blocked", artifact_location=(blocker / "mlruns").as_uri())
    ran = False
    with pytest.raises(TrackingError, match="artifact store") as error, stage_run("collect", {}):
        ran = True
    assert not ran and "\n" not in str(error.value) and "is not a directory" in str(error.value)
    experiment = client.get_experiment_by_name("blocked")
    assert client.search_runs([experiment.experiment_id]) == []


def test_the_experiment_opens_in_mlflow_3s_model_training_view(sqlite_uri: str) -> None:
    with stage_run("collect", {}):
        pass
    experiment = mlflow.tracking.MlflowClient().get_experiment_by_name("socnav-wm")
    assert experiment.tags["mlflow.experimentKind"] == "custom_model_development"


def test_headline_metrics_are_the_runs_description(sqlite_uri: str) -> None:
    """The UI's first view: the experiment's description, and each run's few headline metrics
    (tagged, and its description), each metric logged once."""
    with stage_run("evaluate/orca", {}) as run:
        run.log_metrics({"success": 0.9, "success_ci_low": 0.8})
        run.log_headline({"success": 0.9, "simulation_time": 31.5}, units={"simulation_time": "s"})
    result = get_run(run.run_id)
    assert result.data.tags["headline_metrics"] == "success,simulation_time"
    assert result.data.tags["mlflow.note.content"] == "success 0.9; simulation_time 31.5 s"
    client = mlflow.tracking.MlflowClient()
    assert len(client.get_metric_history(run.run_id, "success")) == 1
    assert result.data.metrics["simulation_time"] == 31.5
    experiment = client.get_experiment_by_name("socnav-wm")
    assert "headline_metrics" in experiment.tags["mlflow.note.content"]
