"""``socnav-wm sweep``: a grid of agent runs (variants × seeds × parameter values) as Ray tasks.

Each run is exactly ``socnav-wm train-agent --variant V --seed S --set KEY=VALUE …`` followed by
``socnav-wm evaluate --method V`` on that one agent (same code, same parameters: its weights are
bit for bit the serial command's), in a Ray task of one CPU and one torch thread. Ray starts
locally (one task per core) unless ``address`` names a running cluster (docs/cluster.md).

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
files it executes, and the world model's files when its variant reads them) is skipped; an
unfinished one resumes from its checkpoint; a failed one is reported with its error and does not
stop the others. A run that another study (a sibling of ``runs_dir``) finished with the same
fingerprint is copied, not trained again: the horizon study's horizon-2 cells are the seeds
study's 2stepahead runs. Only this module imports ray, and only inside :func:`run_sweep`.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import os
import re
import shutil
import statistics
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from socnav_wm.config import ConfigError, Params, StudyParams, load_params, params_dict

__all__ = [
    "RunSpec",
    "SweepPlan",
    "SweepResult",
    "execute_run",
    "parse_grid",
    "parse_seeds",
    "plan_sweep",
    "run_sweep",
    "write_results",
]

RESULT_FILE = "result.json"
# The metrics of a run that the summary and the figures show (all of them go to the table).
SUMMARY_METRICS = (
    "success",
    "human_collision",
    "wall_collision",
    "discomfort",
    "time_to_reach_goal",
    "train_episodes_to_solve",
    "train_cpu_s",
)
_RUN_SECTIONS = ("env", "agent", "eval")  # what train-agent and evaluate read
# The stages a run executes: their import closures are the source files in its fingerprint,
# but for the configuration module, which acts on a run only through the resolved parameters
# (in the fingerprint themselves): a new section or a new error message keeps the runs.
_RUN_MODULES = ("socnav_wm.stages.train_agent", "socnav_wm.stages.evaluate")
_NOT_RUN_SOURCES = frozenset({"socnav_wm/config.py"})


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


def _format_value(value: Any) -> str:
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
        return [f"{key}={_format_value(value)}" for key, value in self.values]

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
    an edit elsewhere (this module, the report) keeps them."""
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
    params_path: Path = Path("params.yaml"),
    overlays: Sequence[Path] = (),
    overrides: Sequence[str] = (),
    runs_dir: Path | None = None,
    out_dir: Path | None = None,
    vae: Path = Path("models/vae.pt"),
    lstm: Path = Path("models/lstm.pt"),
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
        runs_dir=Path(runs_dir or Path("data/studies") / name),
        out_dir=Path(out_dir or Path("reports/studies") / name),
        vae=vae,
        lstm=lstm,
    )


# ---------------------------------------------------------------------------------------------
# One run (inside a Ray task)
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RunJob:
    """What a task needs: plain, picklable, with absolute paths (a task may run on another
    machine, where the paths must name a shared folder)."""

    spec: RunSpec
    params: dict[str, Any]
    fingerprint: str
    run_dir: str
    checkpoint_dir: str
    vae: str
    lstm: str
    tracking: bool
    tracking_uri: str | None
    experiment: str | None
    parent_run_id: str | None
    threads: int = 1


def _first_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def execute_run(job: RunJob) -> dict[str, Any]:
    """Train and evaluate one run; returns its result (``status`` ``done`` or ``failed`` with
    ``error``), never raises for the run's own failures."""
    started, cpu_started = time.time(), time.process_time()
    try:
        return _execute(job, started, cpu_started)
    except Exception as exc:  # noqa: BLE001 - a failed run is a result, the others go on
        return {
            "run": job.spec.name,
            "status": "failed",
            "error": _first_line(exc),
            "wall_s": time.time() - started,
        }


