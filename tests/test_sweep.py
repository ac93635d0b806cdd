"""socnav-wm sweep: the grid, its one-line errors, and real sweeps on a local Ray (2 CPUs) with a
real MLflow store: weights equal to the serial train-agent's, a failed run that does not stop the
others, finished runs skipped, an interrupted sweep that resumes from its checkpoints."""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest
import torch
import yaml
from typer.testing import CliRunner

from socnav_wm.agents.params import VARIANT_NAMES
from socnav_wm.cli import app
from socnav_wm.config import ConfigError, StudyParams, load_params
from socnav_wm.studies import (
    SweepResult,
    horizon_verdict,
    parse_grid,
    parse_seeds,
    plan_sweep,
    run_sources,
    seed_interval,
    study_from_options,
    training_claims,
    write_results,
)
from socnav_wm.worldmodel.files import save_lstm, save_vae
from tests.agents.conftest import tiny_world_model
from tests.conftest import tiny_params

runner = CliRunner()


@pytest.fixture
def sweepdir(workdir: Path) -> Path:
    """The tiny working directory with a tiny world model at the pipeline's paths."""
    vae, lstm = tiny_world_model()
    (workdir / "models").mkdir()
    save_vae(workdir / "models" / "vae.pt", vae)
    save_lstm(workdir / "models" / "lstm.pt", lstm)
    return workdir


def _invoke(*args: str):
    return runner.invoke(app, list(args), catch_exceptions=False)


def _weights(path: Path) -> dict[str, torch.Tensor]:
    from socnav_wm.agents.agent_file import load_agent

    return load_agent(path).q_network.state_dict()


# ------------------------------------------------------------------------------- the grid


def test_seeds_and_grid_parse_like_the_command_line() -> None:
    assert parse_seeds("0-4") == [0, 1, 2, 3, 4]
    assert parse_seeds("0,2,7") == [0, 2, 7]
    assert parse_seeds("1-2,5") == [1, 2, 5]
    assert parse_grid(["agent.horizon=2,4", "agent.sort_humans=true,false"]) == {
        "agent.horizon": [2, 4],
        "agent.sort_humans": [True, False],
    }
    for bad in ("4-0", "a", "0,0", ""):
        with pytest.raises(ConfigError, match="--seeds"):
            parse_seeds(bad)
    for bad in (["agent.horizon"], ["=2"], ["agent.horizon=2", "agent.horizon=4"]):
        with pytest.raises(ConfigError, match="--grid"):
            parse_grid(bad)


def test_intervals_over_seeds_stay_in_the_metric_range() -> None:
    mean, low, high = seed_interval([0.0, 1.0], "success")
    assert (mean, low, high) == (0.5, 0.0, 1.0)  # the t interval itself is far wider
    mean, low, high = seed_interval([10.0, 11.0, 12.0], "discomfort")  # t(0.975, 2) = 4.3027
    assert (low, high) == pytest.approx((11 - 4.302653 / 3**0.5, 11 + 4.302653 / 3**0.5))
    assert seed_interval([10.0, 30.0], "discomfort")[1] == 0.0  # never below zero
    assert seed_interval([3.0, 3.0], "train_cpu_s") == (3.0, 3.0, 3.0)
    assert all(math.isnan(bound) for bound in seed_interval([0.5], "success")[1:])  # one seed


