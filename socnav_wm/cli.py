"""The ``socnav-wm`` command line: one thin command per pipeline stage, plus bench and render.

Commands parse options, load the validated configuration and call one library function. Heavy
modules (torch, mlflow, the simulator's compiled kernels) are imported inside the commands, so
``socnav-wm --help`` answers at once. Expected failures (bad params, a missing file, an
unreachable tracking server) end with one line on stderr and exit code 2, never a traceback.
"""

from __future__ import annotations

import functools
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer

# OpenMP threads that wait for work spin a little (1,000 iterations), then sleep. libgomp reads
# this when torch loads it, so it is set before any import of torch. Threads that spin for
# long burn the CPU a neighbour on a shared machine needs, and wait for it in turn. On two
# threads beside two busy processes (`socnav-wm bench contention --threads 2 --hogs 2`), the
# CPU-seconds over those alone were, for train-vae and train-agent: 1.72x and 1.92x with 10,000
# spins; 0.97x and 0.87x with none (OMP_WAIT_POLICY=PASSIVE alone), but train-agent then took
# 29.6 s alone instead of 18.0; 1.09x and 1.12x with this, 21.4 s alone (docs/performance.md).
# Results do not depend on it. Set either variable to override.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
os.environ.setdefault("GOMP_SPINCOUNT", "1000")

app = typer.Typer(
    name="socnav-wm",
    help="Predictive world models for social robot navigation: simulator, pipeline stages, "
    "benchmarks.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
bench_app = typer.Typer(
    help="Measure speed and memory of the hot paths and print a table.", no_args_is_help=True
)
app.add_typer(bench_app, name="bench")


class UserError(Exception):
    """A problem with the user's input, reported as one line."""


def _expected_errors() -> tuple[type[BaseException], ...]:
    # ConfigError, RolloutError and ModelFileError are ValueErrors; tracking.py imports mlflow
    # only when a run starts, so importing it here is cheap.
    from socnav_wm.tracking import TrackingError

    return (UserError, ValueError, FileNotFoundError, TrackingError)


class Terminated(KeyboardInterrupt):
    """SIGTERM (what ``kill``, make, CI and schedulers send), raised where the command runs.

    A KeyboardInterrupt, so that it unwinds like Ctrl-C: the stage's MLflow run ends KILLED
    and every atomic output being written is removed (nothing partial is published).
    """


def _raise_terminated(signum: int, frame: Any) -> None:
    raise Terminated(f"terminated by signal {signum}")


def friendly_errors(command: Callable[..., Any]) -> Callable[..., Any]:
    """Turn expected exceptions into ``error: <one line>`` and exit status 2; SIGTERM ends the
    command like Ctrl-C (exit status 143)."""

    @functools.wraps(command)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        import signal

        previous = signal.signal(signal.SIGTERM, _raise_terminated)
        try:
            return command(*args, **kwargs)
        except Terminated:
            typer.echo("error: terminated (SIGTERM); nothing was written", err=True)
            raise typer.Exit(code=128 + signal.SIGTERM) from None
        except MemoryError:
            typer.echo("error: out of memory; lower the sizes in params.yaml", err=True)
            raise typer.Exit(code=2) from None
        except _expected_errors() as exc:
            message = str(exc).strip().splitlines()[0] if str(exc).strip() else repr(exc)
            typer.echo(f"error: {message}", err=True)
            raise typer.Exit(code=2) from None
        finally:
            signal.signal(signal.SIGTERM, previous)

    return wrapper


def _print_table(rows: list[dict[str, Any]], title: str, formats: dict[str, str]) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title=title)
    columns = list(rows[0]) if rows else []
    for column in columns:
        table.add_column(column, justify="right" if column in formats else "left")
    for row in rows:
        table.add_row(
            *(format(row[c], formats[c]) if c in formats else str(row[c]) for c in columns)
        )
    Console().print(table)


# --------------------------------------------------------------------------- stage plumbing
ParamsOption = Annotated[
    Path, typer.Option("--params", help="Parameters file (YAML), relative to the working dir.")
]
SetOption = Annotated[
    list[str] | None,
    typer.Option("--set", help="Override a parameter: section.key=value (repeatable)."),
]
OverlayOption = Annotated[
    list[Path] | None,
    typer.Option(
        "--overlay",
        help="A YAML file merged over the params file, e.g. configs/paper.yaml (repeatable).",
    ),
]
NoTrackingOption = Annotated[
    bool, typer.Option("--no-tracking", help="Do not record an MLflow run.")
]
QuietOption = Annotated[bool, typer.Option("--quiet", help="No progress bar.")]
DeviceOption = Annotated[
    str | None,
    typer.Option(help="auto, cpu or cuda; overrides the stage's `device` parameter."),
]
ThreadsOption = Annotated[
    int | None,
    typer.Option(
        min=1,
        help="PyTorch CPU threads (default: OMP_NUM_THREADS if set, else the cores this "
        "process may use; never more than those cores).",
    ),
]


def available_cores() -> int:
    """The CPU cores this process may run on (its affinity mask where the OS has one)."""

    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