def _execute(job: RunJob, started: float, cpu_started: float) -> dict[str, Any]:
    import torch

    from socnav_wm import tracking
    from socnav_wm.agents.checkpoint import checkpoint_file, run_identity
    from socnav_wm.io import write_json_atomic
    from socnav_wm.stages import evaluate as evaluate_stage
    from socnav_wm.stages import train_agent as train_stage

    torch.set_num_threads(job.threads)
    if job.tracking_uri:
        os.environ["MLFLOW_TRACKING_URI"] = job.tracking_uri
    if job.experiment:
        os.environ["MLFLOW_EXPERIMENT_NAME"] = job.experiment
    spec = job.spec
    params = Params.model_validate(job.params)
    run_dir = Path(job.run_dir)
    grid_tags = {"sweep_run": spec.name, "variant": spec.variant, "training_seed": spec.seed}
    grid_tags.update({f"grid.{key}": _format_value(value) for key, value in spec.values})
    logged = {"variant": spec.variant, "seed": spec.seed, "grid": dict(spec.values)}
    identity = run_identity(
        spec.variant, params.agent, params.env, spec.seed, Path(job.vae), Path(job.lstm)
    )
    resumed = checkpoint_file(job.checkpoint_dir, identity).is_file()
    with (
        tracking.nested_under(job.parent_run_id, grid_tags),
        tracking.stage_run(
            "sweep-run", logged, enabled=job.tracking, run_name=f"sweep-run/{spec.name}"
        ) as child,
        tracking.nested_under(child.run_id, grid_tags),
    ):
        train_started = time.process_time()
        train_stage.run(
            params,
            variant=spec.variant,
            seed=spec.seed,
            vae=Path(job.vae),
            lstm=Path(job.lstm),
            out_dir=run_dir / "agents",
            log_dir=run_dir / "training",
            metrics_dir=run_dir / "metrics" / "agents",
            checkpoint_dir=Path(job.checkpoint_dir),
            resume=True,
            tracking=job.tracking,
            quiet=True,
        )
        train_cpu = time.process_time() - train_started
        eval_params = params.replace(experiment=params.experiment.replace(seeds=[spec.seed]))
        evaluate_stage.run(
            eval_params,
            method=spec.variant,
            agents_dir=run_dir / "agents",
            out_dir=run_dir / "eval",
            metrics_dir=run_dir / "metrics" / "eval",
            tracking=job.tracking,
            quiet=True,
        )
        metrics = _run_metrics(run_dir, spec)
        metrics["train_cpu_s"] = train_cpu
        child.log_metrics(metrics)
    result = {
        "run": spec.name,
        "status": "done",
        "fingerprint": job.fingerprint,
        "variant": spec.variant,
        "seed": spec.seed,
        "grid": {key: value for key, value in spec.values},
        "metrics": metrics,
        "resumed": resumed,
        "node": _ray_node(),
        "wall_s": time.time() - started,
        "cpu_s": time.process_time() - cpu_started,
    }
    write_json_atomic(run_dir / RESULT_FILE, result)
    return result


def _ray_node() -> str | None:
    """The Ray node this runs on (None outside a Ray task)."""
    ray = sys.modules.get("ray")
    if ray is None or not ray.is_initialized():
        return None
    return ray.get_runtime_context().get_node_id()


def _run_metrics(run_dir: Path, spec: RunSpec) -> dict[str, float]:
    """The evaluation's means and the training's summary (``train_``-prefixed) of one run."""
    evaluation = json.loads((run_dir / "metrics" / "eval" / f"{spec.variant}.json").read_text())
    metrics = {  # None: undefined here (e.g. the time to goal of a run that never arrives)
        name: math.nan if v["mean"] is None else float(v["mean"])
        for name, v in evaluation["metrics"].items()
    }
    training_path = run_dir / "metrics" / "agents" / spec.variant / f"seed-{spec.seed}.json"
    training = json.loads(training_path.read_text())
    for key, value in training.items():
        if isinstance(value, int | float) and not isinstance(value, bool):
            metrics[f"train_{key}"] = float(value)
    if training.get("episodes_to_solve") is None:  # never solved: one past the last episode
        metrics["train_episodes_to_solve"] = float(training.get("episodes", 0)) + 1
    return metrics


