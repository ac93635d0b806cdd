"""A sweep's plan: the grid (``--seeds``, ``--grid``), every run's parameters (validated before
any run starts), its folder and its fingerprint, the runs already finished; and the outcome of a
sweep, every run's result.

Layout (``runs_dir``: ``data/studies/<name>``, ``out_dir``: ``reports/studies/<name>``)::

    runs_dir/<run>/agents/<variant>/seed-<S>.pt      the agent file (train-agent's)
    runs_dir/<run>/training/<variant>/seed-<S>.parquet
    runs_dir/<run>/metrics/{agents,eval}/…            train-agent's and evaluate's metrics
    runs_dir/<run>/eval/<variant>.parquet              the evaluation's episodes
    runs_dir/<run>/result.json                         written last: the run is finished
    runs_dir/checkpoints/                              resumable trainings (train-agent's)
    out_dir/results.parquet                            one row per run: grid values × metrics
    out_dir/summary.md                                 means and 95% intervals over seeds
    out_dir/figures/<key>.png                          each metric against each grid parameter

A run whose ``result.json`` carries the same fingerprint (its resolved parameters, the source
files it executes, and the world model's files when its variant reads them) is skipped. A run
that another study (a sibling of ``runs_dir``) finished with the same fingerprint is copied, not
trained again: the horizon study's horizon-2 cells are the seeds study's 2stepahead runs.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import re
import shutil
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from socnav_wm.config import ConfigError, Params, load_params, params_dict
from socnav_wm.layout import LAYOUT
from socnav_wm.studies.params import StudyParams

__all__ = [
    "RESULT_FILE",
    "RunSpec",
    "SweepPlan",
    "SweepResult",
    "format_value",
    "named_study",
    "parse_grid",
    "parse_seeds",
    "plan_sweep",
    "run_sources",
    "study_from_options",
]

RESULT_FILE = "result.json"
_RUN_SECTIONS = ("env", "agent", "eval")  # what train-agent and evaluate read
# The stages a run executes: their import closures are the source files in its fingerprint,
# but for the configuration's modules, which act on a run only through the resolved parameters
# (in the fingerprint themselves): a new section or a new error message keeps the runs.
_RUN_MODULES = ("socnav_wm.stages.train_agent", "socnav_wm.stages.evaluate")
_NOT_RUN_SOURCES = frozenset(
    {"socnav_wm/config.py", "socnav_wm/studies/__init__.py", "socnav_wm/studies/params.py"}
)


# ---------------------------------------------------------------------------------------------
# The grid
# ---------------------------------------------------------------------------------------------


def parse_seeds(text: str) -> list[int]:
    """``"0-4"`` → ``[0, 1, 2, 3, 4]``; ``"0,2,7"`` → ``[0, 2, 7]`` (``--seeds``)."""
    seeds: list[int] = []
    for part in text.split(","):
        part = part.strip()
        match = re.fullmatch(r"(\d+)(?:-(\d+))?", part)
        if not match or (match[2] is not None and int(match[2]) < int(match[1])):
            raise ConfigError(f"--seeds: expected seeds like '0-4' or '0,2,7', got {text!r}")
        last = int(match[2]) if match[2] is not None else int(match[1])
        seeds += range(int(match[1]), last + 1)
    if len(set(seeds)) != len(seeds):
        raise ConfigError(f"--seeds: a seed is listed twice in {text!r}")
    return seeds


def parse_grid(items: Sequence[str]) -> dict[str, list[Any]]:
    """``["agent.horizon=2,4,8"]`` → ``{"agent.horizon": [2, 4, 8]}`` (``--grid``, repeatable);
    each value is parsed as YAML, like ``--set``'s."""
    grid: dict[str, list[Any]] = {}
    for item in items:
        key, sep, values = item.partition("=")
        key = key.strip()
        if not sep or not key or not values.strip():
            raise ConfigError(f"--grid {item!r}: expected KEY=VALUE,VALUE,… (agent.horizon=2,4)")
        if key in grid:
            raise ConfigError(f"--grid: {key} is given twice")
        try:
            grid[key] = [yaml.safe_load(v.strip()) for v in values.split(",")]
        except yaml.YAMLError as exc:
            raise ConfigError(f"--grid {item!r}: {str(exc).splitlines()[0]}") from None
    return grid