def _set_threads(threads: int | None) -> int:
    """Set PyTorch's intra-op thread count deliberately: ``threads``, else ``OMP_NUM_THREADS``,
    else every available core, capped at the available cores (more threads than cores spin
    against each other and against the neighbours on a shared machine). Returns the count.
    Results do not depend on it (tests/agents/test_training.py)."""

    cores = available_cores()
    if threads is None:
        env = os.environ.get("OMP_NUM_THREADS", "")
        threads = int(env) if env.isdigit() and int(env) > 0 else cores
    threads = min(threads, cores)
    import torch

    torch.set_num_threads(threads)
    return threads


def _load(
    params_path: Path,
    overlays: list[Path] | None,
    overrides: list[str] | None,
    device: tuple[str, str | None] | None = None,
) -> Any:
    """The validated params (before any heavy import), with ``--device`` applied.

    ``device`` is ``(section, --device option)``: the option replaces that section's ``device``
    before the params are logged, and the device is checked (CUDA asked for on a machine
    without it is an error before any run opens).
    """
    from socnav_wm.config import load_params

    params = load_params(params_path, overrides or [], overlays or [])
    if device is not None:
        section, option = device
        params = _with_device(params, section, option)
        from socnav_wm.worldmodel.training import resolve_device

        resolve_device(getattr(params, section).device)
    return params


def _check_device(device: str) -> str:
    if device not in ("auto", "cpu", "cuda"):
        raise UserError(f"--device: must be one of auto, cpu, cuda, got {device!r}")
    return device


def _with_device(params: Any, section: str, device: str | None) -> Any:
    if device is None:
        return params
    _check_device(device)
    updated = getattr(params, section).replace(device=device)
    return params.model_copy(update={section: updated})


# --------------------------------------------------------------------------- stages
@app.command()
@friendly_errors
def collect(
    params_path: ParamsOption = Path("params.yaml"),
    overrides: SetOption = None,
    overlays: OverlayOption = None,
    out: Annotated[Path, typer.Option(help="Directory of Parquet shards.")] = Path("data/rollouts"),
    metrics: Annotated[Path, typer.Option(help="Summary metrics (JSON).")] = Path(
        "metrics/collect.json"
    ),
    no_tracking: NoTrackingOption = False,
    quiet: QuietOption = False,
) -> None:
    """Random-policy rollouts of the simulator into Parquet shards (stage `collect`)."""
    params = _load(params_path, overlays, overrides)
    from socnav_wm.stages import collect as stage

    typer.echo(stage.run(params, out=out, metrics=metrics, tracking=not no_tracking, quiet=quiet))


@app.command("train-vae")
@friendly_errors
def train_vae_command(
    params_path: ParamsOption = Path("params.yaml"),
    overrides: SetOption = None,
    overlays: OverlayOption = None,
    rollouts: Annotated[Path, typer.Option(help="Directory of rollout shards.")] = Path(
        "data/rollouts"
    ),
    out: Annotated[Path, typer.Option(help="Model file to write.")] = Path("models/vae.pt"),
    metrics: Annotated[Path, typer.Option(help="Validation metrics (JSON).")] = Path(
        "metrics/vae.json"
    ),
    history: Annotated[Path, typer.Option(help="Per-epoch losses (JSON, for plots).")] = Path(
        "metrics/vae_history.json"
    ),
    device: DeviceOption = None,
    threads: ThreadsOption = None,
    no_tracking: NoTrackingOption = False,
    quiet: QuietOption = False,
) -> None:
    """Train the VAE (23-d observation → latent) on the rollouts (stage `train-vae`)."""
    params = _load(params_path, overlays, overrides, ("vae", device))
    _set_threads(threads)
    from socnav_wm.stages import train_vae as stage

    message = stage.run(
        params,
        rollouts=rollouts,
        out=out,
        metrics=metrics,
        history=history,
        tracking=not no_tracking,
        quiet=quiet,
    )
    typer.echo(message)


@app.command("train-lstm")
@friendly_errors
def train_lstm_command(
    params_path: ParamsOption = Path("params.yaml"),
    overrides: SetOption = None,
    overlays: OverlayOption = None,
    rollouts: Annotated[Path, typer.Option(help="Directory of rollout shards.")] = Path(
        "data/rollouts"
    ),
    vae: Annotated[Path, typer.Option(help="Trained VAE (frozen here).")] = Path("models/vae.pt"),
    out: Annotated[Path, typer.Option(help="Model file to write.")] = Path("models/lstm.pt"),
    metrics: Annotated[Path, typer.Option(help="Validation metrics (JSON).")] = Path(
        "metrics/lstm.json"
    ),
    history: Annotated[Path, typer.Option(help="Per-epoch losses (JSON, for plots).")] = Path(
        "metrics/lstm_history.json"
    ),
    device: DeviceOption = None,
    threads: ThreadsOption = None,
    no_tracking: NoTrackingOption = False,
    quiet: QuietOption = False,
) -> None:
    """Train the LSTM world model on VAE latents of the rollouts (stage `train-lstm`)."""
    params = _load(params_path, overlays, overrides, ("lstm", device))
    _set_threads(threads)
    from socnav_wm.stages import train_lstm as stage

    message = stage.run(
        params,
        rollouts=rollouts,
        vae=vae,
        out=out,
        metrics=metrics,
        history=history,
        tracking=not no_tracking,
        quiet=quiet,
    )
    typer.echo(message)