# ---------------------------------------------------------------------------------------------
# The sweep
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


def _import_ray() -> Any:
    try:
        import ray
    except ImportError:
        raise ConfigError(
            "socnav-wm sweep needs Ray, which is not installed: pip install 'socnav-wm[sweep]'"
        ) from None
    return ray


def _eta(durations: Sequence[float], remaining: int, slots: int) -> str:
    if not durations or remaining == 0:
        return "unknown" if remaining else "0 min"
    seconds = sum(durations) / len(durations) * math.ceil(remaining / max(slots, 1))
    return f"about {seconds / 60:.0f} min" if seconds >= 60 else f"about {seconds:.0f} s"


def run_sweep(
    plan: SweepPlan,
    *,
    address: str | None = None,
    cpus: int | None = None,
    tracking: bool = True,
    progress: Callable[[str], None] | None = None,
) -> SweepResult:
    """Run ``plan``'s unfinished runs as Ray tasks, then write its results (see the module
    docstring). ``address``: a running Ray cluster (``auto``, ``HOST:PORT``, ``ray://…``); else a
    local Ray with ``cpus`` CPUs (default: every core). ``progress`` receives one line per
    change (default: standard error)."""
    say = progress or (lambda line: print(line, file=sys.stderr, flush=True))
    if cpus is not None and cpus < 1:
        raise ConfigError(f"--cpus: must be >= 1, got {cpus}")
    started = time.time()
    outcome = SweepResult(plan)
    todo = []
    copied = 0
    for run in plan.runs:
        recorded = plan.finished(run)
        if recorded is None:
            recorded = plan.adopt(run)
            copied += recorded is not None
        if recorded is not None:
            outcome.results[run] = recorded
        else:
            todo.append(run)
    outcome.skipped = len(plan.runs) - len(todo)
    from_others = f" ({copied} copied from other studies)" if copied else ""
    say(
        f"sweep {plan.name}: {len(plan.runs)} runs, {outcome.skipped} already finished"
        f"{from_others}, {len(todo)} to run"
    )
    if todo:
        ray = _import_ray()
        _run_tasks(ray, plan, todo, outcome, address, cpus, tracking, say)
    outcome.wall_s = time.time() - started
    write_results(outcome)
    return outcome


def _run_tasks(
    ray: Any,
    plan: SweepPlan,
    todo: list[RunSpec],
    outcome: SweepResult,
    address: str | None,
    cpus: int | None,
    tracking: bool,
    say: Callable[[str], None],
) -> None:
    from socnav_wm import tracking as track

    started_here = not ray.is_initialized()
    if started_here:
        options: dict[str, Any] = {
            "include_dashboard": False,
            "logging_level": "ERROR",
            "log_to_driver": False,
        }
        if address is None:
            options.update(num_cpus=cpus or os.cpu_count() or 1, object_store_memory=200 << 20)
        try:
            ray.init(address=address, **options)
        except (ConnectionError, RuntimeError, ValueError) as exc:
            where = f"--address {address}" if address else "local Ray"
            raise ConfigError(f"{where}: Ray did not start ({_first_line(exc)})") from None
    slots = max(1, int(ray.cluster_resources().get("CPU", 1)))
    logged = {"study": plan.study.model_dump(), "runs": len(plan.runs)}
    try:
        with track.stage_run(
            "sweep", logged, enabled=tracking, run_name=f"sweep/{plan.name}"
        ) as parent:
            parent.set_tag("sweep", plan.name)
            uri = track.tracking_uri() if tracking else None
            task = ray.remote(num_cpus=1, max_retries=0)(execute_run)
            pending = {}
            for run in todo:
                job = RunJob(
                    spec=run,
                    params=params_dict(plan.params[run]),
                    fingerprint=plan.fingerprints[run],
                    run_dir=str(plan.run_dir(run).resolve()),
                    checkpoint_dir=str((plan.runs_dir / "checkpoints").resolve()),
                    vae=str(plan.vae.resolve()),
                    lstm=str(plan.lstm.resolve()),
                    tracking=tracking,
                    tracking_uri=uri,
                    experiment=track.experiment_name() if tracking else None,
                    parent_run_id=parent.run_id,
                )
                pending[task.remote(job)] = run
            durations: list[float] = []
            done = failed = 0
            while pending:
                ready, _ = ray.wait(list(pending), num_returns=1)
                for ref in ready:
                    run = pending.pop(ref)
                    try:
                        result = ray.get(ref)
                    except Exception as exc:  # noqa: BLE001 - a dead worker fails one run
                        result = {"run": run.name, "status": "failed", "error": _first_line(exc)}
                    outcome.results[run] = result
                    if result["status"] == "done":
                        done += 1
                        durations.append(float(result.get("wall_s", 0.0)))
                    else:
                        failed += 1
                        say(f"sweep {plan.name}: run {run.name} failed: {result['error']}")
                running = min(len(pending), slots)
                say(
                    f"sweep {plan.name}: {done + failed}/{len(todo)} finished ({done} done, "
                    f"{failed} failed), {running} running, "
                    f"{_eta(durations, len(pending), slots)} left"
                )
            parent.log_metrics({"runs_done": done, "runs_failed": failed})
    finally:
        if started_here:
            ray.shutdown()


