"""Each stage's source dependencies, computed from its imports.

A stage's command runs its module in :mod:`socnav_wm.stages` (a study's:
:mod:`socnav_wm.studies.runner`); the Python files it can execute are that module's import
closure within the ``socnav_wm`` package: every ``import`` statement of every file reached (at
the top of a module or inside a function alike), and the ``__init__.py`` of every package on the
way. ``dvc.yaml`` and ``studies/dvc.yaml`` list exactly these files as each stage's deps, and
``tests/test_dvc_deps.py`` fails when they disagree; ``socnav-wm deps`` prints the lists.

Two modules are deliberately not dependencies, nor followed: the ``socnav_wm/cli/`` package (it
parses options and calls a stage function, and listing it would rerun every stage on an edit of
any command) and ``socnav_wm/tracking.py`` (it writes to MLflow, never to a stage's outputs).
"""

from __future__ import annotations

import ast
from pathlib import Path

from socnav_wm.io import first_line
from socnav_wm.method_names import BASELINE_NAMES, VARIANT_NAMES
from socnav_wm.methods import METHODS

PACKAGE_ROOT = Path(__file__).resolve().parents[1]
"""The ``socnav_wm`` package directory."""

STAGE_MODULES: dict[str, str] = {
    "collect": "socnav_wm.stages.collect",
    "train_vae": "socnav_wm.stages.train_vae",
    "train_lstm": "socnav_wm.stages.train_lstm",
    "train_agent": "socnav_wm.stages.train_agent",
    "evaluate": "socnav_wm.stages.evaluate",
    "evaluate_baseline": "socnav_wm.stages.evaluate",
    "evaluate_planner": "socnav_wm.stages.evaluate",
    "evaluate_wm_mpc": "socnav_wm.stages.evaluate",
    "evaluate_vae_lstm_mpc": "socnav_wm.stages.evaluate",
    "train_planning_model": "socnav_wm.stages.train_planning_model",
    "predict": "socnav_wm.stages.predict",
    "report": "socnav_wm.stages.report",
    # studies/dvc.yaml: `socnav-wm sweep --study NAME` (train-agent and evaluate per run).
    "study_horizon": "socnav_wm.studies.runner",
    "study_seeds": "socnav_wm.studies.runner",
    "study_sort_humans": "socnav_wm.studies.runner",
    # studies/dvc.yaml: the claims with the studies' evidence, after them and the report.
    "study_claims": "socnav_wm.stages.study_claims",
    # scenarios/dvc.yaml: every non-learning method in every scenario preset, and the table.
    "scenario_robots": "socnav_wm.stages.evaluate",
    "scenario_planners": "socnav_wm.stages.evaluate",
    # scenarios/dvc.yaml: the planning model learned in a preset, wm-mpc on it, and its errors
    # split by interaction.
    "scenario_collect": "socnav_wm.stages.collect",
    "scenario_planning_model": "socnav_wm.stages.train_planning_model",
    "scenario_wm_mpc": "socnav_wm.stages.evaluate",
    "scenario_predict": "socnav_wm.stages.predict",
    "scenario_blind_oracle": "socnav_wm.stages.evaluate",
    "scenario_transfer": "socnav_wm.stages.evaluate",
    # scenarios/dvc.yaml: the paper's world model and its five agents learned in a preset.
    "scenario_vae": "socnav_wm.stages.train_vae",
    "scenario_lstm": "socnav_wm.stages.train_lstm",
    "scenario_dqn": "socnav_wm.studies.runner",
    # scenarios/dvc.yaml: wm-mpc-q, with a dueling-dqn agent trained in the preset as its critic.
    "scenario_critic": "socnav_wm.stages.train_agent",
    "scenario_wm_mpc_q": "socnav_wm.stages.evaluate",
    # scenarios/dvc.yaml: the control, wm-mpc-q on constant velocity (the untrained model).
    "scenario_cv_model": "socnav_wm.stages.train_planning_model",
    "scenario_cv_q": "socnav_wm.stages.evaluate",
    # scenarios/dvc.yaml: more trainings of the planning model, and wm-mpc-q on each.
    "scenario_model_seeds": "socnav_wm.stages.train_planning_model",
    "scenario_wm_mpc_q_seeds": "socnav_wm.stages.evaluate",
    "scenarios_report": "socnav_wm.stages.scenarios_report",
}
"""Stage name → the module its command runs."""

