"""The typer CLI: help, render and bench env, through typer's CliRunner (real code paths)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml
from PIL import Image
from typer.testing import CliRunner

from socnav_wm.cli import app

runner = CliRunner()


def test_help_lists_the_commands() -> None:
    result = runner.invoke(app, ["--help"])
    assert result.exit_code == 0
    for command in ("render", "bench"):
        assert command in result.output


def test_render_writes_an_animated_gif(tmp_path: Path) -> None:
    out = tmp_path / "episode.gif"
    result = runner.invoke(
        app, ["render", "--policy", "random", "--episodes", "2", "--out", str(out), "--size", "96"]
    )
    assert result.exit_code == 0, result.output
    with Image.open(out) as gif:
        assert gif.format == "GIF" and gif.size == (96, 96)
        assert gif.n_frames > 2
    assert "wrote" in result.output


def test_render_rejects_an_unknown_policy_in_one_line(tmp_path: Path) -> None:
    result = runner.invoke(app, ["render", "--policy", "genius", "--out", str(tmp_path / "x.gif")])
    assert result.exit_code == 2
    assert result.output.strip().startswith("error: --policy: unknown 'genius'")
    assert len(result.output.strip().splitlines()) == 1
    assert not (tmp_path / "x.gif").exists()


@pytest.mark.parametrize("policy", ["orca", "cv-mpc", "agent-file"])
def test_render_any_method_on_chosen_scenarios(tmp_path: Path, policy: str) -> None:
    """A baseline, a planner or a trained agent's file, on the scenarios asked for."""
    from socnav_wm.env import EnvParams
    from tests.evaluation.conftest import save_tiny_agent

    if policy == "agent-file":
        policy = str(save_tiny_agent(tmp_path / "a.pt", "dueling-dqn", EnvParams(), seed=0))
    out = tmp_path / "x.gif"
    result = runner.invoke(
        app,
        ["render", "--policy", policy, "--scenario", "4", "--scenario", "7", "--out", str(out),
         "--size", "64", "--params", str(tmp_path / "none.yaml")],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert out.is_file() and result.output.count(",") == 1  # two outcomes: two episodes


def test_bench_env_prints_a_table() -> None:
    result = runner.invoke(
        app, ["bench", "env", "--batch", "1", "--batch", "8", "--humans", "sfm", "--seconds", "0.1"]
    )
    assert result.exit_code == 0, result.output
    assert "steps_per_cpu_s" in result.output and "gym.make_vec" in result.output
    # The machine it ran on, as MLflow records it, under the table.
    machine = result.output.rstrip().splitlines()[-1]
    assert machine.startswith("machine: ") and machine.endswith(" cores")


def test_bench_env_gives_a_preset_per_policy_when_both_are_asked() -> None:
    args = ["bench", "env", "--batch", "4", "--seconds", "0.1",
            "--overlay", "configs/scenarios/crowdnav.yaml"]  # fmt: skip
    own = runner.invoke(app, args)
    assert own.exit_code == 0, own.output
    rows = [line for line in own.output.splitlines() if "crowdnav" in line]
    assert len(rows) == 1 and "orca" in rows[0]  # the preset's own humans
    both = runner.invoke(app, [*args, "--humans", "sfm", "--humans", "mixed"])
    assert both.exit_code == 0, both.output
    rows = [line for line in both.output.splitlines() if "crowdnav" in line]
    assert len(rows) == 2 and "sfm" in rows[0] and "mixed" in rows[1]


def test_bench_plan_of_a_preset_skips_the_models_of_another_in_one_line() -> None:
    result = runner.invoke(
        app,
        ["bench", "plan", "--overlay", "configs/scenarios/crowd.yaml", "--batch", "1",
         "--seconds", "0.1"],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    skipped = [line for line in result.output.splitlines() if line.startswith("skipped")]
    assert skipped == [
        "skipped wm-mpc: models/planning/seed-0.pt: trained with 3 humans in a 10.0 m room; "
        "the params have 10 humans in a 10.0 m room",
        "skipped vae-lstm-mpc: models/vae.pt: trained with 3 humans in a 10.0 m room; "
        "the params have 10 humans in a 10.0 m room",
        "skipped wm-mpc-q: models/planning/seed-0.pt: trained with 3 humans in a 10.0 m room; "
        "the params have 10 humans in a 10.0 m room",
    ]
    rows = [line for line in result.output.splitlines() if line.startswith("│")]
    assert [row.split("│")[1].strip() for row in rows] == ["cv-mpc", "oracle-mpc"]


def test_bench_env_rejects_an_unknown_human_policy() -> None:
    result = runner.invoke(app, ["bench", "env", "--humans", "robots"])
    assert result.exit_code == 2
    assert "--humans: must be one of sfm, orca, mixed" in result.output


def test_bench_collect_prints_a_table() -> None:
    result = runner.invoke(app, ["bench", "collect", "--episodes", "16", "--num-envs", "8"])
    assert result.exit_code == 0, result.output
    assert "steps_per_cpu_s" in result.output and "parquet_mb" in result.output


def test_bench_train_reads_the_params_file_and_overrides(tmp_path: Path) -> None:
    params = tmp_path / "params.yaml"
    params.write_text("agent:\n  num_envs: 4\n  batch_size: 8\n  decode_latents: true\n")
    result = runner.invoke(
        app,
        [
            "bench", "train", "--variant", "maspm", "--params", str(params),
            "--set", "agent.batch_size=16", "--seconds", "0.1", "--device", "cpu",
        ],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    title = " ".join(result.output.split())
    assert "decode_latents True" in title and "per CPU-second" in title
    assert "torch " in result.output.rstrip().splitlines()[-1]  # the machine line
    row = next(line for line in result.output.splitlines() if "maspm" in line)
    cells = [cell.strip() for cell in row.split("│")[1:-1]]
    # maspm with decoded latents: z and four predictions, 23 values each; 4 envs, batch 16.
    assert cells[:4] == ["maspm", "115", "4", "16"]


def test_bench_train_rejects_a_bad_override_in_one_line(tmp_path: Path) -> None:
    params = tmp_path / "params.yaml"
    params.write_text("")
    result = runner.invoke(
        app, ["bench", "train", "--params", str(params), "--set", "agent.batch_size=0"]
    )
    assert result.exit_code == 2
    assert result.output.strip() == (
        "error: --set agent.batch_size=0: agent.batch_size: must be > 0, got 0"
    )


def test_a_bad_setting_is_reported_before_torch_or_mlflow_is_imported(tmp_path: Path) -> None:
    """Fail fast: the params are validated before a stage's heavy imports (seconds each)."""
    import subprocess
    import sys

    code = (
        "import sys\n"
        "from socnav_wm.cli import app\n"
        "try:\n"
        "    app(['train-agent', '--variant', 'maspm', '--set', 'agent.gamma=2'])\n"
        "except SystemExit as exit:\n"
        "    print(exit.code, sorted(m for m in ('torch', 'mlflow') if m in sys.modules))\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], cwd=Path(__file__).resolve().parents[1],
        capture_output=True, text=True,
    )  # fmt: skip
    assert result.stdout.strip() == "2 []", result.stdout + result.stderr
    assert "agent.gamma" in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_the_cli_limits_openmp_spinning_unless_told_otherwise() -> None:
    import os
    import subprocess
    import sys

    show = (
        "import os, socnav_wm.cli; "
        "print(os.environ['OMP_WAIT_POLICY'], os.environ['GOMP_SPINCOUNT'])"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT")}
    out = subprocess.run([sys.executable, "-c", show], env=env, capture_output=True, text=True)
    assert out.stdout.split() == ["PASSIVE", "1000"]
    env["OMP_WAIT_POLICY"] = "ACTIVE"
    out = subprocess.run([sys.executable, "-c", show], env=env, capture_output=True, text=True)
    assert out.stdout.split()[0] == "ACTIVE"


def test_train_planning_model_trains_and_writes_its_outputs(tmp_path: Path) -> None:
    rollouts = tmp_path / "rollouts"
    collected = runner.invoke(
        app,
        ["collect", "--set", "collect.episodes=24", "--set", "collect.num_envs=24",
         "--out", str(rollouts), "--metrics", str(tmp_path / "c.json"), "--no-tracking",
         "--quiet"],
    )  # fmt: skip
    assert collected.exit_code == 0, collected.output
    result = runner.invoke(
        app,
        ["train-planning-model", "--rollouts", str(rollouts), "--seed", "1",
         "--out-dir", str(tmp_path / "models"), "--metrics-dir", str(tmp_path / "metrics"),
         "--set", "planning_model.max_epochs=1", "--set", "planning_model.horizon=4",
         "--set", "planning_model.hidden_dim=8", "--set", "planning_model.val_fraction=0.2",
         "--no-tracking", "--quiet"],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "constant velocity" in result.output and "wrote" in result.output
    from socnav_wm.worldmodel.planning_file import load_residual

    assert load_residual(tmp_path / "models" / "seed-1.pt").net[0].out_features == 8
    metrics = json.loads((tmp_path / "metrics" / "seed-1.json").read_text())
    assert metrics["seed"] == 1 and metrics["epochs"] == 1
    saved = yaml.safe_load((tmp_path / "models" / "seed-1.params.yaml").read_text())
    assert set(saved) == {"env", "planning_model"}
    # A seed outside planning_model.seeds is refused in one line.
    refused = runner.invoke(
        app, ["train-planning-model", "--rollouts", str(rollouts), "--seed", "7",
              "--out-dir", str(tmp_path / "models"), "--no-tracking"],
    )  # fmt: skip
    assert refused.exit_code != 0 and "planning_model.seeds" in refused.output


def test_train_planning_model_names_missing_rollouts(tmp_path: Path) -> None:
    result = runner.invoke(
        app, ["train-planning-model", "--rollouts", str(tmp_path / "none"), "--out-dir",
              str(tmp_path / "m"), "--no-tracking"],
    )  # fmt: skip
    assert result.exit_code != 0
    assert "none" in result.output and "Traceback" not in result.output


@pytest.mark.parametrize(
    ("missing", "argv"),
    [
        ("typer", ["--help"]),
        ("torch", ["bench", "train", "--variant", "maspm", "--seconds", "0.1"]),
    ],
)
def test_without_the_pipeline_extra_the_command_says_how_to_install_it(
    missing: str, argv: list[str]
) -> None:
    """A core install (no `pipeline` extra): one line on stderr naming the extra, exit status 2,
    whether typer itself is missing or a module a command imports."""
    import subprocess
    import sys

    code = (
        "import sys\n"
        f"sys.modules[{missing!r}] = None  # as if it were not installed\n"
        f"sys.argv = ['socnav-wm', *{argv!r}]\n"
        "from socnav_wm.cli import main\n"
        "main()\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], cwd=Path(__file__).resolve().parents[1],
        capture_output=True, text=True,
    )  # fmt: skip
    assert result.returncode == 2, result.stdout + result.stderr
    assert result.stderr == (
        "socnav-wm: the command line needs the pipeline extra: pip install 'socnav-wm[pipeline]'\n"
    )
    assert result.stdout == ""


def test_the_cli_package_imports_only_the_standard_library_before_typer() -> None:
    """`socnav_wm.cli` (the console script's module) runs without typer: only `main` needs it."""
    import subprocess
    import sys

    code = (
        "import sys; before = set(sys.modules)\n"
        "import socnav_wm.cli\n"
        "new = {m.partition('.')[0] for m in set(sys.modules) - before}\n"
        "print(sorted(new & {'typer', 'click', 'rich', 'yaml', 'torch'}))\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.stdout.strip() == "[]", result.stdout + result.stderr


def test_render_keeps_the_params_files_human_policy_unless_told(tmp_path: Path) -> None:
    """`--human-policy` overrides `env.human_policy` only when given."""
    from socnav_wm.env import render as drawing

    seen = []
    original = drawing.episode_frames

    def spy(episode, params, **kwargs):
        seen.append(params.human_policy)
        return original(episode, params, **kwargs)

    params = tmp_path / "params.yaml"
    params.write_text("env:\n  human_policy: sfm\n")
    common = ["render", "--episodes", "1", "--size", "64", "--params", str(params)]
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(drawing, "episode_frames", spy)
        kept = runner.invoke(app, [*common, "--out", str(tmp_path / "a.gif")])
        given = runner.invoke(
            app, [*common, "--out", str(tmp_path / "b.gif"), "--human-policy", "orca"]
        )
    assert kept.exit_code == 0 and given.exit_code == 0, kept.output + given.output
    assert seen == ["sfm", "orca"]