# ---------------------------------------------------------------------------------------------
# Results
# ---------------------------------------------------------------------------------------------


def _is_rate(name: str) -> bool:
    return name in ("success", "human_collision", "wall_collision") or name.endswith("_rate")


def _interval(values: Sequence[float], name: str) -> tuple[float, float, float]:
    """Mean and 95% Student-t interval over seeds (NaN bounds for one seed), cut to the
    metric's range: every summary metric is non-negative, and a rate is at most 1."""
    from scipy import stats

    values = [v for v in values if not math.isnan(v)]
    n = len(values)
    if n == 0:
        return math.nan, math.nan, math.nan
    mean = float(statistics.fmean(values))
    if n < 2:
        return mean, math.nan, math.nan
    half = float(stats.t.ppf(0.975, n - 1)) * statistics.stdev(values) / math.sqrt(n)
    return mean, max(mean - half, 0.0), min(mean + half, 1.0) if _is_rate(name) else mean + half


def _groups(outcome: SweepResult) -> dict[tuple[str, tuple[Any, ...]], list[dict[str, Any]]]:
    groups: dict[tuple[str, tuple[Any, ...]], list[dict[str, Any]]] = {}
    for run in outcome.plan.runs:
        result = outcome.results.get(run)
        if result and result.get("status") == "done":
            key = (run.variant, tuple(value for _, value in run.values))
            groups.setdefault(key, []).append(result)
    return groups


