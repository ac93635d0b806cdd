"""dvc.yaml's source deps are each stage's import closure (socnav_wm.stages.deps)."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest
import yaml

from socnav_wm.stages.deps import (
    STAGE_MODULES,
    dvc_yaml_differences,
    import_closure,
    stage_dependencies,
    write_dvc_yaml,
)

ROOT = Path(__file__).resolve().parents[1]


def test_dvc_yaml_lists_exactly_the_sources_each_stage_executes() -> None:
    assert dvc_yaml_differences(ROOT / "dvc.yaml") == []
    assert dvc_yaml_differences(ROOT / "studies" / "dvc.yaml") == []
    assert dvc_yaml_differences(ROOT / "scenarios" / "dvc.yaml") == []


def test_the_studies_are_a_pipeline_of_their_own() -> None:
    """A plain `dvc repro` (the root dvc.yaml) never starts a study; each study stage runs from
    the repository root, so that its paths and params.yaml are the root's."""
    root = yaml.safe_load((ROOT / "dvc.yaml").read_text())["stages"]
    studies = yaml.safe_load((ROOT / "studies" / "dvc.yaml").read_text())["stages"]
    assert not [name for name in root if name.startswith("study_")]
    assert set(studies) == {"study_horizon", "study_seeds", "study_sort_humans", "study_claims"}
    for name, stage in studies.items():
        assert stage["wdir"] == "..", name
        if name == "study_claims":  # downstream of the report and of the studies that check claims
            assert stage["cmd"] == "socnav-wm study-claims"
            assert stage["deps"][:3] == [
                "reports/claims.json",
                "reports/studies/seeds",
                "reports/studies/horizon",
            ]
            continue
        assert stage["cmd"] == f"socnav-wm sweep --study {name.removeprefix('study_')}"
        assert stage["deps"][:2] == ["models/vae.pt", "models/lstm.pt"]
    # A file that is no pipeline file is refused rather than checked against either list.
    with pytest.raises(ValueError, match="params.yaml: not a dvc.yaml"):
        dvc_yaml_differences(ROOT / "params.yaml")


def test_a_missing_or_extra_dependency_is_reported(tmp_path: Path) -> None:
    spec = yaml.safe_load((ROOT / "dvc.yaml").read_text())
    baseline = spec["stages"]["evaluate_baseline"]["do"]
    baseline["deps"].remove("socnav_wm/env/reward.py")
    spec["stages"]["collect"]["deps"].append("socnav_wm/evaluation/figures.py")
    (tmp_path / "dvc.yaml").write_text(yaml.safe_dump(spec))
    problems = dvc_yaml_differences(tmp_path / "dvc.yaml")
    assert len(problems) == 2
    assert any("evaluate_baseline: missing socnav_wm/env/reward.py" in p for p in problems)
    assert any("collect: missing nothing; not executed socnav_wm/evaluation/figures.py" in p
               for p in problems)  # fmt: skip


def test_a_stage_the_deps_table_does_not_know_is_reported(tmp_path: Path) -> None:
    spec = yaml.safe_load((ROOT / "dvc.yaml").read_text())
    spec["stages"]["my_stage"] = {"cmd": "socnav-wm collect", "deps": ["params.yaml"]}
    (tmp_path / "dvc.yaml").write_text(yaml.safe_dump(spec))
    assert dvc_yaml_differences(tmp_path / "dvc.yaml") == [
        f"{tmp_path / 'dvc.yaml'}: stage my_stage: not in socnav_wm/stages/deps.py's "
        "STAGE_MODULES (its sources cannot be checked)"
    ]


def test_the_closure_follows_imports_inside_functions_and_packages() -> None:
    deps = stage_dependencies()
    # evaluate_method imports the baselines inside a function; the simulator reaches the
    # reward through its package; every stage runs socnav_wm/__init__.py and its own module.
    assert "socnav_wm/agents/baselines.py" in deps["evaluate_baseline"]
    for stage in ("collect", "train_agent", "evaluate", "evaluate_baseline"):
        assert "socnav_wm/env/reward.py" in deps[stage], stage
    for stage, files in deps.items():
        own = STAGE_MODULES[stage].replace(".", "/") + ".py"
        assert "socnav_wm/__init__.py" in files and own in files, stage
        assert not [f for f in files if f.startswith("socnav_wm/cli/")], stage
        assert "socnav_wm/tracking.py" not in files
    # A stage does not depend on what it never runs.
    assert "socnav_wm/evaluation/figures.py" not in deps["train_agent"]
    assert "socnav_wm/agents/learner.py" not in deps["collect"]
    assert import_closure("socnav_wm.stages.train_vae") == deps["train_vae"]


def test_write_brings_the_lists_back_and_keeps_the_data_deps(tmp_path: Path) -> None:
    text = (ROOT / "dvc.yaml").read_text()
    broken = text.replace("      - socnav_wm/env/reward.py\n", "", 1).replace(
        "      - socnav_wm/io.py\n", "      - socnav_wm/io.py\n      - socnav_wm/cli/stages.py\n", 1
    )
    target = tmp_path / "dvc.yaml"
    target.write_text(broken)
    assert dvc_yaml_differences(target)
    assert write_dvc_yaml(target) is True
    assert dvc_yaml_differences(target) == []
    assert target.read_text() == text  # data deps, comments and order as they were
    assert write_dvc_yaml(target) is False


