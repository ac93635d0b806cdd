"""Bad input ends in one line naming the problem, exit status 2, and nothing written: damaged
model files, models and rollouts made for other scenarios than the params', broken rollouts,
and the commands that read metrics, reports, claims and pipeline files. Real files, made by the
commands themselves on the tiny settings."""

from __future__ import annotations

import ast
import json
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import torch
import yaml
from typer.testing import CliRunner

from socnav_wm.cli import app
from socnav_wm.env.params import EnvParams
from tests.conftest import ROOT, tiny_params

runner = CliRunner()
TWO_HUMANS = ("--set", "env.num_humans=2")
BIG_ROOM = ("--set", "env.room_size=12")
PARAMS_SIDE = "the params have 3 humans in a 10.0 m room"


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Rollouts, VAEs, an LSTM and planning models of the tiny settings: of the params' 3
    humans in a 10 m room, of 2 humans, and of a 12 m room."""
    root = tmp_path_factory.mktemp("made")
    params = root / "params.yaml"
    params.write_text(yaml.safe_dump(tiny_params()))

    def run(*args: str | Path) -> None:
        argv = [str(a) for a in args] + ["--params", str(params), "--no-tracking", "--quiet"]
        result = runner.invoke(app, argv)
        assert result.exit_code == 0, result.output

    def outputs(name: str) -> tuple[str | Path, ...]:
        files[name] = root / f"{name}.pt"
        metrics = ("--metrics", root / f"{name}.json", "--history", root / f"{name}-h.json")
        return ("--out", files[name], *metrics)

    files = {name: root / name for name in ("r3", "r2", "r12")}
    scenes = {"3": (), "2": TWO_HUMANS, "12": BIG_ROOM}
    for scene, extra in scenes.items():
        run("collect", "--out", files[f"r{scene}"], "--metrics", root / f"r{scene}.json", *extra)
    for scene in ("3", "2"):
        run("train-vae", "--rollouts", files[f"r{scene}"], *outputs(f"vae{scene}"), *scenes[scene])
    run("train-lstm", "--rollouts", files["r2"], "--vae", files["vae2"], *outputs("lstm2"),
        *TWO_HUMANS)  # fmt: skip
    for scene, extra in scenes.items():
        folder = root / f"p{scene}"
        run("train-planning-model", "--rollouts", files[f"r{scene}"], "--out-dir", folder,
            "--metrics-dir", root / f"p{scene}-metrics", *extra)  # fmt: skip
        files[f"p{scene}"] = folder / "seed-0.pt"
    return files


def _tree(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` and its content, but the advisory lock files that stay
    beside a stage's inputs and outputs (``.NAME.socnav-wm.lock``, empty or a pid)."""
    return {
        str(path.relative_to(folder)): path.read_bytes()
        for path in sorted(folder.rglob("*"))
        if path.is_file() and not path.name.endswith(".socnav-wm.lock")
    }


def refused(workdir: Path, *args: str | Path) -> str:
    """Run the command in ``workdir`` (without MLflow); it must exit with status 2, print one
    line ``error: …`` and write nothing. Returns the message after ``error: ``."""
    before = _tree(workdir)
    argv = [str(a) for a in args]
    if argv[0] not in ("check", "deps"):
        argv.append("--no-tracking")
    result = runner.invoke(app, argv)
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.output
    assert _tree(workdir) == before, "something was written"
    return lines[0].removeprefix("error: ")


# ------------------------------------------------------------------ 1: damaged model files