STAGE_METHODS: dict[str, tuple[str, ...]] = {
    "evaluate": VARIANT_NAMES,
    "evaluate_baseline": BASELINE_NAMES,
    "evaluate_planner": ("cv-mpc", "oracle-mpc"),
    "evaluate_wm_mpc": ("wm-mpc",),
    "evaluate_vae_lstm_mpc": ("vae-lstm-mpc",),
    "study_horizon": VARIANT_NAMES,
    "study_seeds": VARIANT_NAMES,
    "study_sort_humans": VARIANT_NAMES,
    "scenario_robots": BASELINE_NAMES,
    "scenario_planners": ("cv-mpc", "oracle-mpc"),
    "scenario_wm_mpc": ("wm-mpc",),
    "scenario_predict": ("cv-mpc",),
    "scenario_blind_oracle": ("oracle-mpc",),
    "scenario_transfer": ("wm-mpc",),
    "scenario_dqn": VARIANT_NAMES,
    "scenario_wm_mpc_q": ("wm-mpc-q",),
    "scenario_cv_q": ("wm-mpc-q",),
    "scenario_wm_mpc_q_seeds": ("wm-mpc-q",),
}
"""Stage name → the methods whose policies it builds (a ``foreach`` stage: over all its items).
The registry imports a method's builder only when it builds a policy, out of the imports'
sight: the stage's modules are its command's module and these methods' builders
(:attr:`socnav_wm.methods.Method.builder`)."""


def _in_folder(stage: str) -> str:
    return "studies" if stage.startswith("study_") else "scenarios" if "scenario" in stage else ""


PIPELINE_FILES: dict[str, tuple[str, ...]] = {
    "dvc.yaml": tuple(stage for stage in STAGE_MODULES if not _in_folder(stage)),
    "studies/dvc.yaml": tuple(s for s in STAGE_MODULES if _in_folder(s) == "studies"),
    "scenarios/dvc.yaml": tuple(s for s in STAGE_MODULES if _in_folder(s) == "scenarios"),
}
"""Each pipeline file → its stages: the paper's pipeline at the root; the studies (hours of
trainings that a plain ``dvc repro`` must not start) in ``studies/``; the scenario presets'
evaluations in ``scenarios/``."""

NOT_DEPENDENCIES = frozenset({"socnav_wm.cli", "socnav_wm.tracking"})


def _file_of(module: str) -> Path | None:
    """The source file of ``socnav_wm…`` module ``module`` (None if there is none)."""
    parts = module.split(".")
    if parts[0] != "socnav_wm":
        return None
    base = PACKAGE_ROOT.joinpath(*parts[1:])
    if (base / "__init__.py").is_file():
        return base / "__init__.py"
    if base.with_suffix(".py").is_file():
        return base.with_suffix(".py")
    return None