@app.command("train-agent")
@friendly_errors
def train_agent_command(
    variant: Annotated[str, typer.Option(help="Agent variant (see `agent` in params.yaml).")],
    seed: Annotated[int, typer.Option(min=0, help="Training seed.")] = 0,
    params_path: ParamsOption = Path("params.yaml"),
    overrides: SetOption = None,
    overlays: OverlayOption = None,
    vae: Annotated[Path, typer.Option(help="Frozen VAE.")] = Path("models/vae.pt"),
    lstm: Annotated[Path, typer.Option(help="Frozen LSTM.")] = Path("models/lstm.pt"),
    out_dir: Annotated[
        Path, typer.Option(help="Agents folder: writes {variant}/seed-{seed}.pt.")
    ] = Path("models/agents"),
    log_dir: Annotated[
        Path, typer.Option(help="Training logs: writes {variant}/seed-{seed}.parquet.")
    ] = Path("data/training"),
    metrics_dir: Annotated[
        Path, typer.Option(help="Summary metrics: writes {variant}/seed-{seed}.json.")
    ] = Path("metrics/agents"),
    checkpoint_dir: Annotated[
        Path, typer.Option(help="Resumable checkpoints (one file per distinct run).")
    ] = Path("checkpoints"),
    resume: Annotated[
        bool, typer.Option(help="Continue from this run's last checkpoint, if there is one.")
    ] = False,
    keep_checkpoint: Annotated[
        bool, typer.Option(help="Keep the checkpoint after the agent file is written.")
    ] = False,
    device: DeviceOption = None,
    threads: ThreadsOption = None,
    no_tracking: NoTrackingOption = False,
    quiet: QuietOption = False,
) -> None:
    """Train one Dueling DQN variant with one seed on the frozen world model (stage
    `train-agent`)."""
    from socnav_wm.agents.params import check_variant

    check_variant(variant)
    params = _load(params_path, overlays, overrides, ("agent", device))
    _set_threads(threads)
    from socnav_wm.stages import train_agent as stage

    message = stage.run(
        params,
        variant=variant,
        seed=seed,
        vae=vae,
        lstm=lstm,
        out_dir=out_dir,
        log_dir=log_dir,
        metrics_dir=metrics_dir,
        checkpoint_dir=checkpoint_dir,
        resume=resume,
        keep_checkpoint=keep_checkpoint,
        tracking=not no_tracking,
        quiet=quiet,
    )
    typer.echo(message)


# --------------------------------------------------------------------------- evaluation
@app.command()
@friendly_errors
def evaluate(
    method: Annotated[str, typer.Option(help="An agent variant, a baseline or a planner.")],
    params_path: ParamsOption = Path("params.yaml"),
    overrides: SetOption = None,
    overlays: OverlayOption = None,
    agents_dir: Annotated[
        Path, typer.Option(help="Agents folder: reads {variant}/seed-{seed}.pt.")
    ] = Path("models/agents"),
    out_dir: Annotated[
        Path, typer.Option(help="Writes {method}.parquet and {method}-trajectories.parquet.")
    ] = Path("data/eval"),
    metrics_dir: Annotated[Path, typer.Option(help="Writes {method}.json.")] = Path("metrics/eval"),
    planning_model: Annotated[
        Path | None,
        typer.Option(help="wm-mpc's planning model [default: models/planning/seed-0.pt]."),
    ] = None,
    vae: Annotated[
        Path | None, typer.Option(help="vae-lstm-mpc's VAE [default: models/vae.pt].")
    ] = None,
    lstm: Annotated[
        Path | None, typer.Option(help="vae-lstm-mpc's LSTM [default: models/lstm.pt].")
    ] = None,
    device: DeviceOption = None,
    threads: ThreadsOption = None,
    no_tracking: NoTrackingOption = False,
    quiet: QuietOption = False,
) -> None:
    """Run one method greedily on the test scenarios: every training seed of an agent
    (`experiment.seeds`), a baseline, or a planner (cv-mpc, wm-mpc, vae-lstm-mpc, oracle-mpc)
    (stages `evaluate`, `evaluate_baseline`, `evaluate_planner`, `evaluate_wm_mpc`,
    `evaluate_vae_lstm_mpc`)."""
    from socnav_wm.agents.params import METHOD_NAMES

    if method not in METHOD_NAMES:
        raise UserError(f"--method: unknown {method!r}; expected one of {', '.join(METHOD_NAMES)}")
    params = _load(params_path, overlays, overrides, ("eval", device))
    _set_threads(threads)
    from socnav_wm.stages import evaluate as stage

    message = stage.run(
        params,
        method=method,
        agents_dir=agents_dir,
        out_dir=out_dir,
        metrics_dir=metrics_dir,
        planner_files={
            role: path
            for role, path in (("planning_model", planning_model), ("vae", vae), ("lstm", lstm))
            if path is not None
        },
        tracking=not no_tracking,
        quiet=quiet,
    )
    typer.echo(message)


