"""The options the README promises: every command that reads parameters takes `--params`,
`--set` and `--overlay`; every torch stage `--threads`, and `--device` but the CPU-only ones;
help texts show the real defaults."""

from __future__ import annotations

from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

from socnav_wm.cli import app

runner = CliRunner()

CPU_ONLY = {"train-planning-model", "predict"}
"""Torch stages that run on the CPU (README: `--device` but for these)."""


def _commands() -> dict[str, set[str]]:
    """Every command (``bench`` ones as ``bench NAME``) → its option names."""
    root = typer.main.get_command(app)
    found = {}
    for name, command in root.commands.items():
        subcommands = getattr(command, "commands", None)
        for sub_name, sub in (subcommands or {name: command}).items():
            label = name if subcommands is None else f"{name} {sub_name}"
            found[label] = {opt for param in sub.params for opt in param.opts}
    return found


def test_parameter_options_come_together_and_devices_where_the_readme_says() -> None:
    commands = {k: v for k, v in _commands().items() if not k.startswith("bench ")}
    reading = {name for name, options in commands.items() if "--params" in options}
    assert {"render", "sweep", "collect", "evaluate", "train-agent", "report"} <= reading
    for name in reading:
        assert {"--set", "--overlay"} <= commands[name], name
    assert "--params" not in commands["study-claims"]  # it reads no parameters
    stages = {name for name, options in commands.items() if "--threads" in options}
    assert stages >= CPU_ONLY
    for name in stages:
        assert ("--device" in commands[name]) == (name not in CPU_ONLY), name


def test_evaluate_help_shows_the_model_files_it_reads_by_default() -> None:
    shown = runner.invoke(app, ["evaluate", "--help"], env={"COLUMNS": "200"}).output
    for path in ("models/planning/seed-0.pt", "models/vae.pt", "models/lstm.pt"):
        assert f"[default: {path}]" in shown, path


def test_render_takes_set_and_overlay(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from socnav_wm.env import render as drawing

    seen = []
    original = drawing.episode_frames

    def spy(episode, params, **kwargs):
        seen.append((params.human_policy, params.num_humans))
        return original(episode, params, **kwargs)

    monkeypatch.setattr(drawing, "episode_frames", spy)
    overlay = tmp_path / "two.yaml"
    overlay.write_text("env:\n  num_humans: 2\n")
    common = ["render", "--episodes", "1", "--size", "64", "--params", "none.yaml"]
    result = runner.invoke(
        app,
        [*common, "--set", "env.human_policy=orca", "--overlay", str(overlay),
         "--out", str(tmp_path / "a.gif")],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert seen == [("orca", 2)]
