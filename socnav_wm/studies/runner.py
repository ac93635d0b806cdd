"""``socnav-wm sweep``'s runs as Ray tasks.

Each run is exactly ``socnav-wm train-agent --variant V --seed S --set KEY=VALUE …`` followed by
``socnav-wm evaluate --method V`` on that one agent (same code, same parameters: its weights are
bit for bit the serial command's), in a Ray task of one CPU and one torch thread. Ray starts
locally (one task per core) unless ``address`` names a running cluster (docs/cluster.md).

A finished run (:meth:`~socnav_wm.studies.plan.SweepPlan.finished`, or one another study
finished: :meth:`~socnav_wm.studies.plan.SweepPlan.adopt`) is skipped; an unfinished one resumes
from its checkpoint; a failed one is reported with its error and does not stop the others. Only
this module imports ray, and only inside :func:`run_sweep`.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import signal
import socket
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from socnav_wm.config import ConfigError, Params, params_dict
from socnav_wm.studies.plan import RESULT_FILE, RunSpec, SweepPlan, SweepResult, format_value
from socnav_wm.studies.summary import write_results

__all__ = ["RunJob", "describe", "execute_run", "run_sweep"]


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
    grid_tags.update({f"grid.{key}": format_value(value) for key, value in spec.values})
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


RAY_CONNECT_TIMEOUT_S = 10.0
"""How long ``sweep --address HOST:PORT`` waits for the cluster to answer (Ray itself would
retry for ever)."""


def _endpoint(address: str | None) -> tuple[str, int] | None:
    """``(host, port)`` of ``HOST:PORT`` or ``ray://HOST:PORT``; None for a local Ray,
    ``auto`` and whatever else Ray resolves itself."""
    if address is None or address in ("auto", "local"):
        return None
    rest = address.split("://", 1)[1] if "://" in address else address
    host, sep, port = rest.rpartition(":")
    if not sep or not port.isdigit():
        return None
    return host.strip("[]") or "127.0.0.1", int(port)


def check_reachable(address: str | None, timeout_s: float = RAY_CONNECT_TIMEOUT_S) -> None:
    """Fail in one line when nothing answers at a cluster ``address`` (``HOST:PORT``) within
    ``timeout_s``, before ``ray.init``, which would retry for ever.

    Raises:
        ConfigError: ``--address …: no Ray cluster answers there (…)``.
    """
    endpoint = _endpoint(address)
    if endpoint is None:
        return
    try:
        with socket.create_connection(endpoint, timeout=timeout_s):
            pass
    except OSError as exc:
        if isinstance(exc, ConnectionRefusedError):
            reason = "connection refused"
        elif isinstance(exc, TimeoutError):
            reason = f"no answer within {timeout_s:g} s"
        else:
            reason = (exc.strerror or _first_line(exc)).lower()
        raise ConfigError(f"--address {address}: no Ray cluster answers there ({reason})") from None


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
    connect_timeout_s: float = RAY_CONNECT_TIMEOUT_S,
) -> SweepResult:
    """Run ``plan``'s unfinished runs as Ray tasks, then write its results (see the module
    docstring). ``address``: a running Ray cluster (``auto``, ``HOST:PORT``, ``ray://…``); else a
    local Ray with ``cpus`` CPUs (default: every core). ``progress`` receives one line per
    change (default: standard error). ``connect_timeout_s``: how long a cluster at
    ``address`` may take to answer (:func:`check_reachable`)."""
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
        _run_tasks(ray, plan, todo, outcome, address, cpus, tracking, say, connect_timeout_s)
    outcome.wall_s = time.time() - started
    write_results(outcome)
    return outcome


class _TimeUp(BaseException):
    """:func:`_time_limit` ran out (a BaseException: Ray's retry loops catch Exception)."""


@contextlib.contextmanager
def _time_limit(seconds: float | None) -> Iterator[None]:
    """Raise :class:`_TimeUp` in the block after ``seconds`` (a real-time timer; checked
    between Ray's own blocking calls). No limit: ``None``, off the main thread, or Windows."""
    main = threading.current_thread() is threading.main_thread()
    if seconds is None or not main or not hasattr(signal, "setitimer"):
        yield
        return

    def time_up(signum: int, frame: Any) -> None:
        raise _TimeUp

    previous = signal.signal(signal.SIGALRM, time_up)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


@contextlib.contextmanager
def _caller_sigterm() -> Iterator[Callable[[], None]]:
    """Keep SIGTERM's meaning to the caller (the command line's: one line, exit status 143)
    while Ray runs: ``ray.init`` installs its own handler (exit 1 and a crash dump) and Ray's
    waits turn whatever a handler raises into a plain ``KeyboardInterrupt``. Yields the call
    that puts the caller's handler back (after ``ray.init``); the exception the caller's
    handler raised comes out of the block as itself."""
    main = threading.current_thread() is threading.main_thread()
    handler = signal.getsignal(signal.SIGTERM) if main else None
    if not callable(handler):
        yield lambda: None
        return
    raised: list[BaseException] = []

    def on_sigterm(signum: int, frame: Any) -> None:
        try:
            handler(signum, frame)
        except BaseException as exc:
            raised.append(exc)
            raise

    def restore() -> None:
        signal.signal(signal.SIGTERM, on_sigterm)

    restore()
    try:
        yield restore
    except KeyboardInterrupt as exc:
        if raised and exc is not raised[-1]:
            raise raised[-1] from None
        raise
    finally:
        signal.signal(signal.SIGTERM, handler)


def _run_tasks(
    ray: Any,
    plan: SweepPlan,
    todo: list[RunSpec],
    outcome: SweepResult,
    address: str | None,
    cpus: int | None,
    tracking: bool,
    say: Callable[[str], None],
    connect_timeout_s: float = RAY_CONNECT_TIMEOUT_S,
) -> None:
    from socnav_wm import tracking as track

    with _caller_sigterm() as restore_sigterm:
        started_here = not ray.is_initialized()
        if started_here:
            options: dict[str, Any] = {
                "include_dashboard": False,
                "logging_level": "ERROR",
                "log_to_driver": False,
            }
            if address is None:
                options.update(num_cpus=cpus or os.cpu_count() or 1, object_store_memory=200 << 20)
            check_reachable(address, connect_timeout_s)
            try:
                with _time_limit(connect_timeout_s if address is not None else None):
                    ray.init(address=address, **options)
            except _TimeUp:
                ray.shutdown()
                raise ConfigError(
                    f"--address {address}: no Ray cluster answered within {connect_timeout_s:g} s"
                ) from None
            except (ConnectionError, RuntimeError, ValueError) as exc:
                where = f"--address {address}" if address else "local Ray"
                raise ConfigError(f"{where}: Ray did not start ({_first_line(exc)})") from None
            finally:
                restore_sigterm()  # ray.init installed its own
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
                            error = _first_line(exc)
                            result = {"run": run.name, "status": "failed", "error": error}
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


def describe(outcome: SweepResult) -> str:
    """One line: what the sweep did."""
    plan = outcome.plan
    done = len(outcome.results) - len(outcome.failed)
    return (
        f"sweep {plan.name}: {done}/{len(plan.runs)} runs done "
        f"({outcome.skipped} skipped as finished, {len(outcome.failed)} failed) in "
        f"{outcome.wall_s / 60:.1f} min; wrote {plan.out_dir / 'summary.md'}"
    )