def test_the_horizon_claim_is_checked_on_paired_seeds(sweepdir: Path) -> None:
    study = StudyParams(variants=["2stepahead"], seeds=[0, 1, 2], grid={"agent.horizon": [2, 8]})
    plan = plan_sweep("h", study)

    def verdict(success_gain: list[float], cpu_gain: list[float]) -> str:
        outcome = SweepResult(plan)
        for run in plan.runs:
            longer = run.values[0][1] == 8
            metrics = {
                "success": 0.8 + (success_gain[run.seed] if longer else 0.0),
                "train_cpu_s": 300.0 + (cpu_gain[run.seed] if longer else 0.0),
            }
            outcome.results[run] = {"status": "done", "metrics": metrics}
        result = horizon_verdict(outcome)
        assert result is not None and len(result["comparisons"]) == 1
        return result["verdict"]

    assert verdict([0.0, -0.01, 0.01], [100, 110, 120]).startswith("holds")
    assert verdict([0.10, 0.11, 0.12], [100, 110, 120]).startswith(
        "does not hold (2stepahead at 8 succeeds more"
    )
    assert verdict([0.0, 0.0, 0.0], [-50, 40, 5]).startswith("not decided")
    # Not a horizon study: no verdict.
    other = plan_sweep("g", StudyParams(variants=["maspm"], seeds=[0], grid={"agent.gamma": [0.9]}))
    assert horizon_verdict(SweepResult(other)) is None


def _seeds_study(seeds: list[int]) -> SweepResult:
    """A finished `seeds` study of every variant, its results written: 2stepahead succeeds from
    its 50th episode on, the others from their 150th; the world-model variants end at a higher
    return than dueling-dqn, 2stepahead-maspm at the highest."""
    import pyarrow as pa

    plan = plan_sweep("seeds", StudyParams(variants=list(VARIANT_NAMES), seeds=seeds))
    outcome = SweepResult(plan)
    for run in plan.runs:
        first = 50 if run.variant == "2stepahead" else 150
        final = {"dueling-dqn": 0.2, "2stepahead-maspm": 0.9}.get(run.variant, 0.5)
        success = [episode >= first + run.seed for episode in range(300)]
        returns = [final + 0.01 * run.seed if episode >= 100 else 0.0 for episode in range(300)]
        path = plan.run_dir(run) / "training" / run.variant / f"seed-{run.seed}.parquet"
        path.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(pa.table({"return": returns, "success": success}), path)
        outcome.results[run] = {"status": "done", "metrics": {"success": 0.9}}
    write_results(outcome)
    return outcome


def test_a_study_without_a_grid_checks_the_training_claims(sweepdir: Path) -> None:
    def claims(seeds: list[int]) -> dict[str, str]:
        plan = _seeds_study(seeds).plan
        found = json.loads((plan.out_dir / "claims.json").read_text())
        assert "## The paper's training claims" in (plan.out_dir / "summary.md").read_text()
        return {claim["id"]: claim["verdict"] for claim in found}

    assert claims([0, 1, 2, 3, 4]) == {
        "training-twostep-maspm-highest": "reproduced",
        "training-world-models-higher": "reproduced",
        "training-twostep-fastest": "reproduced",
    }
    # Three seeds a side cannot decide them (Mann–Whitney's smallest p is 0.1).
    assert set(claims([0, 1, 2]).values()) == {"inconclusive"}
    # A study with a grid mixes its grid values' seeds: no training claims.
    grid = plan_sweep(
        "g", StudyParams(variants=list(VARIANT_NAMES[:2]), seeds=[0], grid={"agent.gamma": [0.9]})
    )
    assert training_claims(SweepResult(grid)) is None