def write_results(outcome: SweepResult) -> list[Path]:
    """``results.parquet``, ``summary.md`` and the figures of a sweep (atomically each)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from socnav_wm.io import atomic_path, write_text_atomic

    plan = outcome.plan
    rows = []
    metric_names: list[str] = []
    for run in plan.runs:
        result = outcome.results.get(run, {"status": "not run"})
        metrics = result.get("metrics", {})
        for name in metrics:
            if name not in metric_names:
                metric_names.append(name)
        rows.append((run, result, metrics))
    columns: dict[str, list[Any]] = {
        "run": [r.name for r, _, _ in rows],
        "variant": [r.variant for r, _, _ in rows],
        "seed": [r.seed for r, _, _ in rows],
    }
    for index, key in enumerate(plan.grid_keys):
        columns[key] = [_format_value(r.values[index][1]) for r, _, _ in rows]
    columns["status"] = [res.get("status", "not run") for _, res, _ in rows]
    columns["error"] = [res.get("error") for _, res, _ in rows]
    columns["resumed"] = [res.get("resumed") for _, res, _ in rows]
    columns["node"] = [res.get("node") for _, res, _ in rows]
    columns["wall_s"] = [res.get("wall_s") for _, res, _ in rows]
    for name in metric_names:
        columns[name] = [m.get(name) for _, _, m in rows]
    table = pa.table(
        {
            k: pa.array(v, type=pa.float64() if k in metric_names else None)
            for k, v in columns.items()
        }
    )
    plan.out_dir.mkdir(parents=True, exist_ok=True)
    results_path = plan.out_dir / "results.parquet"
    with atomic_path(results_path) as tmp:
        pq.write_table(table, tmp)
    summary_path = plan.out_dir / "summary.md"
    verdict = horizon_verdict(outcome)
    training = training_claims(outcome)
    write_text_atomic(summary_path, _summary(outcome, verdict, training))
    written = [results_path, summary_path]
    found = verdict if verdict is not None else training
    if found is not None:  # for machines: each claim, its comparisons, its verdict
        written.append(plan.out_dir / "claims.json")
        write_text_atomic(written[-1], json.dumps(found, indent=2) + "\n")
    return [*written, *_figures(outcome)]


def _present_metrics(groups: Mapping[Any, list[dict[str, Any]]]) -> list[str]:
    return [
        m for m in SUMMARY_METRICS if any(m in r["metrics"] for g in groups.values() for r in g)
    ]


def _fmt(value: float, name: str) -> str:
    if math.isnan(value):
        return "–"
    if _is_rate(name):
        return f"{value:.1%}"
    return f"{value:.3g}"


def _summary(
    outcome: SweepResult,
    verdict: dict[str, Any] | None,
    training: list[dict[str, Any]] | None = None,
) -> str:
    plan = outcome.plan
    groups = _groups(outcome)
    done = sum(len(v) for v in groups.values())
    grid = ", ".join(
        f"`{key}` ∈ {{{', '.join(map(_format_value, vals))}}}"
        for key, vals in plan.study.grid.items()
    )
    lines = [
        f"# Study `{plan.name}`",
        "",
        f"Variants {', '.join(plan.study.variants)}; seeds "
        f"{', '.join(map(str, plan.study.seeds))}" + (f"; {grid}" if grid else "") + ". "
        f"{done} of {len(plan.runs)} runs finished"
        + (f", {len(outcome.failed)} failed" if outcome.failed else "")
        + ". Each run: `socnav-wm train-agent` then `socnav-wm evaluate` on "
        f"{plan.params[plan.runs[0]].eval.episodes} test scenarios; mean [95% interval over "
        "seeds] (Student t; – with one seed).",
        "",
    ]
    metrics = _present_metrics(groups)
    header = ["variant", *[f"`{k}`" for k in plan.grid_keys], "seeds", *metrics]
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for (variant, values), results in groups.items():
        cells = [variant, *map(_format_value, values), str(len(results))]
        for metric in metrics:
            vals = [r["metrics"][metric] for r in results if metric in r["metrics"]]
            mean, low, high = _interval(vals, metric)
            cell = _fmt(mean, metric)
            if not math.isnan(low):
                cell += f" [{_fmt(low, metric)}, {_fmt(high, metric)}]"
            cells.append(cell)
        lines.append("| " + " | ".join(cells) + " |")
    if outcome.failed:
        lines += ["", "Failed runs:", ""]
        lines += [f"- `{r['run']}`: {r.get('error', '')}" for r in outcome.failed]
    if verdict is not None:
        lines += ["", "## The paper's horizon claim", "", f"> {HORIZON_CLAIM}", ""]
        lines += [*verdict["comparisons"], "", f"**Verdict: {verdict['verdict']}.**"]
    if training is not None:
        lines += ["", "## The paper's training claims", "", TRAINING_CLAIMS_NOTE, ""]
        for claim in training:
            lines.append(f"- **{claim['verdict'].upper()}**: {claim['statement']}")
            lines += [f"  - {check['status']}: {check['evidence']}" for check in claim["checks"]]
    lines += ["", *[f"![{key}](figures/{_figure_name(key)})" for key in plan.grid_keys]]
    return "\n".join(lines).rstrip() + "\n"


HORIZON_CLAIM = (
    "predicting more than 2 steps ahead did not improve the results in our SocNavGym setup and "
    "made training slower (the paper, section 3.1)"
)


def horizon_verdict(outcome: SweepResult, alpha: float = 0.05) -> dict[str, Any] | None:
    """The paper's horizon claim checked on a study whose only grid key is ``agent.horizon``
    with 2 among its values (None for any other study): for each variant and each horizon above
    2, a paired t-test over the seeds that finished both, on test success and on the training's
    CPU seconds. The claim holds when no longer horizon has a higher success (p < ``alpha``)
    and every one trains slower (p < ``alpha``); it fails when a longer horizon succeeds more
    or trains faster; otherwise the seeds do not decide it."""
    from scipy import stats

    plan = outcome.plan
    if plan.grid_keys != ["agent.horizon"] or 2 not in plan.study.grid["agent.horizon"]:
        return None
    by_point: dict[tuple[str, Any], dict[int, dict[str, float]]] = {}
    for run in plan.runs:
        result = outcome.results.get(run)
        if result and result.get("status") == "done":
            by_point.setdefault((run.variant, run.values[0][1]), {})[run.seed] = result["metrics"]
    lines, better, faster, undecided = [], [], [], []
    for variant in plan.study.variants:
        base = by_point.get((variant, 2), {})
        for horizon in plan.study.grid["agent.horizon"]:
            if horizon <= 2:
                continue
            other = by_point.get((variant, horizon), {})
            seeds = sorted(set(base) & set(other))
            line = f"- `{variant}`, horizon {horizon} against 2, {len(seeds)} paired seeds:"
            where = f"{variant} at {horizon}"
            if len(seeds) < 2:
                lines.append(f"{line} too few to test.")
                undecided.append(where)
                continue
            parts = []
            for metric, label in (("success", "success"), ("train_cpu_s", "training CPU s")):
                diffs = [other[s][metric] - base[s][metric] for s in seeds]
                diff = statistics.fmean(diffs)
                if statistics.stdev(diffs) > 0:
                    p = float(stats.ttest_1samp(diffs, 0.0).pvalue)  # the paired t-test
                else:  # the same difference on every seed
                    p = 1.0 if diff == 0 else 0.0
                shown = f"{diff:+.1%}" if metric == "success" else f"{diff:+.0f}"
                parts.append(f"{label} {shown} (p = {p:.3f})")
                significant = p < alpha
                if metric == "success" and significant and diff > 0:
                    better.append(where)
                if metric == "train_cpu_s":
                    if significant and diff < 0:
                        faster.append(where)
                    elif not (significant and diff > 0):
                        undecided.append(where)
            lines.append(f"{line} {'; '.join(parts)}.")
    if better or faster:
        verdict = (
            "does not hold ("
            + ", ".join(
                [*(f"{w} succeeds more" for w in better), *(f"{w} trains faster" for w in faster)]
            )
            + ")"
        )
    elif undecided:
        verdict = "not decided by these seeds (" + ", ".join(sorted(set(undecided))) + ")"
    else:
        verdict = "holds: no horizon above 2 succeeds more, and every one trains slower"
    return {"claim": HORIZON_CLAIM, "comparisons": lines, "verdict": verdict}


TRAINING_CLAIMS_NOTE = (
    "Checked as the report checks them (`socnav_wm/evaluation/claims.py`), on this study's "
    "seeds: per-seed final smoothed training return or episodes to solve, Mann–Whitney, Holm "
    "within each claim."
)


def training_claims(outcome: SweepResult) -> list[dict[str, Any]] | None:
    """The paper's training claims (``training-…`` in :data:`socnav_wm.evaluation.paper.CLAIMS`)
    checked on a study without a grid (one run per variant and seed, like the pipeline's, with
    more seeds), from its runs' training logs, with the report's rules and the report section's
    window and α; None for a study with a grid or fewer than two variants finished."""
    plan = outcome.plan
    if plan.grid_keys:
        return None
    import pyarrow.parquet as pq

    from socnav_wm.evaluation.claims import check_claims
    from socnav_wm.evaluation.paper import CLAIMS
    from socnav_wm.evaluation.report import training_summary

    logs: dict[str, dict[int, Any]] = {}
    for run in plan.runs:
        result = outcome.results.get(run)
        if result and result.get("status") == "done":
            path = plan.run_dir(run) / "training" / run.variant / f"seed-{run.seed}.parquet"
            logs.setdefault(run.variant, {})[run.seed] = pq.read_table(path)
    if len(logs) < 2:
        return None
    params = plan.params[plan.runs[0]]
    summary = training_summary(
        logs,
        window=params.report.smoothing_window,
        solved_window=params.agent.solved_window,
        solved_success_rate=params.agent.solved_success_rate,
    )
    claims = [c for c in CLAIMS if c.kind in ("training-better", "training-fastest")]
    results = check_claims({}, {}, summary, claims=claims, alpha=params.report.alpha)
    return [{"id": result.claim.claim_id, **result.to_dict()} for result in results]


def _figure_name(key: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", key) + ".png"


def _figures(outcome: SweepResult) -> list[Path]:
    """Per grid parameter: each summary metric against the parameter's values, one line per
    variant, with the 95% intervals over seeds."""
    plan = outcome.plan
    if not plan.grid_keys:
        return []
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from socnav_wm.io import atomic_path

    groups = _groups(outcome)
    metrics = _present_metrics(groups)
    paths = []
    (plan.out_dir / "figures").mkdir(parents=True, exist_ok=True)
    for index, key in enumerate(plan.grid_keys):
        values = plan.study.grid[key]
        numeric = all(isinstance(v, int | float) and not isinstance(v, bool) for v in values)
        fig, axes = plt.subplots(1, len(metrics), figsize=(3.2 * len(metrics), 3.0), squeeze=False)
        for variant in plan.study.variants:
            for axis, metric in zip(axes[0], metrics, strict=True):
                xs, means, lows, highs = [], [], [], []
                for position, value in enumerate(values):
                    vals = [
                        r["metrics"][metric]
                        for (v, point), results in groups.items()
                        if v == variant and point[index] == value
                        for r in results
                        if metric in r["metrics"]
                    ]
                    if not vals:
                        continue
                    mean, low, high = _interval(vals, metric)
                    xs.append(value if numeric else position)
                    means.append(mean)
                    lows.append(mean if math.isnan(low) else low)
                    highs.append(mean if math.isnan(high) else high)
                if xs:
                    errors = [
                        [m - lo for m, lo in zip(means, lows, strict=True)],
                        [h - m for m, h in zip(means, highs, strict=True)],
                    ]
                    axis.errorbar(xs, means, yerr=errors, marker="o", capsize=3, label=variant)
        for axis, metric in zip(axes[0], metrics, strict=True):
            axis.set_title(metric, fontsize=9)
            axis.set_xlabel(key, fontsize=8)
            if not numeric:
                axis.set_xticks(range(len(values)), [_format_value(v) for v in values])
            elif len(values) > 1 and min(values) > 0 and max(values) / min(values) >= 8:
                axis.set_xscale("log", base=2)
                axis.set_xticks(values, [str(v) for v in values])
        axes[0][0].legend(fontsize=7)
        fig.suptitle(f"study {plan.name}: mean and 95% interval over seeds", fontsize=10)
        fig.tight_layout()
        path = plan.out_dir / "figures" / _figure_name(key)
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format="png", dpi=90)
        plt.close(fig)
        paths.append(path)
    return paths


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
    if name not in params.studies:
        known = ", ".join(params.studies) or "none"
        raise ConfigError(f"--study: no study {name!r} in params.yaml (studies: {known})")
    return params.studies[name]


def describe(outcome: SweepResult) -> str:
    """One line: what the sweep did."""
    plan = outcome.plan
    done = len(outcome.results) - len(outcome.failed)
    return (
        f"sweep {plan.name}: {done}/{len(plan.runs)} runs done "
        f"({outcome.skipped} skipped as finished, {len(outcome.failed)} failed) in "
        f"{outcome.wall_s / 60:.1f} min; wrote {plan.out_dir / 'summary.md'}"
    )