def format_value(value: Any) -> str:
    """A grid value as ``--set`` spells it (YAML: ``true``, ``4``, ``0.5``, ``sfm``)."""
    return yaml.safe_dump(value, default_flow_style=True).strip().removesuffix("...").strip()


@dataclass(frozen=True)
class RunSpec:
    """One grid point of one variant and one seed."""

    variant: str
    seed: int
    values: tuple[tuple[str, Any], ...] = ()

    @property
    def overrides(self) -> list[str]:
        """The run's ``--set`` values (after the study's own overrides)."""
        return [f"{key}={format_value(value)}" for key, value in self.values]

    @property
    def name(self) -> str:
        """``2stepahead/agent.horizon=4/seed-0``: the run's name, in MLflow too."""
        return "/".join([self.variant, *self.overrides, f"seed-{self.seed}"])

    @property
    def slug(self) -> str:
        """The run's folder name (no ``/``)."""
        return re.sub(r"[^A-Za-z0-9._=-]+", "_", self.name.replace("/", "__"))


@dataclass
class SweepPlan:
    """A sweep, resolved: every run's parameters validated before any run starts."""

    name: str
    study: StudyParams
    runs: list[RunSpec]
    params: dict[RunSpec, Params]
    fingerprints: dict[RunSpec, str]
    runs_dir: Path
    out_dir: Path
    vae: Path
    lstm: Path

    @property
    def grid_keys(self) -> list[str]:
        return list(self.study.grid)

    def run_dir(self, run: RunSpec) -> Path:
        return self.runs_dir / run.slug

    def finished(self, run: RunSpec) -> dict[str, Any] | None:
        """The run's recorded result if it finished with the same fingerprint."""
        path = self.run_dir(run) / RESULT_FILE
        try:
            result = json.loads(path.read_text())
        except (OSError, ValueError):
            return None
        if result.get("fingerprint") != self.fingerprints[run]:
            return None
        # JSON has no NaN: an undefined metric was written as null.
        metrics = result.get("metrics", {})
        result["metrics"] = {k: math.nan if v is None else v for k, v in metrics.items()}
        return result

    def adopt(self, run: RunSpec) -> dict[str, Any] | None:
        """Copy the run that another study under ``runs_dir``'s parent finished with this run's
        fingerprint (the same training and evaluation, bit for bit) into this run's folder, and
        return its result (None if no study has it)."""
        from socnav_wm.io import write_json_atomic

        own = self.runs_dir.resolve()
        for path in sorted(self.runs_dir.parent.glob(f"*/*/{RESULT_FILE}")):
            if path.parent.parent.resolve() == own or path.parent.name.endswith(".copying"):
                continue
            try:
                result = json.loads(path.read_text())
            except (OSError, ValueError):
                continue
            if (
                result.get("fingerprint") != self.fingerprints[run]
                or result.get("status") != "done"
            ):
                continue
            target = self.run_dir(run)
            staging = target.with_name(f"{target.name}.copying")
            shutil.rmtree(staging, ignore_errors=True)
            shutil.copytree(path.parent, staging)
            result.update(run=run.name, grid=dict(run.values), copied_from=str(path.parent))
            write_json_atomic(staging / RESULT_FILE, result)
            if target.is_dir():  # an unfinished run's files
                shutil.rmtree(target)
            staging.rename(target)
            return self.finished(run)
        return None


