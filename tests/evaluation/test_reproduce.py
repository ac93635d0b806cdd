"""socnav-wm check: a rerun's test metrics against the committed ones."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from socnav_wm.evaluation.reproduce import compare_runs


def _write(folder: Path, method: str, success: tuple[float, float, float], seed: int = 5) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    entry = {"mean": success[0], "low": success[1], "high": success[2], "n": 500}
    metrics = {m: entry for m in ("success", "human_collision", "discomfort", "simulation_time")}
    content = {"method": method, "scenario_seed": seed, "episodes": 500, "metrics": metrics}
    (folder / f"{method}.json").write_text(json.dumps(content))


def test_means_inside_each_others_intervals_agree(tmp_path: Path) -> None:
    _write(tmp_path / "a", "orca", (0.96, 0.94, 0.98))
    _write(tmp_path / "b", "orca", (0.95, 0.93, 0.97))
    _write(tmp_path / "a", "sfm", (0.97, 0.95, 0.99))
    _write(tmp_path / "b", "sfm", (0.80, 0.75, 0.85))
    checks = {c.method: c for c in compare_runs(tmp_path / "a", tmp_path / "b")}
    assert checks["orca"].agrees and not checks["orca"].identical
    assert not checks["sfm"].agrees
    same = compare_runs(tmp_path / "a", tmp_path / "a")
    assert all(c.identical and c.agrees for c in same)


def test_other_scenarios_or_no_common_method_is_an_error(tmp_path: Path) -> None:
    _write(tmp_path / "a", "orca", (0.96, 0.94, 0.98))
    _write(tmp_path / "b", "orca", (0.96, 0.94, 0.98), seed=6)
    with pytest.raises(ValueError, match="scenario_seed 6, the committed run has 5"):
        compare_runs(tmp_path / "a", tmp_path / "b")
    _write(tmp_path / "c", "sfm", (0.96, 0.94, 0.98))
    with pytest.raises(ValueError, match="no evaluation metrics"):
        compare_runs(tmp_path / "a", tmp_path / "c")