def test_study_claims_take_each_claim_from_the_study_that_checks_it(sweepdir: Path) -> None:
    from socnav_wm.evaluation.paper import CLAIMS
    from socnav_wm.stages import study_claims

    # The report: every claim inconclusive, one check each (its claims.json's shape).
    report = {
        claim.claim_id: {
            "statement": claim.statement,
            "source": claim.source,
            "kind": claim.kind,
            "verdict": "inconclusive",
            "note": "",
            "checks": [{"status": "inconclusive", "evidence": f"report on {claim.claim_id}"}],
        }
        for claim in CLAIMS
    }
    (sweepdir / "reports").mkdir()
    (sweepdir / "reports" / "claims.json").write_text(json.dumps(report))
    (sweepdir / "docs").mkdir()
    document = sweepdir / "docs" / "studies.md"
    document.write_text("# Studies\n\n<!-- socnav-wm:claims -->\n<!-- /socnav-wm:claims -->\nend\n")

    def merged() -> dict[str, dict]:
        result = _invoke("study-claims", "--no-tracking")
        assert result.exit_code == 0, result.output
        found = json.loads((sweepdir / "reports" / "studies" / "claims.json").read_text())
        return {claim["id"]: claim for claim in found}

    # No study has run: the report decides, and the look-ahead claim is not checked.
    before = merged()
    assert set(before) == {*report, study_claims.HORIZON_ID}
    assert {c["evidence"] for i, c in before.items() if i in report} == {"the pipeline's report"}
    assert before[study_claims.HORIZON_ID]["verdict"] == "not checked"
    # The seeds study (5 seeds; 2stepahead learns first, the world models end higher) decides
    # the training claims; the horizon study the look-ahead claim.
    _seeds_study([0, 1, 2, 3, 4])
    horizon = plan_sweep(
        "horizon",
        StudyParams(variants=["2stepahead"], seeds=[0, 1, 2], grid={"agent.horizon": [2, 8]}),
    )
    outcome = SweepResult(horizon)
    for run in horizon.runs:
        longer = run.values[0][1] == 8
        metrics = {"success": 0.8, "train_cpu_s": 300.0 + (100.0 + run.seed if longer else 0)}
        outcome.results[run] = {"status": "done", "metrics": metrics}
    write_results(outcome)
    after = merged()
    for claim_id, claim in after.items():
        if claim_id.startswith("training-"):
            assert claim["verdict"] == "reproduced", claim_id
            assert claim["evidence"] == "the `seeds` study, 5 seeds a variant"
        elif claim_id in report:
            assert claim == before[claim_id]
    assert after[study_claims.HORIZON_ID]["verdict"] == "reproduced"
    assert after[study_claims.HORIZON_ID]["evidence"] == "the `horizon` study, 3 seeds a variant"
    text = document.read_text()
    assert text.startswith("# Studies") and text.endswith("end\n")
    assert "| **reproduced** | the `horizon` study, 3 seeds a variant |" in text
    assert "INCONCLUSIVE" in (sweepdir / "reports" / "studies" / "claims.md").read_text()


def test_study_claims_without_the_report_fail_in_one_line(sweepdir: Path) -> None:
    result = runner.invoke(app, ["study-claims", "--no-tracking"])
    assert result.exit_code != 0
    assert result.output.strip().splitlines() == [
        "error: reports/claims.json: no report claims (run `dvc repro report`)"
    ]


def test_a_study_is_validated_like_every_section(tmp_path: Path) -> None:
    path = tmp_path / "params.yaml"
    for text, message in (
        ("studies: {s: {variants: [dqn], seeds: [0]}}", "unknown 'dqn'"),
        ("studies: {s: {variants: [maspm], seeds: 3-1}}", "a range like '0-4'"),
        ("studies: {s: {variants: [maspm], seeds: [0], grid: {agent.gamma: []}}}", "no values"),
        ("studies: {s: {variants: [maspm], seeds: [0], gird: {}}}", "studies.s.gird"),
    ):
        path.write_text(text + "\n")
        with pytest.raises(ConfigError, match=message):
            load_params(path)
    path.write_text("studies: {s: {variants: [maspm], seeds: 0-2}}\n")
    assert load_params(path).studies["s"].seeds == [0, 1, 2]


def test_the_shipped_studies_resolve_every_run(sweepdir: Path) -> None:
    params = load_params("params.yaml")
    horizon = plan_sweep("horizon", params.studies["horizon"])
    assert len(horizon.runs) == 2 * 4 * 5
    assert {p.agent.horizon for p in horizon.params.values()} == {2, 4, 8, 16}
    assert len(set(horizon.fingerprints.values())) == len(horizon.runs)
    assert horizon.runs_dir == Path("data/studies/horizon")
    assert len(plan_sweep("seeds", params.studies["seeds"]).runs) == 5 * 5