@app.command()
@friendly_errors
def report(
    params_path: ParamsOption = Path("params.yaml"),
    overrides: SetOption = None,
    overlays: OverlayOption = None,
    eval_dir: Annotated[Path, typer.Option(help="Evaluation files.")] = Path("data/eval"),
    training_dir: Annotated[Path, typer.Option(help="Training logs.")] = Path("data/training"),
    out_dir: Annotated[Path, typer.Option(help="Report folder.")] = Path("reports"),
    metrics: Annotated[Path, typer.Option(help="Machine-readable summary (JSON).")] = Path(
        "metrics/report.json"
    ),
    document: Annotated[
        list[Path] | None,
        typer.Option(help="Markdown file whose results block gets the table (repeatable)."),
    ] = None,
    no_tracking: NoTrackingOption = False,
) -> None:
    """Table, paired tests, Pareto set, figures and the paper's claims checked; the results
    table also goes into the results blocks of README.md and docs/evaluation.md (stage
    `report`), or of the --document files. A report of other evaluations (--eval-dir or
    --out-dir not the pipeline's) writes no block unless --document names one."""
    params = _load(params_path, overlays, overrides)
    from socnav_wm.stages import report as stage

    documents = tuple(document) if document is not None else None
    if documents is None and (eval_dir != Path("data/eval") or out_dir != Path("reports")):
        documents = ()  # the README's table is the pipeline's, not another set's
    message = stage.run(
        params,
        eval_dir=eval_dir,
        training_dir=training_dir,
        out_dir=out_dir,
        metrics=metrics,
        documents=documents,
        tracking=not no_tracking,
    )
    typer.echo(message)


@app.command()
@friendly_errors
def predict(
    params_path: ParamsOption = Path("params.yaml"),
    overrides: SetOption = None,
    overlays: OverlayOption = None,
    vae: Annotated[Path, typer.Option(help="The VAE file.")] = Path("models/vae.pt"),
    lstm: Annotated[Path, typer.Option(help="The LSTM file.")] = Path("models/lstm.pt"),
    agent: Annotated[
        Path | None,
        typer.Option(help="Agent file of the ε-greedy policy (default: dueling-dqn seed 0)."),
    ] = Path("models/agents/dueling-dqn/seed-0.pt"),
    planning_model: Annotated[
        list[Path] | None,
        typer.Option(
            help="A planning world model file (repeat: one per training seed; default: "
            "models/planning/seed-S.pt for each of planning_model.seeds)."
        ),
    ] = None,
    out: Annotated[Path, typer.Option(help="The errors (JSON).")] = Path("metrics/prediction.json"),
    figure: Annotated[Path, typer.Option(help="Error against k (PNG).")] = Path(
        "reports/prediction.png"
    ),
    no_tracking: NoTrackingOption = False,
    threads: ThreadsOption = None,
) -> None:
    """k-step prediction errors in metres of the world model (VAE + LSTM) and the planning world
    model's seeds beside copy-last, static humans and constant velocity (the robot's own motion
    exact), under the random policy and a trained agent's ε-greedy one, open loop with the true
    actions; the settings are params.yaml's `prediction` section."""
    params = _load(params_path, overlays, overrides)
    _set_threads(threads)
    from socnav_wm.evaluation.rendering import PREDICTION_KS
    from socnav_wm.stages import predict as stage
    from socnav_wm.worldmodel.prediction import error_table

    result = stage.run(
        params,
        vae=vae,
        lstm=lstm,
        agent=agent,
        planning_models=planning_model,
        out=out,
        figure=figure,
        tracking=not no_tracking,
    )
    for policy, errors in result["policies"].items():
        table = error_table(errors)
        formats = {c: ".3f" for c in table[0] if c not in ("k", "n")} if table else {}
        _print_table(table, f"{policy} policy: mean error (m) k steps ahead", {"n": "d", **formats})
        change = errors.get("goal_change")
        if change:
            rows = []
            for i, k in enumerate(errors["k"]):
                if k not in PREDICTION_KS:
                    continue
                row: dict[str, Any] = {"k": k, "new goal": change["changed_share"][i]}
                for name, values in change["predictors"].items():
                    if name in ("constant-velocity", "planning-model"):
                        row[f"{name}: kept"] = values["kept"][i]
                        row[f"{name}: new"] = values["changed"][i]
                rows.append(row)
            _print_table(
                rows,
                f"{policy} policy: humans' error (m) by whether they drew a new goal",
                {c: ".3f" for c in rows[0] if c != "k"} if rows else {},
            )
        versus = errors.get("planning_model")
        if versus:
            rows = [
                {"k": k, "difference": d, "low": ci[0], "high": ci[1], "verdict": v}
                for k, d, ci, v in zip(
                    errors["k"],
                    versus["difference"],
                    versus["difference_ci"],
                    versus["verdict"],
                    strict=True,
                )  # fmt: skip
                if k in PREDICTION_KS
            ]
            _print_table(
                rows,
                f"{policy} policy: planning model − constant velocity, humans (m), "
                f"{versus['seeds']} seeds",
                {"difference": "+.4f", "low": "+.4f", "high": "+.4f"},
            )
    typer.echo(f"wrote {out} and {figure}")