def _torch_callers(function: str) -> list[str]:
    """The package's files, one entry per call, that call ``torch.<function>`` directly."""
    callers = []
    for path in sorted((ROOT / "socnav_wm").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if (
                isinstance(node, ast.Call)
                and isinstance(node.func, ast.Attribute)
                and node.func.attr == function
                and isinstance(node.func.value, ast.Name)
                and node.func.value.id == "torch"
            ):
                callers.append(path.relative_to(ROOT).as_posix())
    return callers


def test_every_torch_load_of_the_package_is_the_safe_loader() -> None:
    assert _torch_callers("load") == ["socnav_wm/io.py"]  # load_torch_file, weights only


def test_every_torch_save_of_the_package_is_torch_bytes() -> None:
    """Saved in memory (io.torch_bytes), so the bytes do not depend on the temporary name."""
    assert _torch_callers("save") == ["socnav_wm/io.py"]


class Unsafe:
    """An object no socnav-wm file holds (the weights-only unpickler refuses it)."""


def test_damaged_planning_models_are_named_in_one_line(workdir: Path, made) -> None:
    garbage = workdir / "garbage.pt"
    garbage.write_bytes(np.random.default_rng(0).bytes(4096))
    truncated = workdir / "truncated.pt"
    content = made["p3"].read_bytes()
    truncated.write_bytes(content[: len(content) // 2])
    unsafe = workdir / "unsafe.pt"
    torch.save({"format": "socnav-wm residual-cv", "thing": Unsafe()}, unsafe)
    unreadable = "not a readable planning model (truncated, or not written by torch.save)"
    for path in (garbage, truncated):
        message = refused(workdir, "evaluate", "--method", "wm-mpc", "--planning-model", path)
        assert message == f"{path}: {unreadable}"
    message = refused(workdir, "predict", "--planning-model", truncated)
    assert message == f"{truncated}: {unreadable}"
    message = refused(workdir, "predict", "--planning-model", unsafe)
    assert message == (
        f"{unsafe}: not a readable planning model (it holds objects other than tensors and "
        "plain values, which socnav-wm never saves; not loaded)"
    )
    assert "weights_only" not in message


def test_a_critic_that_is_not_a_dueling_dqn_agent_is_one_line(workdir: Path, made) -> None:
    p3 = made["p3"]
    wm_mpc_q = ("evaluate", "--method", "wm-mpc-q", "--planning-model", p3, "--critic")
    assert refused(workdir, *wm_mpc_q, p3) == f"{p3}: not a socnav-wm agent file"
    missing = workdir / "nope.pt"
    assert refused(workdir, *wm_mpc_q, missing) == (
        f"{missing}: no such critic file (make it: socnav-wm train-agent --variant dueling-dqn "
        "--seed 0)"
    )
    message = refused(workdir, "evaluate", "--method", "cv-mpc", "--critic", p3)
    assert message == "planner 'cv-mpc' reads no critic file (it reads: none)"


# ------------------------------------------------------------------ 2: other scenarios


def test_models_of_other_scenarios_are_refused_by_every_stage(workdir: Path, made) -> None:
    p2, p12 = made["p2"], made["p12"]
    vae2, vae3, lstm2 = made["vae2"], made["vae3"], made["lstm2"]
    two = f"trained with 2 humans in a 10.0 m room; {PARAMS_SIDE}"
    wm_mpc = ("evaluate", "--method", "wm-mpc", "--planning-model")
    vae_lstm_mpc = ("evaluate", "--method", "vae-lstm-mpc", "--vae")
    cases = [
        ((*wm_mpc, p2), f"{p2}: {two}"),
        ((*wm_mpc, p12), f"{p12}: trained with 3 humans in a 12.0 m room; {PARAMS_SIDE}"),
        ((*vae_lstm_mpc, vae2, "--lstm", lstm2), f"{vae2}: {two}"),
        ((*vae_lstm_mpc, vae3, "--lstm", lstm2), f"{lstm2}: {two}"),
        (("predict", "--planning-model", p2), f"{p2}: {two}"),
        (
            ("predict", "--planning-model", made["p3"], "--vae", vae2, "--lstm", lstm2),
            f"{vae2}: {two}",
        ),
        (
            ("train-lstm", "--rollouts", made["r3"], "--vae", vae2, "--out", "l.pt"),
            f"{vae2}: {two}",
        ),
        (("train-agent", "--variant", "maspm", "--vae", vae2, "--lstm", lstm2), f"{vae2}: {two}"),
    ]
    for args, expected in cases:
        assert refused(workdir, *args) == expected, args


def test_rollouts_of_other_scenarios_are_refused_by_every_training(workdir: Path, made) -> None:
    r2 = made["r2"] / "shard-00000.parquet"
    r12 = made["r12"] / "shard-00000.parquet"
    two = f"{r2}: collected with 2 humans in a 10.0 m room; {PARAMS_SIDE}"
    cases = [
        (("train-vae", "--rollouts", made["r2"], "--out", "v.pt"), two),
        (("train-lstm", "--rollouts", made["r2"], "--vae", made["vae3"], "--out", "l.pt"), two),
        (("train-planning-model", "--rollouts", made["r2"], "--out-dir", "p"), two),
        (
            ("train-planning-model", "--rollouts", made["r12"], "--out-dir", "p"),
            f"{r12}: collected with 3 humans in a 12.0 m room; {PARAMS_SIDE}",
        ),
    ]
    for args, expected in cases:
        assert refused(workdir, *args) == expected, args


def test_an_agent_of_another_room_is_refused(workdir: Path) -> None:
    from tests.evaluation.conftest import save_tiny_agent

    for seed in (0, 1):  # experiment.seeds of the tiny settings
        path = workdir / "agents" / "dueling-dqn" / f"seed-{seed}.pt"
        path.parent.mkdir(parents=True, exist_ok=True)
        save_tiny_agent(path, "dueling-dqn", EnvParams(room_size=12), seed=seed)
    message = refused(workdir, "evaluate", "--method", "dueling-dqn", "--agents-dir", "agents")
    assert message == (
        f"agents/dueling-dqn/seed-0.pt: trained with 3 humans in a 12.0 m room; {PARAMS_SIDE}"
    )


def test_a_model_of_another_world_is_used_only_in_a_transfer_evaluation(workdir: Path) -> None:
    """Same observation, other behaviour (here: humans who see the robot): refused in one line
    naming the field and both values, used with --transfer (and the evaluation says so)."""
    from socnav_wm.evaluation.records import evaluation_metadata
    from tests.evaluation.conftest import save_tiny_agent

    seeing = EnvParams(humans_see_robot=True)
    for seed in (0, 1):
        path = workdir / "agents" / "dueling-dqn" / f"seed-{seed}.pt"
        path.parent.mkdir(parents=True, exist_ok=True)
        save_tiny_agent(path, "dueling-dqn", seeing, seed=seed)
    args = ("evaluate", "--method", "dueling-dqn", "--agents-dir", "agents", "--set",
            "eval.episodes=2", "--out-dir", "transfer", "--metrics-dir", "transfer")  # fmt: skip
    assert refused(workdir, *args) == (
        "agents/dueling-dqn/seed-0.pt: trained with env.humans_see_robot true; the params have "
        "paper (another scenario: use it here only as a transfer, --transfer)"
    )
    result = runner.invoke(app, [*args, "--transfer", "--no-tracking"])
    assert result.exit_code == 0, result.output
    metadata = evaluation_metadata(workdir / "transfer" / "dueling-dqn.parquet")
    assert metadata["settings"]["transfer"] is True
    message = refused(workdir, "evaluate", "--method", "orca", "--transfer")
    assert message == "robot 'orca' reads no model files: nothing to transfer"


def test_predict_measures_a_preset_without_its_own_world_model_or_agent(
    workdir: Path, made
) -> None:
    """--no-world-model --no-agent-policy: the planning model and the baselines under the
    random policy only (where no VAE, LSTM or agent of the preset exists)."""
    out = workdir / "p" / "prediction.json"
    result = runner.invoke(
        app,
        ["predict", "--planning-model", str(made["p3"]), "--no-world-model",
         "--no-agent-policy", "--set", "prediction.episodes=4", "--out", str(out),
         "--figure", str(workdir / "p" / "prediction.png"), "--no-tracking"],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    errors = json.loads(out.read_text())["policies"]
    assert list(errors) == ["random"]
    assert "planning-model" in errors["random"]["predictors"]
    assert sorted(errors["random"]["predictors"]) == [
        "constant-velocity",
        "copy-last",
        "planning-model",
        "static",  # no "vae-lstm"
    ]


def test_predict_under_a_planner_measures_its_policy_too_and_refuses_a_learned_one(
    workdir: Path, made
) -> None:
    out = workdir / "pp" / "prediction.json"
    figure = str(workdir / "pp" / "prediction.png")
    common = ["--planning-model", str(made["p3"]), "--no-world-model", "--no-agent-policy",
              "--set", "prediction.episodes=3", "--set", "prediction.starts=2", "--out",
              str(out), "--figure", figure, "--no-tracking"]  # fmt: skip
    result = runner.invoke(app, ["predict", "--planner-policy", "cv-mpc", *common])
    assert result.exit_code == 0, result.output
    written = json.loads(out.read_text())
    assert sorted(written["policies"]) == ["cv-mpc", "random"]
    assert written["settings"]["starts"] == 2
    assert "by what they met" in result.output
    message = refused(workdir, "predict", "--planner-policy", "wm-mpc", *common)
    assert message == "--planner-policy: expected one of cv-mpc, oracle-mpc, got 'wm-mpc'"


def test_collect_under_a_planner_is_refused_for_a_learned_one_or_a_lone_epsilon(
    workdir: Path,
) -> None:
    message = refused(workdir, "collect", "--policy", "wm-mpc", "--out", "r", "--metrics", "r.json")
    assert message == "--policy: expected random or one of cv-mpc, oracle-mpc, got 'wm-mpc'"
    message = refused(workdir, "collect", "--epsilon", "0.3", "--out", "r", "--metrics", "r.json")
    assert message == "--epsilon: only under a planner (--policy)"
    lattice = ("--set", "planning.actions=lattice", "--set", "planning.prefix_length=1")
    message = refused(
        workdir, "collect", "--policy", "cv-mpc", *lattice, "--out", "r", "--metrics", "r.json"
    )
    assert message == (
        "--policy: the rollouts and the models hold the paper's four actions; planning.actions "
        "must be paper, not a lattice"
    )


def _without_env(source: Path, target: Path) -> Path:
    """``source`` as a file written before the scenarios (and a format version) were saved."""
    payload = torch.load(source, weights_only=True)
    payload.pop("env")
    if payload["format"] == "socnav-wm residual-cv":
        payload.pop("format_version")
    torch.save(payload, target)
    return target


def test_files_written_before_the_scenarios_were_recorded_are_checked_on_what_they_hold(
    tmp_path: Path, made
) -> None:
    from socnav_wm.data.shards import RolloutError, read_rollouts
    from socnav_wm.io import ModelFileError
    from socnav_wm.worldmodel.files import load_lstm, load_vae
    from socnav_wm.worldmodel.planning_file import load_residual

    ours, two = EnvParams(), EnvParams(num_humans=2)
    old = _without_env(made["p2"], tmp_path / "p2.pt")
    assert load_residual(old, two).num_humans == 2
    with pytest.raises(ModelFileError) as error:
        load_residual(old, ours)
    assert str(error.value) == f"{old}: trained with 2 humans; {PARAMS_SIDE}"
    old = _without_env(made["p12"], tmp_path / "p12.pt")  # knows the room: goals within ±5.5 m
    assert load_residual(old, EnvParams(room_size=12)).room_half == 5.5
    with pytest.raises(ModelFileError) as error:
        load_residual(old, ours)
    assert str(error.value) == (
        f"{old}: trained with 3 humans, goals drawn within ±5.5 m; {PARAMS_SIDE} "
        "(goals drawn within ±4.5 m)"
    )
    old = _without_env(made["vae2"], tmp_path / "vae2.pt")  # by the size of its observations
    assert load_vae(old, env_params=two).input_dim == 16
    with pytest.raises(ModelFileError) as error:
        load_vae(old, env_params=ours)
    assert str(error.value) == f"{old}: trained with 2 humans; {PARAMS_SIDE}"
    old = _without_env(made["lstm2"], tmp_path / "lstm2.pt")  # an LSTM tells nothing
    assert load_lstm(old, env_params=ours).latent_dim > 0
    # A shard without the scenarios in its metadata: its number of humans.
    shard = made["r2"] / "shard-00000.parquet"
    table = pq.read_table(shard)
    metadata = {k: v for k, v in table.schema.metadata.items() if k != b"socnav_wm.env"}
    pq.write_table(table.replace_schema_metadata(metadata), tmp_path / "shard-00000.parquet")
    assert read_rollouts(tmp_path, env_params=two).num_rows == table.num_rows
    with pytest.raises(RolloutError) as error:
        read_rollouts(tmp_path, env_params=ours)
    assert str(error.value) == (
        f"{tmp_path / 'shard-00000.parquet'}: collected with 2 humans; {PARAMS_SIDE}"
    )


# ------------------------------------------------------------------ 3: broken rollouts


def _broken_copy(source: Path, target: Path, column: str, row: int, value: int) -> Path:
    shutil.copytree(source, target)
    shard = target / "shard-00000.parquet"
    table = pq.read_table(shard)
    values = table.column(column).to_numpy().copy()
    values[row] = value
    index = table.schema.get_field_index(column)
    table = table.set_column(index, table.schema.field(index), pa.array(values, pa.int8()))
    pq.write_table(table, shard)
    return shard


def test_actions_out_of_range_are_named_with_their_file_and_value(workdir: Path, made) -> None:
    seven = _broken_copy(made["r3"], workdir / "seven", "action", 5, 7)
    message = refused(workdir, "train-planning-model", "--rollouts", "seven", "--out-dir", "p")
    assert message == f"{seven.relative_to(workdir)}: row 5, column action: 7, not one of 0..3"
    minus = _broken_copy(made["r3"], workdir / "minus", "action", 9, -3)
    message = refused(
        workdir, "train-lstm", "--rollouts", "minus", "--vae", made["vae3"], "--out", "l.pt"
    )
    assert message == f"{minus.relative_to(workdir)}: row 9, column action: -3, not one of 0..3"


def test_broken_episodes_are_named_with_their_file(workdir: Path, made) -> None:
    # The first shard again as a third: its episodes are in two shards.
    shutil.copytree(made["r3"], workdir / "twice")
    first = workdir / "twice" / "shard-00000.parquet"
    shutil.copy(first, workdir / "twice" / "shard-00002.parquet")
    episode = int(pq.read_table(first, columns=["episode_id"])["episode_id"].to_numpy().min())
    message = refused(workdir, "train-vae", "--rollouts", "twice", "--out", "v.pt")
    assert message == (
        f"twice/shard-00002.parquet: episode {episode} is also in twice/shard-00000.parquet "
        "(an episode's rows must be contiguous, in one shard)"
    )
    # The first row of a shard moved to its end: that episode's rows are not contiguous.
    shutil.copytree(made["r3"], workdir / "moved")
    shard = workdir / "moved" / "shard-00000.parquet"
    table = pq.read_table(shard)
    order = np.append(np.arange(1, table.num_rows), 0)
    pq.write_table(table.take(pa.array(order)), shard)
    episode = table["episode_id"][0].as_py()
    message = refused(workdir, "train-vae", "--rollouts", "moved", "--out", "v.pt")
    assert message == (
        f"moved/shard-00000.parquet: episode {episode}: rows are not contiguous "
        "(the id appears twice)"
    )


# ------------------------------------------------------------------ 4: socnav-wm check


def _metrics(folder: Path, method: str, drop: str | None = None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    entry = {"mean": 0.9, "low": 0.85, "high": 0.95, "n": 500}
    metrics = {m: entry for m in ("success", "human_collision", "discomfort", "simulation_time")}
    metrics.pop(drop, None)
    content = {"method": method, "scenario_seed": 5, "episodes": 500, "metrics": metrics}
    path = folder / f"{method}.json"
    path.write_text(json.dumps(content))
    return path


def test_check_refuses_a_missing_metric_a_corrupt_file_or_a_missing_method(workdir: Path) -> None:
    for method in ("dueling-dqn", "orca", "wm-mpc"):
        _metrics(workdir / "committed", method)
    _metrics(workdir / "rerun", "dueling-dqn")
    _metrics(workdir / "rerun", "wm-mpc")
    lacking = _metrics(workdir / "rerun", "orca", drop="discomfort")
    message = refused(workdir, "check", "rerun", "--committed", "committed")
    assert message == f"{lacking.relative_to(workdir)}: no 'discomfort' metric"
    lacking.write_text('{"method": "orca", "metrics": {')
    message = refused(workdir, "check", "rerun", "--committed", "committed")
    assert message.startswith("rerun/orca.json: not valid JSON (Expecting")
    lacking.unlink()
    (workdir / "rerun" / "wm-mpc.json").unlink()
    message = refused(workdir, "check", "rerun", "--committed", "committed")
    assert message == (
        "rerun: no evaluation metrics of orca, wm-mpc (evaluated in committed); a rerun must "
        "evaluate every committed method"
    )


def test_check_says_which_differing_planner_rests_on_one_model_training(workdir: Path) -> None:
    for method in ("dueling-dqn", "vae-lstm-mpc", "cv-mpc"):
        _metrics(workdir / "committed", method)
        _metrics(workdir / "rerun", method)
    for method in ("dueling-dqn", "vae-lstm-mpc", "cv-mpc"):  # every rerun differs
        content = json.loads((workdir / "rerun" / f"{method}.json").read_text())
        content["metrics"]["success"] = {"mean": 0.5, "low": 0.45, "high": 0.55, "n": 500}
        (workdir / "rerun" / f"{method}.json").write_text(json.dumps(content))
    result = runner.invoke(app, ["check", "rerun", "--committed", "committed"])
    assert result.exit_code == 1, result.output
    notes = [line for line in result.output.splitlines() if "one training" in line]
    assert notes == [
        "vae-lstm-mpc: plans with one training of its model files; its interval counts the "
        "test scenarios only, not that training's chance (docs/reproducibility.md)"
    ]


# ------------------------------------------------------------------ 5-7: report, deps, claims


def test_a_report_of_no_evaluation_is_refused(workdir: Path) -> None:
    (workdir / "empty").mkdir()
    message = refused(
        workdir, "report", "--eval-dir", "empty", "--out-dir", "r", "--metrics", "r.json"
    )
    assert message == (
        "no evaluation found in empty (no {method}.parquet; run `socnav-wm evaluate --method …` "
        "first)"
    )


def test_deps_names_a_broken_pipeline_file(workdir: Path) -> None:
    (workdir / "dvc.yaml").write_text("stages:\n  collect:\n    cmd: [socnav-wm collect\n")
    message = refused(workdir, "deps", "--check", "dvc.yaml")
    assert message.startswith("dvc.yaml: not valid YAML (line ")
    assert refused(workdir, "deps", "--write", "dvc.yaml") == message


def test_study_claims_names_a_corrupt_claims_file(workdir: Path) -> None:
    claims = workdir / "claims.json"
    claims.write_text('{"best-success": ')
    message = refused(workdir, "study-claims", "--report-claims", "claims.json")
    assert message.startswith("claims.json: not valid JSON (Expecting value: line 1")
    claims.write_text("{}")
    seeds = workdir / "reports" / "studies" / "seeds"
    seeds.mkdir(parents=True)
    (seeds / "claims.json").write_text("[{")
    (seeds / "results.parquet").write_bytes(b"")
    studies = ("--studies-dir", "reports/studies")
    message = refused(workdir, "study-claims", "--report-claims", "claims.json", *studies)
    assert message.startswith("reports/studies/seeds/claims.json: not valid JSON (")