def test_only_the_runs_that_read_the_world_model_depend_on_its_files(sweepdir: Path) -> None:
    study = StudyParams(variants=["dueling-dqn", "maspm"], seeds=[0])
    before = plan_sweep("s", study).fingerprints
    vae, _ = tiny_world_model(seed=1)
    save_vae(sweepdir / "models" / "vae.pt", vae)
    after = plan_sweep("s", study).fingerprints
    changed = {run.variant for run in before if before[run] != after[run]}
    assert changed == {"maspm"}  # dueling-dqn's runs are kept across a new world model


def test_an_edit_of_the_code_a_run_executes_makes_its_result_stale(
    sweepdir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import socnav_wm.stages.deps as deps

    sources = run_sources()
    assert "socnav_wm/env/reward.py" in sources and "socnav_wm/agents/learner.py" in sources
    assert "socnav_wm/studies/runner.py" not in sources
    assert "socnav_wm/stages/report.py" not in sources
    # The configuration acts through the parameters, fingerprinted themselves.
    assert "socnav_wm/config.py" not in sources and "socnav_wm/studies/params.py" not in sources
    copy = tmp_path / "src" / "socnav_wm"
    shutil.copytree(deps.PACKAGE_ROOT, copy, ignore=shutil.ignore_patterns("__pycache__"))
    monkeypatch.setattr(deps, "PACKAGE_ROOT", copy)
    study = StudyParams(variants=["dueling-dqn", "maspm"], seeds=[0, 1])
    before = plan_sweep("s", study).fingerprints
    # Code no run executes, or only through the parameters.
    for outside in ("studies/runner.py", "studies/params.py", "stages/report.py"):
        (copy / outside).write_text((copy / outside).read_text() + "# an edit\n")
    assert plan_sweep("s", study).fingerprints == before
    (copy / "env" / "reward.py").write_text((copy / "env" / "reward.py").read_text() + "# x\n")
    after = plan_sweep("s", study).fingerprints
    assert all(after[run] != before[run] for run in before)


def test_a_bad_grid_fails_in_one_line_before_any_run(sweepdir: Path) -> None:
    study = StudyParams(variants=["maspm"], seeds=[0], grid={"agent.horizn": [2]})
    with pytest.raises(ConfigError, match=r"sweep s, run maspm/agent\.horizn=2/seed-0: .*horizn"):
        plan_sweep("s", study)
    study = StudyParams(variants=["maspm"], seeds=[0], grid={"agent.horizon": [0]})
    with pytest.raises(ConfigError, match="agent.horizon"):
        plan_sweep("s", study)
    with pytest.raises(FileNotFoundError, match="no such world-model file"):
        plan_sweep("s", study, vae=Path("nowhere.pt"))
    with pytest.raises(ConfigError, match="--variants: required without --study"):
        study_from_options(None, None, "0", [])
    result = runner.invoke(app, ["sweep", "--study", "nope"])
    assert result.exit_code == 2 and "no study 'nope' in params.yaml" in result.output
    result = runner.invoke(app, ["sweep", "--variants", "maspm", "--seeds", "0"])
    assert result.exit_code == 2 and "--name: required without --study" in result.output


def test_without_ray_a_sweep_fails_in_one_line(
    sweepdir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray raises ImportError
    args = ["sweep", "--variants", "dueling-dqn", "--seeds", "0", "--name", "t", "--no-tracking"]
    result = runner.invoke(app, args)
    assert result.exit_code == 2
    assert result.output.strip().splitlines()[-1] == (
        "error: socnav-wm sweep needs Ray, which is not installed: pip install 'socnav-wm[sweep]'"
    )


def test_other_commands_do_not_import_ray() -> None:
    code = "import sys, socnav_wm.cli, socnav_wm.studies.runner; print('ray' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


# ------------------------------------------------------------------------------- real sweeps


def test_a_sweep_on_local_ray_equals_the_serial_runs_and_survives_a_failure(
    sweepdir: Path,
) -> None:
    from mlflow import MlflowClient

    args = [
        "sweep", "--variants", "dueling-dqn,2stepahead", "--seeds", "0-1",
        "--grid", "agent.gamma=0.9,0.99", "--name", "tiny", "--cpus", "2",
    ]  # fmt: skip
    # One run cannot write its folder (a file is in the way): it fails, the others go on.
    blocked = Path("data/studies/tiny/2stepahead__agent.gamma=0.99__seed-1")
    blocked.parent.mkdir(parents=True)
    blocked.write_text("in the way")
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    assert "1 of 8 runs failed (first: 2stepahead/agent.gamma=0.99/seed-1" in result.output

    table = pq.read_table("reports/studies/tiny/results.parquet").to_pylist()
    assert len(table) == 8
    by_run = {row["run"]: row for row in table}
    assert by_run["2stepahead/agent.gamma=0.99/seed-1"]["status"] == "failed"
    assert by_run["2stepahead/agent.gamma=0.99/seed-1"]["error"]
    assert {row["agent.gamma"] for row in table} == {"0.9", "0.99"}
    done = [row for row in table if row["status"] == "done"]
    assert len(done) == 7 and all(0.0 <= row["success"] <= 1.0 for row in done)
    assert all(row["node"] for row in done)  # the Ray node each ran on
    summary = Path("reports/studies/tiny/summary.md").read_text()
    assert "7 of 8 runs finished, 1 failed" in summary
    assert "| dueling-dqn | 0.9 | 2 |" in summary and "| 2stepahead | 0.99 | 1 |" in summary
    assert Path("reports/studies/tiny/figures/agent.gamma.png").stat().st_size > 1000

    # Each run is exactly train-agent with its --set values and the sweep's one torch thread:
    # the same weights, bit for bit (float32 sums of the world model depend on the threads).
    for variant, seed, gamma in (("dueling-dqn", 1, "0.9"), ("2stepahead", 0, "0.99")):
        _invoke(
            "train-agent", "--variant", variant, "--seed", str(seed), "--set",
            f"agent.gamma={gamma}", "--out-dir", "serial", "--threads", "1", "--no-tracking",
            "--quiet",
        )  # fmt: skip
        swept = Path(f"data/studies/tiny/{variant}__agent.gamma={gamma}__seed-{seed}")
        ours = _weights(swept / "agents" / variant / f"seed-{seed}.pt")
        serial = _weights(Path("serial") / variant / f"seed-{seed}.pt")
        assert ours.keys() == serial.keys()
        for key in ours:
            assert torch.equal(ours[key], serial[key]), (variant, key)

    # One MLflow parent run for the sweep, a child per run tagged with its grid values, and the
    # run's training and evaluation nested under the child.
    client = MlflowClient()
    experiment = client.get_experiment_by_name("socnav-wm").experiment_id
    runs = client.search_runs([experiment], max_results=500)
    parents = [r for r in runs if r.info.run_name == "sweep/tiny"]
    assert len(parents) == 1
    children = [r for r in runs if r.data.tags.get("mlflow.parentRunId") == parents[0].info.run_id]
    assert len(children) == 8
    child = next(
        r for r in children if r.info.run_name == "sweep-run/dueling-dqn/agent.gamma=0.9/seed-1"
    )
    assert child.data.tags["grid.agent.gamma"] == "0.9" and child.info.status == "FINISHED"
    assert "success" in child.data.metrics
    nested = [r for r in runs if r.data.tags.get("mlflow.parentRunId") == child.info.run_id]
    assert sorted(r.info.run_name for r in nested) == [
        "evaluate/dueling-dqn",
        "train-agent/dueling-dqn/seed-1",
    ]
    failed = next(r for r in children if r.info.run_name.endswith("gamma=0.99/seed-1")
                  and "2stepahead" in r.info.run_name)  # fmt: skip
    assert failed.info.status == "FAILED"

    # Started again: the finished runs are skipped, the failed one runs (and now succeeds).
    blocked.unlink()
    result = runner.invoke(app, [*args, "--no-tracking"])
    assert result.exit_code == 0, result.output
    assert "7 already finished, 1 to run" in result.output
    assert "8/8 runs done (7 skipped as finished, 0 failed)" in result.output
    # Started once more: nothing to run, and Ray is not even started.
    result = runner.invoke(app, [*args, "--no-tracking"])
    assert "8 already finished, 0 to run" in result.output

    # Another study holding two of these runs copies them instead of training them again.
    other = [
        "sweep", "--variants", "dueling-dqn", "--seeds", "0-1", "--grid", "agent.gamma=0.9",
        "--name", "other", "--cpus", "2", "--no-tracking",
    ]  # fmt: skip
    result = runner.invoke(app, other)
    assert result.exit_code == 0, result.output
    assert "2 already finished (2 copied from other studies), 0 to run" in result.output
    copied = Path("data/studies/other/dueling-dqn__agent.gamma=0.9__seed-1")
    recorded = json.loads((copied / "result.json").read_text())
    assert recorded["run"] == "dueling-dqn/agent.gamma=0.9/seed-1"
    assert recorded["copied_from"].endswith("tiny/dueling-dqn__agent.gamma=0.9__seed-1")
    ours = _weights(copied / "agents" / "dueling-dqn" / "seed-1.pt")
    serial = _weights(Path("serial") / "dueling-dqn" / "seed-1.pt")
    assert all(torch.equal(ours[key], serial[key]) for key in serial)
    rows = pq.read_table("reports/studies/other/results.parquet").to_pylist()
    assert [row["status"] for row in rows] == ["done", "done"]


def test_an_interrupted_sweep_resumes_from_its_checkpoints(sweepdir: Path) -> None:
    params = tiny_params()
    params["agent"].update(episodes=120, checkpoint_every=4)
    Path("params.yaml").write_text(yaml.safe_dump(params))
    command = [
        sys.executable, "-m", "socnav_wm.cli", "sweep", "--variants", "dueling-dqn",
        "--seeds", "0-1", "--name", "cut", "--cpus", "2", "--no-tracking",
    ]  # fmt: skip
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    sweep = subprocess.Popen(command, env=env, stderr=subprocess.PIPE, text=True)
    checkpoints = Path("data/studies/cut/checkpoints")
    deadline = time.monotonic() + 240
    while not list(checkpoints.rglob("*.ckpt")) and time.monotonic() < deadline:
        assert sweep.poll() is None, sweep.stderr.read() if sweep.stderr else ""
        time.sleep(0.2)
    assert list(checkpoints.rglob("*.ckpt")), "no checkpoint was written"
    sweep.send_signal(signal.SIGTERM)  # what Ctrl-C, kill or a scheduler does
    _, err = sweep.communicate(timeout=120)
    # One line and 143, not Ray's own handler's crash dump and exit status 1.
    assert sweep.returncode == 143, err
    assert err.strip().splitlines()[-1] == "error: terminated (SIGTERM); nothing was written"
    assert not list(Path("data/studies/cut").rglob("result.json"))  # nothing finished

    result = subprocess.run(command, env=env, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    results = [json.loads(p.read_text()) for p in Path("data/studies/cut").rglob("result.json")]
    assert len(results) == 2 and all(r["status"] == "done" for r in results)
    assert any(r["resumed"] for r in results)
    # Exact resume: the resumed run's weights are those of one uninterrupted training.
    resumed = next(r for r in results if r["resumed"])
    subprocess.run(
        [sys.executable, "-m", "socnav_wm.cli", "train-agent", "--variant", "dueling-dqn",
         "--seed", str(resumed["seed"]), "--out-dir", "serial", "--threads", "1",
         "--no-tracking", "--quiet"],
        env=env, check=True, capture_output=True,
    )  # fmt: skip
    slug = f"dueling-dqn__seed-{resumed['seed']}"
    ours = _weights(
        Path("data/studies/cut") / slug / "agents/dueling-dqn" / f"seed-{resumed['seed']}.pt"
    )
    serial = _weights(Path("serial/dueling-dqn") / f"seed-{resumed['seed']}.pt")
    for key in ours:
        assert torch.equal(ours[key], serial[key]), key
