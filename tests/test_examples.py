"""The examples run as shipped (tiny budgets)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def load(name: str):
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_sb3_dqn_trains_and_tests_on_the_registered_env(capsys) -> None:
    rates = load("sb3_dqn").main(["--timesteps", "300", "--test-episodes", "3"])
    assert set(rates) == {"success", "human_collision", "wall_collision", "timeout"}
    assert sum(rates.values()) == pytest.approx(1.0)
    assert "on 3 test scenarios" in capsys.readouterr().out
