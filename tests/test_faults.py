"""Bad input and faults of the machine end in one line naming the problem and exit status 2,
with nothing written or everything rolled back: memory a run cannot have, bounds of the
parameters (planning horizon, benchmark episodes, seeds, scenario ids, people in a room), a
full disk, an output that is a directory, an output set whose last rename fails, stages that
read what another process writes, a new MLflow store opened by several processes at once, the
claims of other studies, and a Ray cluster that does not answer. Tiny settings throughout."""

from __future__ import annotations

import errno
import json
import os
import shutil
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest
import torch
from typer.testing import CliRunner

from socnav_wm import resources
from socnav_wm.cli import app
from socnav_wm.cli.application import one_line_error
from socnav_wm.locks import lock_path
from tests.conftest import ROOT

runner = CliRunner()


def _line(*args: str) -> str:
    """The one line a command that must fail ends with (checks exit status 2)."""
    result = runner.invoke(app, [str(a) for a in args])
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.output
    return lines[0]


def _ok(*args: str) -> None:
    result = runner.invoke(app, [str(a) for a in args])
    assert result.exit_code == 0, result.output


def _written() -> list[Path]:
    """Files of the working directory but its params file."""
    return [p for p in Path(".").rglob("*") if p.is_file() and p.name != "params.yaml"]


def _leftovers(*folders: Path) -> list[Path]:
    """Hidden temporaries and set-aside copies of outputs left in ``folders``."""
    return [p for f in folders for p in f.glob(".*") if ".tmp-" in p.name or ".old-" in p.name]


# -- 1, 2: memory --------------------------------------------------------------------------