@app.command("train-planning-model")
@friendly_errors
def train_planning_model(
    params_path: ParamsOption = Path("params.yaml"),
    overrides: SetOption = None,
    overlays: OverlayOption = None,
    seed: Annotated[
        int, typer.Option(min=0, help="Training seed (one of planning_model.seeds).")
    ] = 0,
    rollouts: Annotated[Path, typer.Option(help="The rollouts (collect's output).")] = Path(
        "data/rollouts"
    ),
    out_dir: Annotated[Path, typer.Option(help="Where seed-N.pt is written.")] = Path(
        "models/planning"
    ),
    metrics_dir: Annotated[Path, typer.Option(help="Where seed-N.json is written.")] = Path(
        "metrics/planning"
    ),
    threads: ThreadsOption = None,
    no_tracking: NoTrackingOption = False,
    quiet: QuietOption = False,
) -> None:
    """Train the planning world model (socnav_wm/worldmodel/residual.py: constant velocity plus a
    learned correction of each human's velocity) on the rollouts (stage `train_planning_model`,
    params.yaml's planning_model). Its k-step errors are measured by `socnav-wm predict`."""
    params = _load(params_path, overlays, overrides)
    _set_threads(threads)
    from socnav_wm.stages import train_planning_model as stage

    message = stage.run(
        params,
        seed=seed,
        rollouts=rollouts,
        out_dir=out_dir,
        metrics_dir=metrics_dir,
        tracking=not no_tracking,
        quiet=quiet,
    )
    typer.echo(message)


@app.command()
@friendly_errors
def check(
    rerun: Annotated[Path, typer.Argument(help="metrics/eval of a rerun (another clone).")],
    committed: Annotated[Path, typer.Option(help="The committed evaluation metrics.")] = Path(
        "metrics/eval"
    ),
) -> None:
    """Compare a rerun's test metrics with the committed ones: each mean within the other's 95%
    interval (what reproduces across machines), or identical (same CPU, build and threads)."""
    from socnav_wm.evaluation.reproduce import compare_runs

    checks = compare_runs(committed, rerun)
    rows = [
        {
            "method": c.method,
            "metric": c.metric,
            "committed": f"{c.committed['mean']:.4g} [{c.committed['low']:.4g}, "
            f"{c.committed['high']:.4g}]",
            "rerun": f"{c.rerun['mean']:.4g} [{c.rerun['low']:.4g}, {c.rerun['high']:.4g}]",
            "verdict": "identical" if c.identical else "agrees" if c.agrees else "DIFFERS",
        }
        for c in checks
    ]
    _print_table(rows, f"socnav-wm check {rerun} against {committed}", {})
    differs = sum(not c.agrees for c in checks)
    typer.echo(f"{len(checks) - differs} of {len(checks)} agree within the 95% intervals")
    if differs:
        raise typer.Exit(code=1)


@app.command()
@friendly_errors
def deps(
    check: Annotated[
        list[Path] | None,
        typer.Option(
            help="Compare with this dvc.yaml (repeatable: dvc.yaml, studies/dvc.yaml); exit 1 "
            "if a stage's deps differ."
        ),
    ] = None,
    write: Annotated[
        list[Path] | None,
        typer.Option(help="Rewrite the source deps of this dvc.yaml's stages (repeatable)."),
    ] = None,
) -> None:
    """Each stage's source dependencies: the import closure of its module (what dvc.yaml and
    studies/dvc.yaml list)."""
    from socnav_wm.stages.deps import dvc_yaml_differences, stage_dependencies, write_dvc_yaml

    if write:
        for path in write:
            changed = write_dvc_yaml(path)
            typer.echo(f"{path}: {'updated' if changed else 'already up to date'}")
        return

    if check:
        problems = [line for path in check for line in dvc_yaml_differences(path)]
        for line in problems:
            typer.echo(line, err=True)
        if problems:
            raise typer.Exit(code=1)
        files = ", ".join(map(str, check))
        typer.echo(f"{files}: every stage lists exactly the sources it executes")
        return
    for stage, files in stage_dependencies().items():
        typer.echo(f"{stage}:")
        for path in files:
            typer.echo(f"  - {path}")


