"""Helpers shared by the stage, CLI and DVC tests: the tiny configuration and a working
directory with its own params file and MLflow store."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
TINY_OVERLAY = ROOT / "tests" / "tiny.yaml"
"""The tests' tiny configuration, an overlay of params.yaml: every stage runs in seconds."""


def tiny_params() -> dict:
    """The tiny configuration as a params mapping (a fresh copy each call)."""
    return yaml.safe_load(TINY_OVERLAY.read_text())


@pytest.fixture
def workdir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An empty working directory with the tiny params.yaml and a SQLite MLflow store."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MLFLOW_TRACKING_URI", f"sqlite:///{tmp_path / 'mlflow.db'}")
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(tiny_params()))
    return tmp_path