def test_allocations_that_fail_are_one_line(workdir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    torch_oom = RuntimeError(
        "[enforce fail at alloc_cpu.cpp:127] err == 0. DefaultCPUAllocator: can't allocate "
        "memory: you tried to allocate 4000000000000 bytes. Error code 12"
    )
    expected = "out of memory (PyTorch could not allocate 3.6 TiB); lower the sizes in params.yaml"
    assert one_line_error(torch_oom) == expected
    assert one_line_error(MemoryError()) == "out of memory; lower the sizes in params.yaml"
    assert one_line_error(RuntimeError("a bug")) is None  # keeps its traceback
    # A network that would not fit is refused before it is built, naming the parameter...
    _ok("collect", "--no-tracking", "--quiet")
    line = _line(
        "train-planning-model", "--set", "planning_model.hidden_dim=1000000", "--no-tracking"
    )
    assert line.startswith(
        "error: planning_model.hidden_dim: training the planning model (hidden_dim 1000000) "
        "would take 18.2 TiB, this machine has "
    )
    # ...and one whose allocation fails anyway is named too.
    monkeypatch.setattr(resources, "available_memory_bytes", lambda: 2**60)

    def build() -> torch.nn.Module:  # counted on the meta device, then out of memory
        if torch.empty(0).device.type != "meta":
            raise torch_oom
        return torch.nn.Linear(3, 9)

    with pytest.raises(resources.ResourceError) as info:
        resources.build_trainable("vae.hidden_dim", "the VAE (hidden_dim 9)", build)
    assert (
        str(info.value) == "vae.hidden_dim: out of memory building the VAE (hidden_dim 9); lower it"
    )


def test_one_runs_allocations_are_checked_together(
    workdir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # 1,000 environments (~14 MiB) and 75,000 transitions (~15 MiB) each fit in 20 MiB; not
    # both (10 million of each once passed two checks of 11.2 and 1.9 GiB, then met the OOM
    # killer).
    monkeypatch.setattr(resources, "available_memory_bytes", lambda: 20 * 2**20)
    args = ["train-agent", "--variant", "dueling-dqn", "--no-tracking", "--set"]
    line = _line(*args, "agent.num_envs=1000", "--set", "agent.buffer_size=75000")
    assert line.startswith(
        "error: agent.num_envs, agent.buffer_size, agent.select_episodes: together 1,000 "
        "environments ("
    )
    assert "+ a replay buffer of 75,000 transitions (14.3 MiB) +" in line
    assert line.endswith("this machine has 20.0 MiB available")
    assert _written() == []
    # Small sizes keep their units, not "0.0 GiB".
    monkeypatch.setattr(shutil, "disk_usage", lambda _: shutil._ntuple_diskusage(9, 9, 512))
    with pytest.raises(resources.ResourceError) as info:
        resources.check_disk("collect.episodes", 10_000, workdir, "3 episodes")
    assert str(info.value) == (
        f"collect.episodes: 3 episodes could take up to 9.8 KiB, {workdir} has 512 bytes free"
    )
    # The operating system's words, not "[Errno 2] No such file or directory: 'x'".
    missing = FileNotFoundError(errno.ENOENT, "No such file or directory", "x/y.pt")
    assert one_line_error(missing) == "x/y.pt: no such file or directory"
    assert _line("train-vae", "--rollouts", "nowhere", "--no-tracking") == (
        "error: nowhere: no such file or directory"
    )


# -- 3, 4, 5: bounds of the parameters -------------------------------------------------------


def test_work_without_end_and_values_the_kernels_cannot_take_are_refused(workdir: Path) -> None:
    assert _line(
        "evaluate", "--method", "cv-mpc", "--set", "planning.horizon=1000000", "--no-tracking"
    ) == (
        "error: --set planning.horizon=1000000: planning.horizon: 1000000 steps ahead is longer "
        "than an episode (env.max_steps 201); at most 201"
    )
    assert _line("bench", "collect", "--episodes", str(10**12)) == (
        "error: --episodes: must be in 1..100,000 (a benchmark row of minutes), "
        "got 1,000,000,000,000"
    )
    assert _line("render", "--scenario", str(10**20)) == (
        "error: --scenario: scenario ids are below 2**62 (the simulator's), "
        "got 100000000000000000000"
    )
    assert _line("collect", "--set", f"seed={2**70}", "--no-tracking") == (
        f"error: --set seed={2**70}: seed: must be < 2**63 (the simulator's seeds are 63-bit), "
        f"got {2**70}"
    )
    assert _line("collect", "--set", "env.num_humans=150", "--no-tracking") == (
        "error: --set env.num_humans=150: env.num_humans: 150 humans and their goals cannot be "
        "placed in a 10.0 m room without running out of spawn attempts (at most 40 here; or "
        "enlarge room_size)"
    )
    assert _written() == []


# -- 6: a full disk, an output that is a directory, a rename that fails ----------------------


def _disk_full(*args: object, **kwargs: object) -> None:
    raise OSError(errno.ENOSPC, "No space left on device")


def test_a_full_disk_ends_in_one_line_naming_the_output(
    workdir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _ok("collect", "--no-tracking", "--quiet")
    before = sorted(p.name for p in Path("data/rollouts").iterdir())
    with monkeypatch.context() as patch:  # the rollouts: pyarrow's writer
        patch.setattr(pq.ParquetWriter, "write_table", _disk_full)
        assert _line("collect", "--no-tracking", "--set", "seed=5") == (
            "error: no space left on device writing data/rollouts"
        )
    assert sorted(p.name for p in Path("data/rollouts").iterdir()) == before
    with monkeypatch.context() as patch:  # the metrics: a JSON file
        write_bytes = Path.write_bytes
        patch.setattr(
            Path,
            "write_bytes",
            lambda self, data: _disk_full() if ".json" in self.name else write_bytes(self, data),
        )
        assert _line("collect", "--no-tracking", "--set", "seed=5") == (
            "error: no space left on device writing metrics/collect.json"
        )
    with monkeypatch.context() as patch:  # the model: torch's zip writer cut short
        pos = RuntimeError("[enforce fail at inline_container.cc:626] . unexpected pos 64 vs 0")
        patch.setattr(torch, "save", lambda *a, **k: (_ for _ in ()).throw(pos))
        assert _line("train-vae", "--no-tracking") == (
            "error: no space left on device writing models/vae.pt"
        )
    with monkeypatch.context() as patch:  # an evaluation: a Parquet table
        patch.setattr(pq, "write_table", _disk_full)
        line = _line("evaluate", "--method", "cv-mpc", "--no-tracking")
        assert line.startswith("error: no space left on device writing data/eval/cv-mpc")
    assert not Path("models/vae.pt").exists() and not Path("data/eval/cv-mpc.parquet").exists()
    assert not _leftovers(Path("data"), Path("metrics"), Path("models"), Path("data/eval"))


def test_an_output_that_is_a_directory_is_refused_before_any_work(workdir: Path) -> None:
    Path("metrics/collect.json").mkdir(parents=True)
    assert _line("collect", "--no-tracking") == (
        "error: metrics/collect.json: is a directory, cannot be written as a file"
    )
    assert _written() == []


def test_a_rename_that_fails_rolls_the_whole_output_set_back(
    workdir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _ok("collect", "--no-tracking", "--quiet")
    _ok("train-vae", "--no-tracking", "--quiet")
    outputs = [
        Path(p)
        for p in ("models/vae.pt", "models/vae.params.yaml", "metrics/vae.json")
        + ("metrics/vae_history.json",)
    ]
    before = {path: path.read_bytes() for path in outputs}
    replace = os.replace

    def last_rename_fails(src: object, dst: object) -> None:
        if Path(dst).name == "vae_history.json" and ".tmp-" in Path(src).name:
            raise OSError(errno.EIO, "Input/output error", str(dst))
        replace(src, dst)

    monkeypatch.setattr(os, "replace", last_rename_fails)
    # Another model (two epochs): the model, its params and its metrics are renamed first.
    assert _line("train-vae", "--no-tracking", "--set", "vae.max_epochs=2") == (
        "error: metrics/vae_history.json: input/output error"
    )
    assert {path: path.read_bytes() for path in outputs} == before
    assert not _leftovers(Path("models"), Path("metrics"))


# -- 7, 8: processes at once -----------------------------------------------------------------


def test_stages_started_together_create_a_new_mlflow_store_once(tmp_path: Path) -> None:
    script = tmp_path / "stage.py"
    script.write_text(
        textwrap.dedent(
            """
            import sys, time
            import mlflow  # the import takes seconds: before the common start
            from socnav_wm.tracking import stage_run
            while time.time() < float(sys.argv[1]):
                time.sleep(0.005)
            with stage_run("stage", {"x": 1}, run_name=sys.argv[2]) as run:
                run.log_metrics({"m": 1.0})
            """
        )
    )
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    env = {**os.environ, "MLFLOW_TRACKING_URI": uri, "OMP_NUM_THREADS": "1"}
    start = str(time.time() + 15)
    stages = [
        subprocess.Popen(
            [sys.executable, str(script), start, f"stage-{i}"],
            env=env,
            cwd=ROOT,
            stderr=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        for i in range(3)
    ]
    errors = [stage.communicate(timeout=180)[1] for stage in stages]
    assert [stage.returncode for stage in stages] == [0, 0, 0], errors
    from mlflow import MlflowClient

    client = MlflowClient(tracking_uri=uri)
    experiment = client.get_experiment_by_name("socnav-wm")
    runs = client.search_runs([experiment.experiment_id])
    assert sorted(r.info.run_name for r in runs) == ["stage-0", "stage-1", "stage-2"]


def _hold(path: Path, exclusive: bool) -> subprocess.Popen:
    """Another process holding ``path``'s lock (exclusive: as a writer) until its stdin ends."""
    code = textwrap.dedent(
        f"""
        import fcntl, os, sys
        fd = os.open({str(lock_path(path))!r}, os.O_RDWR | os.O_CREAT)
        fcntl.flock(fd, fcntl.{"LOCK_EX" if exclusive else "LOCK_SH"})
        if {exclusive}:
            os.pwrite(fd, f"{{os.getpid()}}\\n".encode(), 0)
        print("held", flush=True)
        sys.stdin.read()
        """
    )
    holder = subprocess.Popen(
        [sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    assert holder.stdout is not None and holder.stdout.readline() == "held\n"
    return holder


def test_a_stage_refuses_to_start_while_another_process_writes_its_inputs(workdir: Path) -> None:
    _ok("collect", "--no-tracking", "--quiet")
    rollouts = Path("data/rollouts")
    writer = _hold(rollouts, exclusive=True)  # a `socnav-wm collect` rewriting the rollouts
    assert _line("train-vae", "--no-tracking") == (
        f"error: data/rollouts: being written by another socnav-wm process (pid {writer.pid}); "
        "wait for it to finish, then rerun"
    )
    writer.communicate("")
    assert not Path("models/vae.pt").exists()
    reader = _hold(rollouts, exclusive=False)  # a training reading them
    assert _line("collect", "--no-tracking", "--set", "seed=5") == (
        "error: data/rollouts: another socnav-wm process is reading or writing it; wait for it "
        "to finish, then rerun"
    )
    _ok("train-vae", "--no-tracking", "--quiet")  # readers share
    reader.communicate("")
    _ok("collect", "--no-tracking", "--quiet", "--set", "seed=5")  # nobody holds it any more


# -- 9, 10: the studies ----------------------------------------------------------------------


def test_claims_of_other_studies_write_no_document_and_garbage_is_refused(
    workdir: Path,
) -> None:
    shutil.copy(ROOT / "reports" / "claims.json", "claims.json")
    document = Path("docs/studies.md")  # the pipeline's document, relative to the working dir
    document.parent.mkdir()
    document.write_text("# Studies\n<!-- socnav-wm:claims -->\nold\n<!-- /socnav-wm:claims -->\n")
    before = document.read_text()
    args = ["study-claims", "--report-claims", "claims.json", "--no-tracking"]
    _ok(*args, "--studies-dir", "scratch")
    assert document.read_text() == before and Path("scratch/claims.md").is_file()
    Path("scratch/seeds").mkdir()
    Path("scratch/seeds/claims.json").write_text(json.dumps({"verdict": 3}))
    assert _line(*args, "--studies-dir", "scratch") == (
        "error: scratch/seeds/claims.json: not the seeds study's claims (socnav-wm sweep writes "
        "them)"
    )
    Path("scratch/seeds/claims.json").write_text("[{]")
    assert _line(*args, "--studies-dir", "scratch").startswith(
        "error: scratch/seeds/claims.json: not valid JSON ("
    )
    shutil.rmtree("scratch/seeds")
    _ok(*args, "--studies-dir", "scratch", "--document", str(document))  # asked for: written
    assert document.read_text() != before


def test_a_ray_cluster_that_does_not_answer_ends_in_one_line(
    workdir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from socnav_wm.config import ConfigError
    from socnav_wm.studies.runner import _time_limit, _TimeUp, check_reachable
    from socnav_wm.worldmodel.files import save_lstm, save_vae
    from tests.agents.conftest import tiny_world_model

    def no_answer(address: tuple[str, int], timeout: float) -> None:
        raise TimeoutError("timed out")

    with monkeypatch.context() as patch:  # a host that drops the connection attempt
        patch.setattr(socket, "create_connection", no_answer)
        with pytest.raises(ConfigError) as info:
            check_reachable("10.0.0.9:6379", timeout_s=0.5)
    assert str(info.value) == (
        "--address 10.0.0.9:6379: no Ray cluster answers there (no answer within 0.5 s)"
    )
    started = time.monotonic()  # and ray.init, which retries for ever, gets a time limit
    with pytest.raises(_TimeUp), _time_limit(0.2):
        time.sleep(5)
    assert time.monotonic() - started < 2
    vae, lstm = tiny_world_model()
    save_vae(workdir / "models" / "vae.pt", vae)
    save_lstm(workdir / "models" / "lstm.pt", lstm)
    sweep = ["sweep", "--variants", "dueling-dqn", "--seeds", "0", "--name", "x", "--no-tracking"]
    result = runner.invoke(app, [*sweep, "--address", "127.0.0.1:1"])
    assert result.exit_code == 2, result.output
    assert result.output.strip().splitlines()[-1] == (
        "error: --address 127.0.0.1:1: no Ray cluster answers there (connection refused)"
    )