# --------------------------------------------------------------------------- render
@app.command()
@friendly_errors
def render(
    out: Annotated[Path, typer.Option(help="Animated GIF to write.")] = Path("episode.gif"),
    policy: Annotated[
        str,
        typer.Option(
            help="Robot policy: random, orca, sfm, a planner (cv-mpc, wm-mpc, vae-lstm-mpc, "
            "oracle-mpc: their models at the pipeline's paths), a variant (its seed-0 agent in "
            "--agents-dir) or the path of an agent file."
        ),
    ] = "random",
    scenario: Annotated[
        list[int] | None, typer.Option(min=0, help="Scenario ids to show (repeatable).")
    ] = None,
    episodes: Annotated[
        int, typer.Option(min=1, help="Without --scenario: scenarios 0..episodes-1.")
    ] = 3,
    seed: Annotated[int, typer.Option(min=0, help="Scenario seed.")] = 0,
    human_policy: Annotated[str, typer.Option(help="Human motion: mixed, sfm or orca.")] = "mixed",
    agents_dir: Annotated[Path, typer.Option(help="Agents folder for a variant name.")] = Path(
        "models/agents"
    ),
    params_path: ParamsOption = Path("params.yaml"),
    fps: Annotated[float, typer.Option(min=0.5, help="Frames per second.")] = 8.0,
    size: Annotated[int, typer.Option(min=64, help="Frame side in pixels.")] = 480,
) -> None:
    """Render episodes of any robot policy (random, a baseline, a planner, a trained agent) in
    the simulator as an animated GIF, on chosen scenarios."""
    from socnav_wm.agents.params import BASELINE_NAMES, PLANNER_NAMES, VARIANT_NAMES

    as_file = Path(policy)
    named = ("random", *BASELINE_NAMES, *PLANNER_NAMES, *VARIANT_NAMES)
    if policy not in named and as_file.suffix != ".pt":
        choices = ", ".join(named)
        raise UserError(f"--policy: unknown {policy!r}; expected {choices} or an agent file (.pt)")
    import numpy as np

    from socnav_wm.config import Params
    from socnav_wm.env.render import write_gif
    from socnav_wm.env.rollout import episode_frames, random_policy, run_episodes

    config = _load(params_path, None, None) if params_path.exists() else Params()
    params = config.env.replace(human_policy=human_policy)
    ids = np.asarray(scenario if scenario else range(episodes), dtype=np.int64)
    if policy == "random":
        runs = run_episodes(params, random_policy(seed), seed, ids)
    elif policy in BASELINE_NAMES:
        from socnav_wm.agents.baselines import make_baseline

        overrides = getattr(config.baselines, policy).model_dump()
        baseline = make_baseline(policy, **overrides)
        act = lambda sim: baseline.act(sim.state, sim.params)  # noqa: E731
        runs = run_episodes(params, act, seed, ids, reads_simulator=True)
    elif policy in PLANNER_NAMES:
        from socnav_wm.planning.methods import planner_policy

        act, reads_simulator = planner_policy(policy, params, config.planning)
        runs = run_episodes(params, act, seed, ids, reads_simulator=reads_simulator)
    else:
        from socnav_wm.agents.agent_file import greedy_episodes, load_agent

        path = agents_dir / policy / "seed-0.pt" if policy in VARIANT_NAMES else as_file
        runs = greedy_episodes(load_agent(path), params, seed=seed, scenario_ids=ids)
    frames = []
    for episode in runs:
        frames += episode_frames(episode, params, label=policy if len(policy) < 24 else "agent",
                                 size=size)  # fmt: skip
    write_gif(frames, out, fps=fps)
    outcomes = ", ".join(
        "success" if e.success else f"{e.collision} collision" if e.collision else "timeout"
        for e in runs
    )
    typer.echo(f"wrote {out} ({len(frames)} frames; {outcomes})")


@app.command()
@friendly_errors
def sweep(
    study: Annotated[
        str | None,
        typer.Option(help="A study of params.yaml's `studies:` (its variants, seeds and grid)."),
    ] = None,
    variants: Annotated[
        str | None,
        typer.Option(help="Comma-separated variants (replace the study's), e.g. 2stepahead,maspm."),
    ] = None,
    seeds: Annotated[
        str | None, typer.Option(help="Training seeds (replace the study's): 0-4 or 0,2,7.")
    ] = None,
    grid: Annotated[
        list[str] | None,
        typer.Option(
            help="A parameter and its values, KEY=V1,V2,… (repeatable; replaces the study's grid)."
        ),
    ] = None,
    name: Annotated[
        str | None, typer.Option(help="The sweep's name (default: the study's); names its folders.")
    ] = None,
    params_path: ParamsOption = Path("params.yaml"),
    overrides: SetOption = None,
    overlays: OverlayOption = None,
    address: Annotated[
        str | None,
        typer.Option(help="A running Ray cluster (auto, HOST:PORT); default: Ray on this machine."),
    ] = None,
    cpus: Annotated[
        int | None, typer.Option(min=1, help="Local Ray's CPUs: runs at once (default: cores).")
    ] = None,
    vae: Annotated[Path, typer.Option(help="Frozen VAE.")] = Path("models/vae.pt"),
    lstm: Annotated[Path, typer.Option(help="Frozen LSTM.")] = Path("models/lstm.pt"),
    runs_dir: Annotated[
        Path | None,
        typer.Option(help="Every run's files and checkpoints (default: data/studies/NAME)."),
    ] = None,
    out_dir: Annotated[
        Path | None,
        typer.Option(help="results.parquet, summary.md, figures (default: reports/studies/NAME)."),
    ] = None,
    no_tracking: NoTrackingOption = False,
) -> None:
    """Train and evaluate a grid of agent runs (variants × seeds × parameter values) as Ray tasks,
    each exactly `train-agent --set …` then `evaluate`; finished runs are skipped, unfinished ones
    resume from their checkpoints, a failed one does not stop the others (docs/cluster.md)."""
    params = _load(params_path, overlays, overrides)
    from socnav_wm import sweep as sweeping

    base = sweeping.named_study(params, study) if study is not None else None
    chosen = sweeping.study_from_options(base, variants, seeds, grid or [])
    sweep_name = name or study
    if sweep_name is None:
        raise UserError("--name: required without --study")
    plan = sweeping.plan_sweep(
        sweep_name,
        chosen,
        params_path=params_path,
        overlays=overlays or [],
        overrides=overrides or [],
        runs_dir=runs_dir,
        out_dir=out_dir,
        vae=vae,
        lstm=lstm,
    )
    outcome = sweeping.run_sweep(plan, address=address, cpus=cpus, tracking=not no_tracking)
    typer.echo(sweeping.describe(outcome))
    if outcome.failed:
        first = outcome.failed[0]
        raise UserError(
            f"{len(outcome.failed)} of {len(plan.runs)} runs failed (first: {first['run']}: "
            f"{first.get('error', '')}); rerun the same command to retry them"
        )


