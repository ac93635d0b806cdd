"""The world-model stages through the CLI, on tiny params, with a real MLflow SQLite store."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from pipeline.cli import app

TINY = {
    "seed": 1,
    "collect": {"episodes": 40, "num_envs": 8, "max_rows_per_shard": 2000},
    "vae": {
        "hidden_dim": 32,
        "kl_weight": 0.1,
        "learning_rate": 0.003,
        "max_epochs": 3,
        "batch_size": 128,
        "device": "cpu",
    },
    "lstm": {
        "hidden_dim": 32,
        "seq_len": 8,
        "learning_rate": 0.005,
        "max_epochs": 6,
        "batch_size": 32,
        "device": "cpu",
    },
}

runner = CliRunner()


@pytest.fixture
def workdir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{tmp_path / 'mlflow.db'}")
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(TINY))
    return tmp_path


def _invoke(*args: str):
    result = runner.invoke(app, list(args))
    assert result.exit_code == 0, result.output
    return result


def test_collect_vae_lstm_write_every_output_and_mlflow_runs(workdir: Path) -> None:
    _invoke("collect")
    _invoke("train-vae")
    out = _invoke("train-lstm").output
    assert "1-step latent MSE" in out

    assert list((workdir / "data/rollouts").glob("shard-*.parquet"))
    resolved = yaml.safe_load((workdir / "data/rollouts/params.yaml").read_text())
    assert resolved["collect"]["episodes"] == 40 and resolved["seed"] == 1
    for path in ("models/vae.pt", "models/lstm.pt", "models/vae.params.yaml"):
        assert (workdir / path).is_file(), path
    vae = json.loads((workdir / "metrics/vae.json").read_text())
    lstm = json.loads((workdir / "metrics/lstm.json").read_text())
    assert vae["val_recon_mse"] < vae["baseline_mse"]
    assert lstm["one_step_mse"] < lstm["copy_last_one_step_mse"]
    history = json.loads((workdir / "metrics/vae_history.json").read_text())
    assert [row["epoch"] for row in history] == [1, 2, 3]

    from mlflow.tracking import MlflowClient

    client = MlflowClient()
    experiment = client.get_experiment_by_name("socnav-wm")
    runs = client.search_runs([experiment.experiment_id])
    stages = sorted(run.data.tags["stage"] for run in runs)
    assert stages == ["collect", "train-lstm", "train-vae"]
    vae_run = next(run for run in runs if run.data.tags["stage"] == "train-vae")
    assert vae_run.info.status == "FINISHED"
    assert vae_run.data.params["vae.hidden_dim"] == "32"
    assert len(client.get_metric_history(vae_run.info.run_id, "val_loss")) == 3
    artifacts = {a.path for a in client.list_artifacts(vae_run.info.run_id)}
    assert {"vae.pt", "figures"} <= artifacts


def test_overrides_apply_and_are_saved(workdir: Path) -> None:
    _invoke("collect", "--set", "collect.episodes=12", "--no-tracking")
    resolved = yaml.safe_load((workdir / "data/rollouts/params.yaml").read_text())
    assert resolved["collect"]["episodes"] == 12
    assert not (workdir / "mlflow.db").exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["collect", "--set", "collect.episodes=-3"], "collect.episodes"),
        (["collect", "--set", "collect.epsiodes=3"], "unknown key 'collect.epsiodes'"),
        (["collect", "--params", "missing.yaml"], "missing.yaml: file not found"),
        (["train-vae", "--rollouts", "nowhere"], "nowhere"),
        (["train-lstm", "--vae", "nothing.pt", "--no-tracking"], "nothing.pt"),
        (["train-vae", "--device", "tpu"], "--device: must be one of auto, cpu, cuda"),
    ],
)
def test_bad_input_gives_one_line_and_exit_2(workdir: Path, args: list[str], message: str) -> None:
    if args[0] == "train-lstm":
        _invoke("collect", "--no-tracking")
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and message in lines[0]


def test_unreachable_tracking_server_fails_before_any_work(
    workdir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("MLFLOW_TRACKING_URI", "http://127.0.0.1:9")
    result = runner.invoke(app, ["collect"])
    assert result.exit_code == 2
    assert "unreachable" in result.output
    assert not (workdir / "data").exists()


def test_a_failed_collect_keeps_the_previous_dataset(workdir: Path) -> None:
    _invoke("collect", "--no-tracking")
    before = sorted(p.name for p in (workdir / "data/rollouts").iterdir())
    bad = workdir / "bad.yaml"
    bad.write_text(yaml.safe_dump({**TINY, "env": {"num_humans": 90, "room_size": 4.0}}))
    result = runner.invoke(app, ["collect", "--params", str(bad), "--no-tracking"])
    assert result.exit_code != 0
    assert sorted(p.name for p in (workdir / "data/rollouts").iterdir()) == before
