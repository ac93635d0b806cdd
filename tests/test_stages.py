"""Every stage through the CLI, on tiny params, with a real MLflow SQLite store."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
import torch
import yaml
from typer.testing import CliRunner

from socnav_wm.cli import app
from tests.conftest import tiny_params

TINY = tiny_params()

runner = CliRunner()


def _invoke(*args: str):
    result = runner.invoke(app, list(args))
    assert result.exit_code == 0, result.output
    return result


def test_collect_vae_lstm_write_every_output_and_mlflow_runs(workdir: Path) -> None:
    _invoke("collect")
    _invoke("train-vae", "--device", "auto")  # the params file says cpu
    out = _invoke("train-lstm").output
    assert "1-step latent MSE" in out

    assert list((workdir / "data/rollouts").glob("shard-*.parquet"))
    resolved = yaml.safe_load((workdir / "data/rollouts/params.yaml").read_text())
    assert resolved["collect"]["episodes"] == 40 and resolved["seed"] == 1
    assert set(resolved) == {"seed", "env", "collect"}  # only what collect reads
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
    assert vae_run.data.params["vae.device"] == "auto"  # the run logs what --device set
    assert yaml.safe_load((workdir / "models/vae.params.yaml").read_text())["vae"]["device"] == (
        "auto"
    )
    assert len(client.get_metric_history(vae_run.info.run_id, "val_loss")) == 3
    artifacts = {a.path for a in client.list_artifacts(vae_run.info.run_id)}
    assert {"vae.pt", "vae.params.yaml", "figures"} <= artifacts
    # The models as MLflow logged models of their runs (tests/test_logged_models.py checks
    # them all), with the weights of the pipeline's files.
    import mlflow.pytorch

    from socnav_wm.worldmodel.files import load_lstm, load_vae

    lstm_run = next(run for run in runs if run.data.tags["stage"] == "train-lstm")
    vae = load_vae(workdir / "models/vae.pt")
    logged = mlflow.pytorch.load_model(f"runs:/{vae_run.info.run_id}/vae").vae
    obs = torch.randn(5, vae.input_dim, dtype=vae.mu_head.weight.dtype)
    assert torch.equal(logged.encode(obs)[0], vae.encode(obs)[0])
    lstm = load_lstm(workdir / "models/lstm.pt")
    logged = mlflow.pytorch.load_model(f"runs:/{lstm_run.info.run_id}/lstm").lstm
    pairs = zip(logged.parameters(), lstm.parameters(), strict=True)
    assert all(torch.equal(a, b) for a, b in pairs)


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
        # Sizes the machine cannot hold: refused in one line before any work.
        (["collect", "--set", "collect.episodes=1000000000000"], "collect.episodes: "),
        (["collect", "--set", "env.num_humans=100000"], "env.num_humans: 100000 humans"),
        (
            [
                "train-agent",
                "--variant",
                "dueling-dqn",
                "--no-tracking",
                "--set",
                "agent.num_envs=100000000",
                "--set",
                "agent.buffer_size=100000000",
            ],
            "num_envs: 100,000,000 environments would take",
        ),
        (
            [
                "train-agent",
                "--variant",
                "dueling-dqn",
                "--no-tracking",
                "--set",
                "agent.buffer_size=100000000000",
            ],
            "agent.buffer_size: a replay buffer of 100,000,000,000 transitions would take",
        ),
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


def _runs(stage_prefix: str) -> list:
    from mlflow.tracking import MlflowClient

    client = MlflowClient()
    experiment = client.get_experiment_by_name("socnav-wm")
    runs = client.search_runs([experiment.experiment_id])
    return [run for run in runs if run.data.tags["stage"].startswith(stage_prefix)]


def test_agents_evaluation_and_report_write_every_output(workdir: Path) -> None:
    for command in ("collect", "train-vae", "train-lstm"):
        _invoke(command, "--no-tracking", "--quiet")
    for variant in ("dueling-dqn", "2stepahead-maspm"):
        for seed in ("0", "1"):
            out = _invoke("train-agent", "--variant", variant, "--seed", seed, "--quiet").output
            assert "greedy success" in out
            assert (workdir / f"models/agents/{variant}/seed-{seed}.pt").is_file()
            assert (workdir / f"models/agents/{variant}/seed-{seed}.params.yaml").is_file()
            log = pq.read_table(workdir / f"data/training/{variant}/seed-{seed}.parquet")
            assert log.num_rows == 30 and log["episode"].to_pylist() == list(range(1, 31))
            summary = json.loads(
                (workdir / f"metrics/agents/{variant}/seed-{seed}.json").read_text()
            )
            assert summary["episodes"] == 30 and summary["greedy_episodes"] == 8
            assert 10 <= summary["selected_episode"] <= 30  # one of the greedy runs' weights
            assert summary["final_success_rate"] == pytest.approx(
                float(np.mean(log["success"].to_numpy()[-10:]))  # agent.solved_window
            )
    # A finished run leaves no checkpoint behind (they hold the replay buffer).
    assert not list((workdir / "checkpoints").rglob("*.ckpt"))

    for method in ("dueling-dqn", "2stepahead-maspm", "orca", "sfm"):
        _invoke("evaluate", "--method", method, "--quiet")
        episodes = pq.read_table(workdir / f"data/eval/{method}.parquet")
        seeds = {-1} if method in ("orca", "sfm") else {0, 1}
        assert set(episodes["training_seed"].to_pylist()) == seeds
        assert episodes.num_rows == 6 * len(seeds)
        assert (workdir / f"data/eval/{method}-trajectories.parquet").is_file()
        metrics = json.loads((workdir / f"metrics/eval/{method}.json").read_text())
        success = metrics["metrics"]["success"]
        assert success["mean"] == pytest.approx(float(np.mean(episodes["success"].to_numpy())))

    # A report of other evaluations leaves the README's results block alone.
    readme = workdir / "README.md"
    readme.write_text("<!-- socnav-wm:results -->\n<!-- /socnav-wm:results -->\n")
    other = ("--out-dir", "other", "--metrics", "other/report.json", "--no-tracking")
    _invoke("report", *other)
    assert (workdir / "other" / "summary.md").is_file()
    assert readme.read_text() == "<!-- socnav-wm:results -->\n<!-- /socnav-wm:results -->\n"
    out = _invoke("report").output
    assert "`dueling-dqn` |" in readme.read_text()
    assert "missing: wm-dueling-dqn, 2stepahead, maspm" in out
    for path in ("summary.md", "pareto.json", "claims.json", "figures/histograms.png",
                 "figures/training_curves.png", "figures/scenarios.gif"):  # fmt: skip
        assert (workdir / "reports" / path).is_file(), path
    report = json.loads((workdir / "metrics/report.json").read_text())
    assert report["methods_present"] == ["dueling-dqn", "2stepahead-maspm", "orca", "sfm"]

    # MLflow: one run per agent and seed, one per evaluated method, and the report's.
    agents = _runs("train-agent/")
    assert sorted(r.data.tags["stage"] for r in agents) == [
        "train-agent/2stepahead-maspm/seed-0", "train-agent/2stepahead-maspm/seed-1",
        "train-agent/dueling-dqn/seed-0", "train-agent/dueling-dqn/seed-1",
    ]  # fmt: skip
    from mlflow.tracking import MlflowClient

    client = MlflowClient()
    run = agents[0]
    assert client.get_metric_history(run.info.run_id, "success_rate")
    assert "greedy_success_rate" in run.data.metrics
    selection = client.get_metric_history(run.info.run_id, "selection_success_rate")
    assert len(selection) == 3 and max(m.step for m in selection) == 30  # episodes 10, 20, 30
    evaluations = {r.data.tags["method"]: r for r in _runs("evaluate/")}
    assert set(evaluations) == {"dueling-dqn", "2stepahead-maspm", "orca", "sfm"}
    assert "success" in evaluations["orca"].data.metrics
    # For comparing methods in MLflow: the method and variant as params, per-seed metrics, the
    # evaluation linked to the trainings whose weights it used, the machine it ran on.
    agent_eval = evaluations["dueling-dqn"]
    assert agent_eval.data.params["method"] == "dueling-dqn"
    assert {"seed-0.success", "seed-1.success"} <= set(agent_eval.data.metrics)
    trained = {r.data.tags["stage"]: r.info.run_id for r in agents}
    assert agent_eval.data.tags["training_runs"].split(",") == [
        trained["train-agent/dueling-dqn/seed-0"], trained["train-agent/dueling-dqn/seed-1"]
    ]  # fmt: skip
    assert agents[0].data.params["variant"] == agents[0].data.tags["variant"]
    assert "machine.cpu" in agents[0].data.tags and "machine.torch_threads" in agents[0].data.tags
    # The agent as a logged model of its run: the agent file's Q-network in a greedy policy.
    import mlflow.pytorch

    from socnav_wm.agents.agent_file import load_agent

    maspm_run = trained["train-agent/2stepahead-maspm/seed-0"]
    q = load_agent(workdir / "models/agents/2stepahead-maspm/seed-0.pt").q_network
    logged = mlflow.pytorch.load_model(f"runs:/{maspm_run}/2stepahead-maspm-seed-0").q_network
    features = torch.randn(3, q.input_dim, dtype=next(q.parameters()).dtype)
    assert torch.equal(logged(features), q(features))
    experiment = client.get_experiment_by_name("socnav-wm")
    assert experiment.tags["mlflow.experimentKind"] == "custom_model_development"
    (report_run,) = _runs("report")
    assert any(k.startswith("claim.") for k in report_run.data.tags)
    figures = {a.path for a in client.list_artifacts(report_run.info.run_id, "figures")}
    assert "figures/histograms.png" in figures


def test_train_agent_resumes_its_own_checkpoint(workdir: Path) -> None:
    args = ("train-agent", "--variant", "dueling-dqn", "--no-tracking", "--quiet")
    _invoke(*args, "--keep-checkpoint")
    (checkpoint,) = (workdir / "checkpoints/dueling-dqn").glob("seed-0-*.ckpt")
    first = torch.load(workdir / "models/agents/dueling-dqn/seed-0.pt", weights_only=True)
    resumed = _invoke(*args, "--resume")
    assert f"resuming from {checkpoint.relative_to(workdir)}" in resumed.output
    assert not checkpoint.exists()
    second = torch.load(workdir / "models/agents/dueling-dqn/seed-0.pt", weights_only=True)
    for key, value in first["q_network"]["state_dict"].items():
        assert torch.equal(value, second["q_network"]["state_dict"][key]), key
    # Another parameter value is another run: its checkpoint has another name.
    _invoke(*args, "--keep-checkpoint", "--set", "agent.gamma=0.9")
    (other,) = (workdir / "checkpoints/dueling-dqn").glob("seed-0-*.ckpt")
    assert other.name != checkpoint.name


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["train-agent", "--variant", "dqn"], "unknown 'dqn'"),
        (["train-agent", "--variant", "maspm", "--vae", "no.pt"], "no.pt"),
        (["train-agent", "--variant", "maspm", "--set", "agent.gamma=2"], "agent.gamma"),
        (["evaluate", "--method", "astar"], "--method: unknown 'astar'"),
        (["evaluate", "--method", "maspm"], "models/agents/maspm/seed-0.pt: no such agent file"),
        (["evaluate", "--method", "orca", "--set", "baselines.orca={radius: 1}"], "radius"),
        (["report", "--set", "report.reference=me"], "report.reference"),
        (["bench", "train", "--variant", "dqn"], "unknown 'dqn'"),
    ],
)
def test_agent_and_evaluation_commands_reject_bad_input(
    workdir: Path, args: list[str], message: str
) -> None:
    result = runner.invoke(app, [*args, "--no-tracking"] if args[0] != "bench" else args)
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and message in lines[0]


@pytest.mark.parametrize(
    "args",
    [
        ["train-vae", "--device", "cuda"],
        ["train-lstm", "--device", "cuda"],
        ["train-agent", "--variant", "maspm", "--device", "cuda"],
        ["train-agent", "--variant", "maspm", "--set", "agent.device=cuda"],
        ["evaluate", "--method", "orca", "--device", "cuda"],
        ["bench", "train", "--variant", "maspm", "--device", "cuda"],
    ],
)
def test_cuda_without_a_gpu_is_one_line_before_any_run(
    workdir: Path, monkeypatch: pytest.MonkeyPatch, args: list[str]
) -> None:
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1, result.output
    assert lines[0] == (
        f"error: device 'cuda': CUDA is not available here (torch {torch.__version__}); "
        "use auto or cpu"
    )
    assert not (workdir / "mlflow.db").exists()  # no MLflow run was opened


def test_stage_functions_run_without_the_cli(tmp_path: Path) -> None:
    """The stage bodies are library functions: called directly on the params file plus the
    tiny overlay, they write their outputs where they are told."""
    from socnav_wm.config import load_params
    from socnav_wm.stages import collect, train_vae
    from tests.conftest import TINY_OVERLAY

    root = Path(__file__).resolve().parents[1]
    params = load_params(root / "params.yaml", ["collect.episodes=12"], [TINY_OVERLAY])
    rollouts, vae = tmp_path / "rollouts", tmp_path / "vae.pt"
    message = collect.run(params, out=rollouts, metrics=tmp_path / "c.json", tracking=False)
    assert message.startswith("wrote 12 episodes")
    train_vae.run(
        params, rollouts=rollouts, out=vae, metrics=tmp_path / "v.json",
        history=tmp_path / "h.json", tracking=False,
    )  # fmt: skip
    assert vae.is_file() and (tmp_path / "vae.params.yaml").is_file()
    assert set(yaml.safe_load((tmp_path / "vae.params.yaml").read_text())) == {"seed", "vae"}


def test_sigterm_ends_the_run_killed_and_leaves_no_output(workdir: Path) -> None:
    """kill (SIGTERM) mid-stage: exit 143, the MLflow run KILLED (not RUNNING forever), and
    neither the output nor a temporary of it left behind."""
    import contextlib
    import os
    import signal
    import sqlite3
    import subprocess
    import sys
    import time

    from mlflow.tracking import MlflowClient

    cli = [sys.executable, "-c", "from socnav_wm.cli import app; app()"]
    process = subprocess.Popen(
        [*cli, "collect", "--quiet", "--set", "collect.episodes=200000"],
        env={**os.environ, "OMP_NUM_THREADS": "1"},
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    # Wait for the child's run, reading the database without touching its schema (a second
    # process creating MLflow's tables at the same time would race the child).
    database = workdir / "mlflow.db"
    deadline = time.monotonic() + 180
    running: list = []
    while time.monotonic() < deadline and not running and process.poll() is None:
        time.sleep(0.5)
        if database.exists():
            uri = f"file:{database}?mode=ro"
            with (
                contextlib.suppress(sqlite3.Error),
                contextlib.closing(sqlite3.connect(uri, uri=True)) as connection,
            ):
                query = "SELECT run_uuid FROM runs WHERE status = 'RUNNING'"
                running = connection.execute(query).fetchall()
    assert running, process.stderr.read() if process.poll() is not None else "no run"
    time.sleep(1.0)  # inside the collection loop
    process.send_signal(signal.SIGTERM)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 128 + signal.SIGTERM, stderr
    assert stderr.strip().splitlines()[-1].startswith("error: terminated")
    assert MlflowClient().get_run(running[0][0]).info.status == "KILLED"
    leftovers = (
        [p.name for p in (workdir / "data").glob("*")] if (workdir / "data").exists() else []
    )
    assert leftovers == [], leftovers


def test_an_unwritable_output_fails_before_the_work(workdir: Path) -> None:
    """train-vae with a metrics folder that cannot exist: one line, exit 2, before any
    training, and the model is not written either (a stage's outputs change as a set)."""
    _invoke("collect", "--no-tracking")
    (workdir / "blocked").write_text("a file where the metrics folder should be")
    result = runner.invoke(app, ["train-vae", "--no-tracking", "--metrics", "blocked/vae.json"])
    assert result.exit_code == 2, result.output
    assert result.output.strip() == (
        "error: blocked/vae.json: cannot be written "
        f"({(workdir / 'blocked').resolve()} is not a directory)"
    )
    assert not (workdir / "models").exists()