def _imported_modules(path: Path, module: str) -> set[str]:
    """Every module ``path`` (the file of ``module``) imports, absolute, as dotted names; for
    ``from package import name``, also ``package.name`` (which may be a submodule)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    is_package = path.name == "__init__.py"
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against this module's package
                package = module.split(".")
                package = package if is_package else package[:-1]
                package = package[: len(package) - (node.level - 1)]
                base = ".".join(package + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            found.add(base)
            found.update(f"{base}.{alias.name}" for alias in node.names)
    return found


def _with_parents(module: str) -> list[str]:
    """``a.b.c`` → ``a``, ``a.b``, ``a.b.c``: importing a module runs its packages first."""
    parts = module.split(".")
    return [".".join(parts[: i + 1]) for i in range(len(parts))]


def stage_modules(stage: str) -> list[str]:
    """The modules stage ``stage`` runs: its command's, then its methods' builders."""
    builders = {METHODS[name].builder_module for name in STAGE_METHODS.get(stage, ())}
    return [STAGE_MODULES[stage], *sorted(builders)]


def import_closure(*modules: str) -> list[str]:
    """The repository-relative paths of the ``socnav_wm`` files that ``modules`` can execute."""
    seen: set[str] = set()
    files: set[Path] = set()
    todo = list(modules)
    while todo:
        name = todo.pop()
        for current in _with_parents(name):
            if current in seen or current in NOT_DEPENDENCIES:
                continue
            seen.add(current)
            path = _file_of(current)
            if path is None:
                continue
            files.add(path)
            todo.extend(m for m in _imported_modules(path, current) if m.startswith("socnav_wm"))
    root = PACKAGE_ROOT.parent
    return sorted(path.relative_to(root).as_posix() for path in files)


def stage_dependencies(path: str | Path | None = None) -> dict[str, list[str]]:
    """Stage name → the source files it depends on (:func:`import_closure` of its modules): of
    every stage, or of those of pipeline file ``path`` (``…/studies/dvc.yaml``: the studies',
    any other ``dvc.yaml``: the root pipeline's)."""
    stages = STAGE_MODULES if path is None else PIPELINE_FILES[_pipeline_file(path)]
    return {stage: import_closure(*stage_modules(stage)) for stage in stages}


def _pipeline_file(path: str | Path) -> str:
    """The key of :data:`PIPELINE_FILES` that ``path`` is (a copy of)."""
    path = Path(path)
    if path.name != "dvc.yaml":
        raise ValueError(f"{path}: not a dvc.yaml")
    folder = path.parent.name
    return f"{folder}/dvc.yaml" if folder in ("studies", "scenarios") else "dvc.yaml"


def _stage_definitions(dvc_yaml: dict) -> dict[str, dict]:
    """Stage name → its definition (the ``do:`` body of a ``foreach``)."""
    stages = {}
    for name, body in (dvc_yaml.get("stages") or {}).items():
        stages[name] = body.get("do", body) if "foreach" in body else body  # or a matrix
    return stages


def _read_dvc_yaml(path: str | Path) -> dict:
    """The content of pipeline file ``path``; a ValueError naming it when it is missing, not
    valid YAML (with the line of the first fault) or not a mapping."""
    import yaml

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such file")
    try:
        content = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}: " if mark is not None else ""
        problem = getattr(exc, "problem", None) or first_line(exc)
        raise ValueError(f"{path}: not valid YAML ({where}{problem})") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: not readable ({first_line(exc)})") from None
    if not isinstance(content, dict) or not isinstance(content.get("stages") or {}, dict):
        raise ValueError(f"{path}: not a dvc.yaml (no mapping of stages)")
    return content


def dvc_yaml_differences(path: str | Path = "dvc.yaml") -> list[str]:
    """One line per stage whose ``socnav_wm/`` deps in ``dvc.yaml`` are not exactly its import
    closure (empty when they all agree); a ValueError naming the file when it is no readable
    pipeline file."""
    closures = stage_dependencies(path)
    definitions = _stage_definitions(_read_dvc_yaml(path))
    problems = [
        f"{path}: stage {stage}: not in socnav_wm/stages/deps.py's STAGE_MODULES (its sources "
        "cannot be checked)"
        for stage in definitions
        if stage not in closures
    ]
    for stage, expected in closures.items():
        if stage not in definitions:
            problems.append(f"{path}: no stage {stage!r}")
            continue
        listed = {
            dep
            for dep in definitions[stage].get("deps") or []
            if isinstance(dep, str) and dep.startswith("socnav_wm")
        }
        missing, extra = sorted(set(expected) - listed), sorted(listed - set(expected))
        if missing or extra:
            problems.append(
                f"{path}: stage {stage}: missing {', '.join(missing) or 'nothing'}; "
                f"not executed {', '.join(extra) or 'nothing'}"
            )
    return problems


def write_dvc_yaml(path: str | Path = "dvc.yaml") -> bool:
    """Rewrite the ``socnav_wm/`` entries of each stage's deps in ``path`` to its import closure,
    keeping everything else (data deps, comments, order) as it is. Returns whether the file
    changed."""
    import re

    path = Path(path)
    expected = stage_dependencies(path)
    _read_dvc_yaml(path)  # a broken file is refused, not rewritten
    lines = path.read_text(encoding="utf-8").splitlines(keepends=True)
    out: list[str] = []
    stage: str | None = None
    i = 0
    while i < len(lines):
        line = lines[i]
        top = re.match(r"^  ([A-Za-z_][\w-]*):\s*$", line)
        if top:
            stage = top.group(1)
        deps = re.match(r"^(\s+)deps:", line)
        if deps and stage in expected:
            out.append(line)
            item = deps.group(1) + "  - "
            i += 1
            while i < len(lines) and lines[i].startswith(item):
                if not lines[i][len(item) :].startswith("socnav_wm"):
                    out.append(lines[i])  # data deps stay first, as they are
                i += 1
            out.extend(f"{item}{source}\n" for source in expected[stage])
            stage = None
            continue
        out.append(line)
        i += 1
    text = "".join(out)
    changed = text != path.read_text(encoding="utf-8")
    if changed:
        path.write_text(text, encoding="utf-8")
    return changed