def test_predict_measures_every_planning_model_seed() -> None:
    """The stage names no seed: it reads planning_model.seeds (a param of the stage) and the
    folder that holds every seed's model (a dependency), so a change of the seeds reruns it."""
    from socnav_wm.layout import LAYOUT

    stages = yaml.safe_load((ROOT / "dvc.yaml").read_text())["stages"]
    stage = stages["predict"]
    assert "--planning-model" not in stage["cmd"]
    assert "planning_model.seeds" in stage["params"] and "prediction" in stage["params"]
    folder = LAYOUT.planning_dir.as_posix()
    assert folder in stage["deps"]
    writer = stages["train_planning_model"]["do"]["outs"]
    assert all(Path(out if isinstance(out, str) else next(iter(out))).parent.as_posix() == folder
               for out in writer)  # fmt: skip


def test_dvc_status_marks_only_the_stages_that_execute_an_edited_file(tmp_path: Path) -> None:
    """Real `dvc status` in a copy of the repository: after an edit of the renderer, only the
    stages that draw are stale; of the robot controllers, only the robots' evaluations; of the
    reward, every stage that runs the simulator; of the planning model's training, only the
    trainings (the planners and `predict` that read a trained model do not execute it)."""
    from tests.test_dvc import _dvc, _project_files

    copy = tmp_path / "repo"
    for name in _project_files():
        (copy / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / name, copy / name)
    git = ["git", "-c", "user.name=test", "-c", "user.email=test@example.com"]
    subprocess.run([*git, "init", "-q"], cwd=copy, check=True)
    subprocess.run([*git, "add", "-A"], cwd=copy, check=True)
    subprocess.run([*git, "commit", "-q", "-m", "copy"], cwd=copy, check=True)
    edited = (
        "socnav_wm/env/render.py",
        "socnav_wm/agents/baselines.py",
        "socnav_wm/env/reward.py",
        "socnav_wm/worldmodel/residual_training.py",
    )
    for name in edited:
        with (copy / name).open("a", encoding="utf-8") as handle:
            handle.write("\n# an edit\n")
    status = json.loads(_dvc(copy, "status", "--json"))
    stale = {name: set() for name in edited}
    for stage, changes in status.items():
        for change in changes:
            for name in (change.get("changed deps") or {}) if isinstance(change, dict) else ():
                if name in stale:
                    stale[name].add(stage.removeprefix("dvc.yaml:"))
    assert stale["socnav_wm/env/render.py"] == {"report"}
    robots = {stage for stage in status if stage.startswith("scenarios/dvc.yaml:scenario_robots@")}
    assert len(robots) == 2 * len(list((ROOT / "configs/scenarios").glob("*.yaml")))
    assert stale["socnav_wm/agents/baselines.py"] == {
        "evaluate_baseline@orca",
        "evaluate_baseline@sfm",
        *robots,
    }
    runs_the_simulator = {"collect", "evaluate_baseline@orca", "evaluate_planner@cv-mpc"}
    agents = {stage for stage in status if stage.startswith("train_agent@")}
    assert agents and runs_the_simulator | agents <= stale["socnav_wm/env/reward.py"]
    assert not {"train_vae", "train_lstm"} & stale["socnav_wm/env/reward.py"]
    trainings = {  # every stage that runs train-planning-model, in every pipeline
        stage
        for stage in status
        if STAGE_MODULES[stage.split(":")[-1].split("@")[0]]
        == "socnav_wm.stages.train_planning_model"
    }
    assert len(trainings) >= 3
    assert stale["socnav_wm/worldmodel/residual_training.py"] == trainings


def test_every_output_of_dvc_yaml_is_a_layout_path() -> None:
    """dvc.yaml names the files the CLI writes by default: each stage's outs and metrics are
    LAYOUT's paths (files in its folders, a model's parameters file), so that a moved default
    fails here."""
    from dataclasses import fields

    from socnav_wm.layout import LAYOUT
    from socnav_wm.stages.common import config_path

    known: list[Path] = []
    for item in fields(LAYOUT):
        value = getattr(LAYOUT, item.name)
        known += list(value) if isinstance(value, tuple) else [value]
    known += [config_path(path) for path in known]  # a model's resolved parameters beside it
    spec = yaml.safe_load((ROOT / "dvc.yaml").read_text())["stages"]
    outputs = []
    for stage in spec.values():
        body = stage.get("do", stage)
        for entry in (body.get("outs") or []) + (body.get("metrics") or []):
            outputs.append(Path(entry if isinstance(entry, str) else next(iter(entry))))
    assert outputs
    strays = [o for o in outputs if not any(o == k or k in o.parents for k in known)]
    assert strays == []