@app.command("study-claims")
@friendly_errors
def study_claims(
    report_claims: Annotated[
        Path, typer.Option(help="The report's claims (stage `report`).")
    ] = Path("reports/claims.json"),
    studies_dir: Annotated[
        Path, typer.Option(help="The studies' reports (each study's claims.json).")
    ] = Path("reports/studies"),
    document: Annotated[
        list[Path] | None,
        typer.Option(help="Markdown file whose claims block gets the table (repeatable)."),
    ] = None,
    no_tracking: NoTrackingOption = False,
) -> None:
    """The paper's claims, each decided by the strongest evidence present: the seeds study's
    five seeds for the training claims, the horizon study for the look-ahead claim, the report
    for the rest (stage `study_claims` of studies/dvc.yaml)."""
    from socnav_wm.stages import study_claims as stage

    message = stage.run(
        report_claims=report_claims,
        studies_dir=studies_dir,
        documents=tuple(document) if document is not None else (Path("docs/studies.md"),),
        tracking=not no_tracking,
    )
    typer.echo(message)


# --------------------------------------------------------------------------- bench
def _print_machine(torch_build: bool = False) -> None:
    """The machine a benchmark ran on, printed under its table (as MLflow records it), with the
    torch build for the benchmarks that run torch."""
    if torch_build:
        import torch  # noqa: F401  (machine_tags describes torch once it is imported)
    from socnav_wm.tracking import machine_tags

    tags = machine_tags()
    line = f"machine: {tags['machine.cpu']}, {tags['machine.cores']} cores"
    if torch_build:
        line += f", torch {tags['machine.torch']} ({tags.get('machine.torch_blas', 'unknown')})"
    typer.echo(line)


@bench_app.command("env")
@friendly_errors
def bench_env_command(
    batch: Annotated[
        list[int] | None, typer.Option(help="Batch sizes (repeatable).", min=1)
    ] = None,
    humans: Annotated[
        list[str] | None, typer.Option(help="Human policies: sfm, orca, mixed (repeatable).")
    ] = None,
    seconds: Annotated[float, typer.Option(min=0.1, help="Timing budget per row (s).")] = 2.0,
) -> None:
    """Env-steps/s and peak memory of the simulator, random actions, one core."""
    from socnav_wm.bench import ENV_BATCH_SIZES, ENV_POLICIES, bench_env, one_core

    policies = tuple(humans or ENV_POLICIES)
    for policy in policies:
        if policy not in ENV_POLICIES:
            raise UserError(f"--humans: must be one of {', '.join(ENV_POLICIES)}, got {policy!r}")
    with one_core() as where:
        rows = bench_env(tuple(batch or ENV_BATCH_SIZES), policies, seconds)
    _print_table(
        rows,
        f"socnav-wm bench env ({where}, one thread, {seconds:g} CPU-s per row)",
        {"steps_per_cpu_s": ",.0f", "peak_mb": ".1f"},
    )
    _print_machine()


@bench_app.command("collect")
@friendly_errors
def bench_collect_command(
    episodes: Annotated[int, typer.Option(min=1, help="Episodes per row.")] = 2000,
    num_envs: Annotated[
        list[int] | None, typer.Option(help="Batch sizes (repeatable).", min=1)
    ] = None,
) -> None:
    """Env-steps/s of the collect stage end to end, Parquet writing included, one core."""
    from socnav_wm.bench import bench_collect, one_core

    with one_core() as where:
        rows = bench_collect(episodes, tuple(num_envs or (256, 512)))
    _print_table(
        rows,
        f"socnav-wm bench collect ({where})",
        {"cpu_seconds": ".2f", "steps_per_cpu_s": ",.0f", "parquet_mb": ".1f"},
    )
    _print_machine()


