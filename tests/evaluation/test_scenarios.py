"""The per-preset table of the scenarios pipeline, on small synthetic evaluation files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from socnav_wm.config import Params
from socnav_wm.evaluation.scenarios import GAP_POINTS, SCENARIO_METHODS, TABLE_METRICS
from socnav_wm.stages import scenarios_report

METRICS = [name for name, _ in TABLE_METRICS]


def _summary(mean: float) -> dict[str, float]:
    return {"mean": mean, "low": max(0.0, mean - 0.05), "high": min(1.0, mean + 0.05), "n": 200}


def _write(root: Path, preset: str, method: str, success: np.ndarray) -> None:
    metrics = {name: _summary(0.0) for name in METRICS}
    metrics["success"] = _summary(float(success.mean()))
    metrics["time_to_reach_goal"] = {"mean": 10.5, "low": 10.0, "high": 11.0, "n": 100}
    folder = root / "metrics" / preset
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{method}.json").write_text(json.dumps({"method": method, "metrics": metrics}))
    episodes = root / "data" / preset
    episodes.mkdir(parents=True, exist_ok=True)
    n = len(success)
    table = pa.table(
        {
            "method": [method] * n,
            "training_seed": np.full(n, -1, dtype=np.int64),
            "scenario_id": np.arange(n, dtype=np.int64),
            "success": success.astype(np.float64),
        }
    )
    pq.write_table(table, episodes / f"{method}.parquet")


def _run(root: Path, presets: tuple[str, ...], document: Path) -> str:
    configs = root / "configs"
    configs.mkdir(exist_ok=True)
    for preset in presets:
        (configs / f"{preset}.yaml").write_text("env: {}\n")
    return scenarios_report.run(
        Params(),
        presets_dir=configs,
        metrics_dir=root / "metrics",
        episodes_dir=root / "data",
        out=root / "scenarios.md",
        summary=root / "summary.json",
        documents=(document,),
        tracking=False,
    )


def test_the_table_pairs_the_planners_and_names_the_presets_with_room(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    physics = (rng.random(200) < 0.8).astype(float)
    better = physics.copy()
    better[np.flatnonzero(physics == 0)[:30]] = 1.0  # the oracle saves 30 of cv-mpc's failures
    for method in SCENARIO_METHODS:
        _write(tmp_path, "dense", method, better if method == "oracle-mpc" else physics)
        _write(tmp_path, "easy", method, physics)
    document = tmp_path / "doc.md"
    document.write_text(
        "intro\n<!-- socnav-wm:scenarios -->\nPLACEHOLDER\n<!-- /socnav-wm:scenarios -->\n"
    )
    line = _run(tmp_path, ("dense", "easy", "absent"), document)
    assert "≥ 3 points in dense;" in line and "missing: absent/orca" in line
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["gaps"]["dense"]["difference"] == pytest.approx(15.0)
    assert summary["gaps"]["dense"]["room"] and not summary["gaps"]["easy"]["room"]
    assert summary["gaps"]["dense"]["difference"] >= GAP_POINTS
    text = document.read_text()
    assert "PLACEHOLDER" not in text and "| `dense` | `oracle-mpc` | 87.5 [82.5, 92.5]" in text
    assert (tmp_path / "scenarios.md").read_text().count("| `easy` |") == len(SCENARIO_METHODS) + 1


def test_no_evaluation_and_a_broken_file_are_refused_in_one_line(tmp_path: Path) -> None:
    document = tmp_path / "doc.md"
    document.write_text("<!-- socnav-wm:scenarios -->\n<!-- /socnav-wm:scenarios -->\n")
    with pytest.raises(ValueError, match="no scenario evaluation found"):
        _run(tmp_path, ("dense",), document)
    (tmp_path / "metrics" / "dense").mkdir(parents=True)
    (tmp_path / "metrics" / "dense" / "orca.json").write_text(json.dumps({"method": "orca"}))
    with pytest.raises(ValueError, match="orca.json: not an evaluation's metrics file"):
        _run(tmp_path, ("dense",), document)
    assert not (tmp_path / "summary.json").exists()


def test_planners_without_their_episodes_are_refused_rather_than_their_gap_dropped(
    tmp_path: Path,
) -> None:
    """A fresh clone has the metrics (git) but not the episodes (DVC's cache): the table would
    lose the preset's paired gap without a word."""
    success = np.ones(50)
    for method in SCENARIO_METHODS:
        _write(tmp_path, "dense", method, success)
    (tmp_path / "data" / "dense" / "cv-mpc.parquet").unlink()
    document = tmp_path / "doc.md"
    document.write_text("<!-- socnav-wm:scenarios -->\n<!-- /socnav-wm:scenarios -->\n")
    with pytest.raises(ValueError) as error:
        _run(tmp_path, ("dense",), document)
    assert str(error.value) == (
        f"{tmp_path / 'data' / 'dense' / 'cv-mpc.parquet'}: no such episodes file, and the paired "
        "oracle-mpc − cv-mpc gap of dense needs it (dvc repro scenarios/dvc.yaml)"
    )
    assert not (tmp_path / "summary.json").exists()


def test_a_learned_planner_is_compared_with_physics_and_the_oracle_where_it_was_trained(
    tmp_path: Path,
) -> None:
    rng = np.random.default_rng(1)
    physics = (rng.random(200) < 0.8).astype(float)
    oracle = np.ones(200)
    learned = physics.copy()
    learned[np.flatnonzero(physics == 0)[:20]] = 1.0  # saves 20 of cv-mpc's failures
    for method in SCENARIO_METHODS:
        success = oracle if method == "oracle-mpc" else physics
        _write(tmp_path, "dense", method, success)
        _write(tmp_path, "easy", method, success)
    _write(tmp_path, "dense", "wm-mpc", learned)  # trained in dense only
    document = tmp_path / "doc.md"
    document.write_text("<!-- socnav-wm:scenarios -->\n<!-- /socnav-wm:scenarios -->\n")
    line = _run(tmp_path, ("dense", "easy"), document)
    assert "missing" not in line  # no wm-mpc in easy is not a gap in the table
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert list(summary["learned"]) == ["dense"]
    versus = summary["learned"]["dense"]["wm-mpc"]
    assert versus["versus_physics"]["difference"] == pytest.approx(10.0)
    assert versus["versus_oracle"]["difference"] == pytest.approx(100 * (learned.mean() - 1))
    assert "| `dense` | `wm-mpc` | +10.0 [" in document.read_text()


def test_the_planning_models_errors_split_by_interaction_join_the_table(tmp_path: Path) -> None:
    import torch

    from socnav_wm.env.params import EnvParams
    from socnav_wm.methods import method
    from socnav_wm.planning.params import PlanningParams
    from socnav_wm.worldmodel.params import PredictionParams
    from socnav_wm.worldmodel.prediction import evaluate_prediction
    from socnav_wm.worldmodel.residual import ResidualDynamics

    for name in SCENARIO_METHODS:
        _write(tmp_path, "dense", name, np.ones(20))
    env = EnvParams(num_humans=4, humans_see_robot=True)
    torch.manual_seed(0)
    model = ResidualDynamics(env.num_humans, 8, env.dt, None)
    torch.nn.init.normal_(model.net[-1].weight, std=0.5)  # not constant velocity
    planner = ("cv-mpc", method("cv-mpc").configured(env, {"planning": PlanningParams()}))
    settings = PredictionParams(episodes=6, scenario_seed=3, warmup=2, horizon=16)
    result = evaluate_prediction(
        env, settings, world_model=None, agent=None, planner=planner, planning_models=[model]
    )
    path = tmp_path / "metrics" / "dense" / "prediction.json"
    path.write_text(json.dumps(result))
    document = tmp_path / "doc.md"
    document.write_text("<!-- socnav-wm:scenarios -->\n<!-- /socnav-wm:scenarios -->\n")
    _run(tmp_path, ("dense",), document)
    split = json.loads((tmp_path / "summary.json").read_text())["split"]["dense"]
    assert split["policy"] == "cv-mpc" and split["k"] == [1, 4, 16]
    errors = result["policies"]["cv-mpc"]["interactions"]
    humans = split["interactions"]["humans"]
    assert humans["difference"][-1] == errors["planning_model"]["humans"]["difference"][-1]
    assert "| `dense` | `cv-mpc` | humans within 1.5 m |" in document.read_text()
    assert "| `dense` | `cv-mpc` | goal change |" in document.read_text()  # not a distance
    # A part without rollouts at k = 1 (NaN, written as null) shows a dash.
    versus = result["policies"]["cv-mpc"]["interactions"]["planning_model"]
    versus["humans"]["difference"][0] = None
    versus["humans"]["difference_ci"][0] = [None, None]
    path.write_text(json.dumps(result))
    _run(tmp_path, ("dense",), document)
    row = next(r for r in document.read_text().splitlines() if "humans within" in r)
    assert row.split(" | ")[5] == "–"
    # Without a planning model there is nothing to split: refused in one line.
    del result["policies"]["cv-mpc"]["interactions"]["planning_model"]
    path.write_text(json.dumps(result))
    with pytest.raises(ValueError, match="prediction.json: not a prediction with a planning"):
        _run(tmp_path, ("dense",), document)


def test_the_blind_oracle_is_paired_with_physics_and_the_oracle_where_it_ran(
    tmp_path: Path,
) -> None:
    physics = np.r_[np.zeros(20), np.ones(80)]
    oracle = np.ones(100)
    blind = np.r_[np.zeros(5), np.ones(95)]  # knows all but the reaction: 15 of 20 saved
    for method in SCENARIO_METHODS:
        _write(tmp_path, "dense", method, oracle if method == "oracle-mpc" else physics)
    for folder in ("metrics", "data"):
        (tmp_path / folder / "dense" / "blind").mkdir(parents=True)
    _write(tmp_path, "dense", "blind/oracle-mpc", blind)
    document = tmp_path / "doc.md"
    document.write_text("<!-- socnav-wm:scenarios -->\n<!-- /socnav-wm:scenarios -->\n")
    _run(tmp_path, ("dense",), document)
    versus = json.loads((tmp_path / "summary.json").read_text())["learned"]["dense"]
    assert versus["oracle-mpc (blind)"]["versus_physics"]["difference"] == pytest.approx(15.0)
    assert versus["oracle-mpc (blind)"]["versus_oracle"]["difference"] == pytest.approx(-5.0)
    assert "| `dense` | `oracle-mpc (blind)` | 95.0 [" in document.read_text()


def test_the_critic_on_constant_velocity_is_the_control_of_the_learned_model(
    tmp_path: Path,
) -> None:
    physics = np.r_[np.zeros(20), np.ones(80)]
    critic_only = np.r_[np.zeros(12), np.ones(88)]  # the critic saves 8 of the 20
    learned = np.r_[np.zeros(4), np.ones(96)]  # the model 8 more
    for method in SCENARIO_METHODS:
        _write(tmp_path, "dense", method, np.ones(100) if method == "oracle-mpc" else physics)
    _write(tmp_path, "dense", "wm-mpc-q", learned)
    document = tmp_path / "doc.md"
    document.write_text("<!-- socnav-wm:scenarios -->\n<!-- /socnav-wm:scenarios -->\n")
    _run(tmp_path, ("dense",), document)
    assert json.loads((tmp_path / "summary.json").read_text())["model_gain"] == {}
    assert "`cv-mpc-q`" not in document.read_text()  # no control, no row
    for folder in ("metrics", "data"):
        (tmp_path / folder / "dense" / "cv-q").mkdir(parents=True)
    _write(tmp_path, "dense", "cv-q/wm-mpc-q", critic_only)
    _run(tmp_path, ("dense",), document)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["model_gain"]["dense"]["difference"] == pytest.approx(8.0)
    versus = summary["learned"]["dense"]["cv-mpc-q"]["versus_physics"]
    assert versus["difference"] == pytest.approx(8.0)
    text = document.read_text()
    assert "| `dense` | `cv-mpc-q` | 88.0 [" in text
    assert "| `dense` | +8.0 [" in text


def test_more_trainings_of_the_planning_model_are_each_paired_with_the_control(
    tmp_path: Path,
) -> None:
    physics = np.r_[np.zeros(20), np.ones(80)]
    critic_only = np.r_[np.zeros(12), np.ones(88)]
    seed_0 = np.r_[np.zeros(4), np.ones(96)]  # the model saves 8 of the critic's 12 failures
    seed_1 = np.r_[np.zeros(10), np.ones(90)]  # another training of it saves 2
    for method in SCENARIO_METHODS:
        _write(tmp_path, "dense", method, np.ones(100) if method == "oracle-mpc" else physics)
    _write(tmp_path, "dense", "wm-mpc-q", seed_0)
    document = tmp_path / "doc.md"
    document.write_text("<!-- socnav-wm:scenarios -->\n<!-- /socnav-wm:scenarios -->\n")
    _run(tmp_path, ("dense",), document)
    assert json.loads((tmp_path / "summary.json").read_text())["model_seeds"] == {}
    for folder in ("metrics", "data"):
        (tmp_path / folder / "dense" / "model-seed-1").mkdir(parents=True)
    _write(tmp_path, "dense", "model-seed-1/wm-mpc-q", seed_1)
    _run(tmp_path, ("dense",), document)  # without the control: paired with cv-mpc only
    seeds = json.loads((tmp_path / "summary.json").read_text())["model_seeds"]["dense"]
    assert seeds["1"]["versus_control"] is None
    assert seeds["1"]["versus_physics"]["difference"] == pytest.approx(10.0)
    assert "| `dense` | 1 | 90.0 [" in document.read_text()
    for folder in ("metrics", "data"):
        (tmp_path / folder / "dense" / "cv-q").mkdir(parents=True)
    _write(tmp_path, "dense", "cv-q/wm-mpc-q", critic_only)
    _run(tmp_path, ("dense",), document)
    seeds = json.loads((tmp_path / "summary.json").read_text())["model_seeds"]["dense"]
    assert list(seeds) == ["0", "1"]
    assert seeds["0"]["versus_control"]["difference"] == pytest.approx(8.0)
    assert seeds["1"]["versus_control"]["difference"] == pytest.approx(2.0)
    assert seeds["0"]["success"]["mean"] == pytest.approx(0.96)
    text = document.read_text()
    assert "| `dense` | 0 | 96.0 [" in text and "| `dense` | 1 | 90.0 [" in text
    # Its episodes gone (a fresh clone's): refused in one line naming the seed.
    (tmp_path / "data" / "dense" / "model-seed-1" / "wm-mpc-q.parquet").unlink()
    with pytest.raises(ValueError, match="planning model of seed 1"):
        _run(tmp_path, ("dense",), document)
    # A folder whose name holds no seed: refused in one line naming it.
    (tmp_path / "metrics" / "dense" / "model-seed-1").rename(
        tmp_path / "metrics" / "dense" / "model-seed-x"
    )
    with pytest.raises(ValueError, match="model-seed-x: expected a folder named model-seed-"):
        _run(tmp_path, ("dense",), document)


def test_a_model_of_another_preset_is_paired_with_physics_and_the_native_model(
    tmp_path: Path,
) -> None:
    physics = np.r_[np.zeros(20), np.ones(80)]
    native = np.r_[np.zeros(10), np.ones(90)]
    foreign = np.r_[np.zeros(30), np.ones(70)]
    for method in SCENARIO_METHODS:
        _write(tmp_path, "dense", method, np.ones(100) if method == "oracle-mpc" else physics)
    _write(tmp_path, "dense", "wm-mpc", native)
    for folder in ("metrics", "data"):
        (tmp_path / folder / "dense" / "transfer" / "easy").mkdir(parents=True)
    _write(tmp_path, "dense", "transfer/easy/wm-mpc", foreign)
    document = tmp_path / "doc.md"
    document.write_text("<!-- socnav-wm:scenarios -->\n<!-- /socnav-wm:scenarios -->\n")
    _run(tmp_path, ("dense",), document)
    result = json.loads((tmp_path / "summary.json").read_text())["transfer"]["dense"]["easy"]
    assert result["versus_physics"]["difference"] == pytest.approx(-10.0)
    assert result["versus_native"]["difference"] == pytest.approx(-20.0)
    assert "| `dense` | `easy` | 70.0 [" in document.read_text()
    # Its episodes gone (a fresh clone's): refused in one line, not a row without pairs.
    (tmp_path / "data" / "dense" / "transfer" / "easy" / "wm-mpc.parquet").unlink()
    with pytest.raises(ValueError, match="transfer of easy's model to dense"):
        _run(tmp_path, ("dense",), document)


def test_the_presets_agents_join_the_report_with_intervals_over_seeds(tmp_path: Path) -> None:
    for method in SCENARIO_METHODS:
        _write(tmp_path, "dense", method, np.ones(20))
    rows = [
        {"variant": v, "seed": s, "status": "done" if (v, s) != ("maspm", 2) else "failed",
         "success": p, "human_collision": 1 - p, "max_steps": 0.0}
        for v, ps in (("dueling-dqn", (0.8, 0.82, 0.84)), ("maspm", (0.7, 0.72, 0.0)))
        for s, p in enumerate(ps)
    ]  # fmt: skip
    study = tmp_path / "metrics" / "dense" / "dqn"
    study.mkdir(parents=True)
    pq.write_table(pa.Table.from_pylist(rows), study / "results.parquet")
    document = tmp_path / "doc.md"
    document.write_text("<!-- socnav-wm:scenarios -->\n<!-- /socnav-wm:scenarios -->\n")
    _run(tmp_path, ("dense",), document)
    agents = json.loads((tmp_path / "summary.json").read_text())["dqn"]["dense"]
    assert agents["dueling-dqn"]["seeds"] == 3 and agents["maspm"]["seeds"] == 2  # done only
    assert agents["dueling-dqn"]["success"]["mean"] == pytest.approx(0.82)
    assert "| `dense` | `dueling-dqn` | 3 | 82.0 [" in document.read_text()
    pq.write_table(pa.Table.from_pylist([{"variant": "maspm"}]), study / "results.parquet")
    with pytest.raises(ValueError, match="results.parquet: lacks the column"):
        _run(tmp_path, ("dense",), document)