def _file_digest(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def run_sources() -> list[str]:
    """The repository-relative source files a run executes (train-agent's and evaluate's import
    closures): an edit of any of them (the reward, the learner) makes every finished run stale,
    an edit elsewhere (the studies' modules, the report) keeps them."""
    from socnav_wm.stages.deps import import_closure

    files = {path for module in _RUN_MODULES for path in import_closure(module)}
    return sorted(files - _NOT_RUN_SOURCES)


def _sources_digest(files: Sequence[str]) -> str:
    from socnav_wm.stages.deps import PACKAGE_ROOT

    digest = hashlib.sha256()
    for name in files:
        digest.update(f"{name}\0{_file_digest(PACKAGE_ROOT.parent / name)}\0".encode())
    return digest.hexdigest()


def plan_sweep(
    name: str,
    study: StudyParams,
    *,
    params_path: Path = LAYOUT.params,
    overlays: Sequence[Path] = (),
    overrides: Sequence[str] = (),
    runs_dir: Path | None = None,
    out_dir: Path | None = None,
    vae: Path = LAYOUT.vae,
    lstm: Path = LAYOUT.lstm,
) -> SweepPlan:
    """Every run of ``study``, its parameters (``params_path``, ``overlays``, ``overrides``, the
    study's ``overrides``, then the grid values) and its fingerprint.

    Raises:
        ConfigError: a bad name, a grid key or value the parameters reject (one line, naming the
            run), or a missing world-model file.
    """
    if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]*", name):
        raise ConfigError(f"--name: {name!r} must be letters, digits, '_', '.' or '-'")
    for path, command in ((vae, "socnav-wm train-vae"), (lstm, "socnav-wm train-lstm")):
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such world-model file (make it: {command})")
    runs = [
        RunSpec(variant, seed, tuple(zip(study.grid, values, strict=True)))
        for variant in study.variants
        for values in itertools.product(*study.grid.values())
        for seed in study.seeds
    ]
    from socnav_wm.agents.features import VARIANTS

    digests = {"vae": _file_digest(vae), "lstm": _file_digest(lstm)}
    code = _sources_digest(run_sources())
    plan_params: dict[RunSpec, Params] = {}
    fingerprints: dict[RunSpec, str] = {}
    for run in runs:
        sets = [*overrides, *study.overrides, *run.overrides]
        try:
            params = load_params(params_path, overrides=sets, overlays=list(overlays))
        except ConfigError as exc:
            raise ConfigError(f"sweep {name}, run {run.name}: {exc}") from None
        plan_params[run] = params
        data = params_dict(params)
        identity = {
            "variant": run.variant,
            "seed": run.seed,
            "code": code,
            "params": {section: data[section] for section in _RUN_SECTIONS},
            **(digests if VARIANTS[run.variant].needs_world_model else {}),
        }
        fingerprints[run] = hashlib.sha256(
            json.dumps(identity, sort_keys=True, default=str).encode()
        ).hexdigest()
    return SweepPlan(
        name=name,
        study=study,
        runs=runs,
        params=plan_params,
        fingerprints=fingerprints,
        runs_dir=Path(runs_dir or LAYOUT.study_run_dir(name)),
        out_dir=Path(out_dir or LAYOUT.study_report_dir(name)),
        vae=vae,
        lstm=lstm,
    )


def study_from_options(
    study: StudyParams | None,
    variants: str | None,
    seeds: str | None,
    grid: Sequence[str],
) -> StudyParams:
    """A named study with the command line's ``--variants``/``--seeds``/``--grid`` replacing its
    own, or an ad-hoc one from them alone."""
    values: dict[str, Any] = study.model_dump() if study is not None else {}
    if variants is not None:
        values["variants"] = [v.strip() for v in variants.split(",") if v.strip()]
    if seeds is not None:
        values["seeds"] = parse_seeds(seeds)
    if grid:
        values["grid"] = parse_grid(grid)
    for option in ("variants", "seeds"):
        if option not in values:
            raise ConfigError(f"--{option}: required without --study")
    try:
        return StudyParams(**values)
    except ValueError as exc:
        raise ConfigError(f"sweep: {str(exc).splitlines()[0]}") from None


def named_study(params: Params, name: str) -> StudyParams:
    """The study ``--study NAME`` names in ``params.yaml``'s ``studies:``."""
    if name not in params.studies:
        known = ", ".join(params.studies) or "none"
        raise ConfigError(f"--study: no study {name!r} in params.yaml (studies: {known})")
    return params.studies[name]


# ---------------------------------------------------------------------------------------------
# The outcome
# ---------------------------------------------------------------------------------------------


@dataclass
class SweepResult:
    """Every run's result (recorded earlier, or from this sweep), in the plan's order."""

    plan: SweepPlan
    results: dict[RunSpec, dict[str, Any]] = field(default_factory=dict)
    skipped: int = 0
    wall_s: float = 0.0

    @property
    def failed(self) -> list[dict[str, Any]]:
        return [r for r in self.results.values() if r.get("status") != "done"]