@bench_app.command("train")
@friendly_errors
def bench_train_command(
    variant: Annotated[
        list[str] | None, typer.Option(help="Variants (repeatable; default: all five).")
    ] = None,
    params_path: ParamsOption = Path("params.yaml"),
    overrides: SetOption = None,
    overlays: OverlayOption = None,
    seconds: Annotated[float, typer.Option(min=0.1, help="Timing budget per rate (s).")] = 3.0,
    device: DeviceOption = None,
    threads: ThreadsOption = None,
) -> None:
    """Env-steps/s (act + simulate + world-model features + store) and gradient updates/s of
    the DQN learner, per variant, with the `agent` and `env` sections of the params file (e.g.
    `--set agent.num_envs=64`) and a random world model of the `vae`/`lstm` sections' sizes."""
    from socnav_wm.agents.params import VARIANT_NAMES, check_variant
    from socnav_wm.bench import bench_train
    from socnav_wm.worldmodel.training import resolve_device

    names = [check_variant(v) for v in variant or VARIANT_NAMES]
    params = _load(params_path, overlays, overrides, ("agent", device))
    _set_threads(threads)
    agent = params.agent
    import torch

    rows = []
    for name in names:
        r = bench_train(
            name,
            params=agent,
            env_params=params.env,
            seconds=seconds,
            latent_dim=params.vae.latent_dim,
            vae_hidden_dim=params.vae.hidden_dim,
            lstm_hidden_dim=params.lstm.hidden_dim,
        )
        rows.append(
            {
                "variant": name,
                "features": r["feature_dim"],
                "envs": r["num_envs"],
                "batch": r["batch_size"],
                "env_steps_per_cpu_s": r["env_steps_per_cpu_s"],
                "updates_per_cpu_s": r["updates_per_cpu_s"],
            }
        )
    _print_table(
        rows,
        f"socnav-wm bench train ({params_path}, {resolve_device(agent.device)}, "
        f"{torch.get_num_threads()} torch threads, "
        f"decode_latents {agent.resolved(names[0]).decode_latents}, "
        f"per CPU-second of the process, {seconds:g} CPU-s per rate)",
        {
            "features": "d",
            "envs": "d",
            "batch": "d",
            "env_steps_per_cpu_s": ",.0f",
            "updates_per_cpu_s": ",.0f",
        },
    )
    _print_machine(torch_build=True)


@bench_app.command("plan")
@friendly_errors
def bench_plan_command(
    method: Annotated[
        list[str] | None,
        typer.Option(help="Planners (repeatable) [default: every planner whose models exist]."),
    ] = None,
    batch: Annotated[
        list[int] | None, typer.Option(help="Episodes planned together (repeatable).", min=1)
    ] = None,
    params_path: ParamsOption = Path("params.yaml"),
    overrides: SetOption = None,
    seconds: Annotated[float, typer.Option(min=0.1, help="Timing budget per row (CPU-s).")] = 2.0,
) -> None:
    """Decisions per CPU-second of each planner, one core and one torch thread, at the shipped
    batch (`eval.batch_size`) and at 1, 64 and 512 episodes planned together."""
    from socnav_wm.bench import PLAN_BATCH_SIZES, bench_plan, one_core
    from socnav_wm.planning.methods import model_files
    from socnav_wm.planning.params import PLANNER_NAMES

    config = _load(params_path, None, overrides) if params_path.exists() else None
    if config is None:
        from socnav_wm.config import Params

        config = Params()
    for name in method or ():
        if name not in PLANNER_NAMES:
            raise UserError(
                f"--method: unknown {name!r}; expected one of {', '.join(PLANNER_NAMES)}"
            )
    methods = list(method or PLANNER_NAMES)
    if not method:  # by default, skip the learned planners whose models are not there
        for name in list(methods):
            try:
                model_files(name)
            except FileNotFoundError as exc:
                typer.echo(f"skipped {name}: {exc}")
                methods.remove(name)
    sizes = tuple(batch or sorted({config.eval.batch_size, *PLAN_BATCH_SIZES}))
    _set_threads(1)
    with one_core() as where:
        rows = bench_plan(
            tuple(methods), sizes, env_params=config.env, planning=config.planning,
            seconds=seconds,
        )  # fmt: skip
    _print_table(
        rows,
        f"socnav-wm bench plan ({where}, one thread, {seconds:g} CPU-s per row; futures: "
        "prefixes x continuations, each imagined horizon steps)",
        {"decisions_per_cpu_s": ",.1f", "cpu_ms_per_decision": ".2f"},
    )


@bench_app.command("contention")
@friendly_errors
def bench_contention_command(
    threads: Annotated[
        list[int] | None,
        typer.Option(help="Torch threads of the stage (repeatable; default 1 and all).", min=1),
    ] = None,
    hogs: Annotated[
        int | None, typer.Option(help="Busy processes beside it (default: one per core).", min=1)
    ] = None,
    repeats: Annotated[int, typer.Option(min=1, help="Runs per cell; the fastest counts.")] = 1,
    stage: Annotated[
        list[str] | None,
        typer.Option(
            help="A torch stage (repeatable): train-vae, train-lstm, train-agent, "
            "train-planning-model (default: all four)."
        ),
    ] = None,
) -> None:
    """CPU-seconds of each torch stage alone and beside busy processes (`yes`), per thread
    count: how much a shared machine inflates a stage's work."""
    from socnav_wm.bench import CONTENTION_STAGES, bench_contention

    cores = available_cores()
    stages = tuple(stage or CONTENTION_STAGES)
    rows = bench_contention(
        tuple(threads or sorted({1, cores})), hogs or cores, repeats, stages=stages
    )
    _print_table(
        rows,
        f"socnav-wm bench contention ({cores} cores; CPU-seconds of the stage process, "
        "user + system, every thread)",
        {
            "threads": "d",
            "hogs": "d",
            "cpu_s_alone": ".1f",
            "cpu_s_shared": ".1f",
            "ratio": ".2f",
            "wall_s_alone": ".1f",
            "wall_s_shared": ".1f",
        },
    )
    _print_machine(torch_build=True)


def main() -> None:  # pragma: no cover - console entry point
    app()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(app())
