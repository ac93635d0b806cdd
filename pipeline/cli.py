"""The ``socnav-wm`` command line: one thin command per pipeline stage, plus bench and render.

Commands parse options, load the validated configuration and call one library function. Heavy
modules (torch, mlflow, the simulator's compiled kernels) are imported inside the commands, so
``socnav-wm --help`` answers at once. Expected failures (bad params, a missing file, an
unreachable tracking server) end with one line on stderr and exit code 2, never a traceback.
"""

from __future__ import annotations

import dataclasses
import functools
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any

import typer

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
    from pipeline.tracking import TrackingError

    return (UserError, ValueError, FileNotFoundError, TrackingError)


def friendly_errors(command: Callable[..., Any]) -> Callable[..., Any]:
    """Turn expected exceptions into ``error: <one line>`` and exit status 2."""

    @functools.wraps(command)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return command(*args, **kwargs)
        except _expected_errors() as exc:
            message = str(exc).strip().splitlines()[0] if str(exc).strip() else repr(exc)
            typer.echo(f"error: {message}", err=True)
            raise typer.Exit(code=2) from None

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
NoTrackingOption = Annotated[
    bool, typer.Option("--no-tracking", help="Do not record an MLflow run.")
]
QuietOption = Annotated[bool, typer.Option("--quiet", help="No progress bar.")]
DeviceOption = Annotated[
    str | None,
    typer.Option(help="auto, cpu or cuda; overrides the stage's `device` parameter."),
]


@contextmanager
def _stage(
    name: str,
    params_path: Path,
    overrides: list[str] | None,
    no_tracking: bool,
    sections: tuple,
    device: tuple[str, str | None] | None = None,
) -> Iterator[tuple[Any, Any]]:
    """Load and validate the params, then open the stage's MLflow run (checked before work).

    ``device`` is ``(section, --device option)``: the option replaces that section's ``device``
    before the params are logged, and the device is checked (CUDA asked for on a machine
    without it is an error before any run opens).
    """
    from pipeline.config import load_params, params_dict
    from pipeline.tracking import stage_run
    from pipeline.worldmodel.training import resolve_device

    params = load_params(params_path, overrides or [])
    if device is not None:
        section, option = device
        params = _with_device(params, section, option)
        resolve_device(getattr(params, section).device)
    logged = {key: value for key, value in params_dict(params).items() if key in sections}
    with stage_run(name, logged, enabled=not no_tracking) as run:
        yield params, run


def _check_device(device: str) -> str:
    if device not in ("auto", "cpu", "cuda"):
        raise UserError(f"--device: must be one of auto, cpu, cuda, got {device!r}")
    return device


def _with_device(params: Any, section: str, device: str | None) -> Any:
    if device is None:
        return params
    _check_device(device)
    current = getattr(params, section)
    if dataclasses.is_dataclass(current):  # the agent section is a stdlib dataclass
        updated = dataclasses.replace(current, device=device)
    else:
        updated = current.model_copy(update={"device": device})
    return params.model_copy(update={section: updated})


def _config_path(output: Path) -> Path:
    """Where a stage saves its resolved configuration: beside its main output."""
    return (
        output.with_name(output.stem + ".params.yaml") if output.suffix else output / "params.yaml"
    )


# --------------------------------------------------------------------------- stages
@app.command()
@friendly_errors
def collect(
    params_path: ParamsOption = Path("params.yaml"),
    overrides: SetOption = None,
    out: Annotated[Path, typer.Option(help="Directory of Parquet shards.")] = Path("data/rollouts"),
    metrics: Annotated[Path, typer.Option(help="Summary metrics (JSON).")] = Path(
        "metrics/collect.json"
    ),
    no_tracking: NoTrackingOption = False,
    quiet: QuietOption = False,
) -> None:
    """Random-policy rollouts of the simulator into Parquet shards (stage `collect`)."""
    from pipeline.config import save_resolved
    from pipeline.data.collect import collect_rollouts
    from pipeline.io import atomic_path, write_json_atomic
    from pipeline.progress import progress

    stage = _stage("collect", params_path, overrides, no_tracking, ("seed", "env", "collect"))
    with stage as (params, run):
        c = params.collect
        # The whole directory appears at once: a killed run never leaves a partial dataset.
        with (
            atomic_path(out) as staging,
            progress(c.episodes, "collect", quiet=quiet, unit="episodes") as bar,
        ):
            summary = collect_rollouts(
                params.env,
                episodes=c.episodes,
                num_envs=c.num_envs,
                seed=params.seed,
                out_dir=staging,
                max_rows_per_shard=c.max_rows_per_shard,
                on_episodes=bar.advance,
            )
            save_resolved(params, staging / "params.yaml")
        write_json_atomic(metrics, summary.as_metrics())
        run.log_metrics(summary.as_metrics())
        run.log_artifact(out / "params.yaml")
    typer.echo(
        f"wrote {summary.episodes} episodes, {summary.steps} steps in {len(summary.shards)} "
        f"shard(s) to {out} ({summary.steps / summary.seconds:,.0f} steps/s)"
    )


def _world_model_outputs(
    run: Any,
    params: Any,
    model: Path,
    metrics: Path,
    history: Path,
    summary: dict[str, float],
    epochs: list[dict[str, float]],
) -> None:
    """What a world-model stage writes beside its model file, and logs with it to MLflow: the
    resolved params, the metrics and the per-epoch history (JSON), the final metrics (without
    the per-epoch series, so their curves stay clean)."""
    from pipeline.config import save_resolved
    from pipeline.io import write_json_atomic

    save_resolved(params, _config_path(model))
    write_json_atomic(metrics, summary)
    write_json_atomic(history, epochs)
    per_epoch = set().union(*(row.keys() for row in epochs))
    run.log_metrics({key: value for key, value in summary.items() if key not in per_epoch})
    run.log_artifact(model)
    run.log_artifact(_config_path(model))


def _epoch_logger(run: Any, bar: Any) -> Callable[[int, dict[str, float]], None]:
    def on_epoch(epoch: int, values: dict[str, float]) -> None:
        run.log_metrics(values, step=epoch)
        bar.advance()
        bar.set_postfix(val_loss=values.get("val_loss"))

    return on_epoch


@app.command("train-vae")
@friendly_errors
def train_vae_command(
    params_path: ParamsOption = Path("params.yaml"),
    overrides: SetOption = None,
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
    no_tracking: NoTrackingOption = False,
    quiet: QuietOption = False,
) -> None:
    """Train the VAE (23-d observation → latent) on the rollouts (stage `train-vae`)."""
    from pipeline.progress import progress
    from pipeline.worldmodel.fit import fit_vae
    from pipeline.worldmodel.training import save_vae

    stage = _stage(
        "train-vae", params_path, overrides, no_tracking, ("seed", "vae"), ("vae", device)
    )
    with stage as (params, run):
        with progress(params.vae.max_epochs, "train-vae", quiet=quiet, unit="epochs") as bar:
            fitted = fit_vae(
                rollouts,
                params.vae,
                seed=params.seed,
                device=params.vae.device,
                on_epoch=_epoch_logger(run, bar),
            )
        result = fitted.result
        summary = {**result.metrics, **fitted.data}
        save_vae(out, result, extra={"metrics": summary, "params": params.vae.model_dump()})
        _world_model_outputs(run, params, out, metrics, history, summary, result.history)
        run.log_figure(fitted.figure(), "figures/reconstruction.png")
    typer.echo(
        f"wrote {out}: validation reconstruction MSE {result.metrics['val_recon_mse']:.4f} "
        f"vs {result.metrics['baseline_mse']:.4f} for the training mean"
    )


@app.command("train-lstm")
@friendly_errors
def train_lstm_command(
    params_path: ParamsOption = Path("params.yaml"),
    overrides: SetOption = None,
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
    no_tracking: NoTrackingOption = False,
    quiet: QuietOption = False,
) -> None:
    """Train the LSTM world model on VAE latents of the rollouts (stage `train-lstm`)."""
    from pipeline.progress import progress
    from pipeline.worldmodel.fit import fit_lstm
    from pipeline.worldmodel.training import save_lstm

    stage = _stage(
        "train-lstm", params_path, overrides, no_tracking, ("seed", "lstm"), ("lstm", device)
    )
    with stage as (params, run):
        with progress(params.lstm.max_epochs, "train-lstm", quiet=quiet, unit="epochs") as bar:
            fitted = fit_lstm(
                rollouts,
                vae,
                params.lstm,
                seed=params.seed,
                device=params.lstm.device,
                on_epoch=_epoch_logger(run, bar),
            )
        result = fitted.result
        summary = {**result.metrics, **fitted.metrics, **fitted.data}
        save_lstm(out, result, extra={"metrics": summary, "params": params.lstm.model_dump()})
        _world_model_outputs(run, params, out, metrics, history, summary, result.history)
        run.log_figure(fitted.figure(), "figures/latent_predictions.png")
    m = fitted.metrics
    typer.echo(
        f"wrote {out}: 1-step latent MSE {m['one_step_mse']:.4g} "
        f"(copy-last {m['copy_last_one_step_mse']:.4g}); 2-step {m['two_step_mse']:.4g} "
        f"(copy-last {m['copy_last_two_step_mse']:.4g})"
    )


# --------------------------------------------------------------------------- agents
def _training_logger(run: Any, every: int, window: int) -> Callable[[list[dict[str, Any]]], None]:
    """MLflow curves of a training run: means over the last ``window`` episodes, every
    ``every`` episodes (the per-episode rows go to the Parquet log)."""
    import numpy as np

    history: list[dict[str, Any]] = []

    def on_episodes(rows: list[dict[str, Any]]) -> None:
        before = len(history)
        history.extend(rows)
        if len(history) // every == before // every:
            return
        recent = history[-window:]
        run.log_metrics(
            {
                "return": float(np.mean([r["return"] for r in recent])),
                "success_rate": float(np.mean([r["success"] for r in recent])),
                "collision_rate": float(np.mean([r["collision"] for r in recent])),
                "timeout_rate": float(np.mean([r["timeout"] for r in recent])),
                "length": float(np.mean([r["length"] for r in recent])),
                "epsilon": float(recent[-1]["epsilon"]),
            },
            step=len(history),
        )

    return on_episodes


@app.command("train-agent")
@friendly_errors
def train_agent_command(
    variant: Annotated[str, typer.Option(help="Agent variant (see `agent` in params.yaml).")],
    seed: Annotated[int, typer.Option(min=0, help="Training seed.")] = 0,
    params_path: ParamsOption = Path("params.yaml"),
    overrides: SetOption = None,
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
    no_tracking: NoTrackingOption = False,
    quiet: QuietOption = False,
) -> None:
    """Train one Dueling DQN variant with one seed on the frozen world model (stage
    `train-agent`)."""
    from pipeline.agents.params import check_variant

    check_variant(variant)
    import numpy as np

    from pipeline.agents.dqn import (
        agent_from_result,
        checkpoint_file,
        evaluate_agent,
        run_identity,
        save_agent,
        train_agent,
        training_metrics,
        validation_seed,
        write_training_log,
    )
    from pipeline.config import save_resolved
    from pipeline.io import write_json_atomic

    name = f"{variant}/seed-{seed}"
    stage = _stage(
        f"train-agent/{name}",
        params_path,
        overrides,
        no_tracking,
        ("env", "agent"),
        ("agent", device),
    )
    with stage as (params, run):
        p = params.agent
        identity = run_identity(variant, p, params.env, seed, vae, lstm)
        checkpoint = checkpoint_file(checkpoint_dir, identity)
        if resume and checkpoint.exists():
            typer.echo(f"resuming from {checkpoint}", err=True)
        run.set_tag("variant", variant)
        run.set_tag("training_seed", seed)
        result = train_agent(
            variant,
            p,
            params.env,
            vae,
            lstm,
            seed=seed,
            checkpoint_path=checkpoint,
            resume=resume,
            on_episodes=_training_logger(
                run, every=max(1, min(50, p.episodes // 10)), window=p.solved_window
            ),
            quiet=quiet,
        )
        greedy = evaluate_agent(
            agent_from_result(result),
            params.env,
            seed=validation_seed(seed),
            scenario_ids=np.arange(p.eval_episodes),
        )
        summary = training_metrics(result, greedy)
        out = out_dir / variant / f"seed-{seed}.pt"
        save_agent(out, result, extra={"metrics": summary, "selection": result.selection})
        save_resolved(params, _config_path(out))
        write_training_log(result.episodes, log_dir / variant / f"seed-{seed}.parquet")
        write_json_atomic(metrics_dir / variant / f"seed-{seed}.json", summary)
        run.log_metrics({k: float(v) for k, v in summary.items() if v is not None})
        for selection_run in result.selection:
            run.log_metrics(
                {"selection_success_rate": selection_run["success_rate"]},
                step=selection_run["episode"],
            )
        run.log_artifact(out)
        run.log_artifact(_config_path(out))
        if not keep_checkpoint:
            checkpoint.unlink(missing_ok=True)
    solved = summary["episodes_to_solve"]
    selected = ""
    if result.selected_episode is not None:
        selected = (
            f" (weights of episode {result.selected_episode}, best of {len(result.selection)} "
            "greedy runs on the selection scenarios)"
        )
    typer.echo(
        f"wrote {out}: greedy success {summary['greedy_success_rate']:.1%} on "
        f"{len(greedy)} validation scenarios{selected}; solved at episode {solved or 'never'}; "
        f"{result.env_steps:,} env steps, {result.updates:,} updates in "
        f"{result.wall_time / 60:.1f} min"
    )


# --------------------------------------------------------------------------- evaluation
@app.command()
@friendly_errors
def evaluate(
    method: Annotated[str, typer.Option(help="An agent variant, orca or sfm.")],
    params_path: ParamsOption = Path("params.yaml"),
    overrides: SetOption = None,
    agents_dir: Annotated[
        Path, typer.Option(help="Agents folder: reads {variant}/seed-{seed}.pt.")
    ] = Path("models/agents"),
    out_dir: Annotated[
        Path, typer.Option(help="Writes {method}.parquet and {method}-trajectories.parquet.")
    ] = Path("data/eval"),
    metrics_dir: Annotated[Path, typer.Option(help="Writes {method}.json.")] = Path("metrics/eval"),
    device: DeviceOption = None,
    no_tracking: NoTrackingOption = False,
    quiet: QuietOption = False,
) -> None:
    """Run one method greedily on the test scenarios, every training seed of an agent
    (`experiment.seeds`) (stage `evaluate`)."""
    from pipeline.evaluation.evaluate import (
        AGENT_METHODS,
        BASELINE_METHODS,
        METHODS,
        evaluate_method,
        evaluation_metrics,
        write_evaluation,
    )

    if method not in METHODS:
        raise UserError(f"--method: unknown {method!r}; expected one of {', '.join(METHODS)}")
    sections = ("env", "eval", "experiment", "baselines")
    stage = _stage(
        f"evaluate/{method}", params_path, overrides, no_tracking, sections, ("eval", device)
    )
    with stage as (params, run):
        agent_paths = None
        if method in AGENT_METHODS:
            agent_paths = {s: agents_dir / method / f"seed-{s}.pt" for s in params.experiment.seeds}
            for s, path in agent_paths.items():
                if not path.is_file():
                    raise UserError(
                        f"{path}: no such agent file (train it: socnav-wm train-agent "
                        f"--variant {method} --seed {s})"
                    )
        overrides_of = getattr(params.baselines, method) if method in BASELINE_METHODS else None
        result = evaluate_method(
            method,
            env_params=params.env,
            scenario_seed=params.eval.scenario_seed,
            episodes=params.eval.episodes,
            agent_paths=agent_paths,
            baseline_overrides=overrides_of,
            device=params.eval.device,
            batch_size=params.eval.batch_size,
            quiet=quiet,
        )
        episodes_path = out_dir / f"{method}.parquet"
        metrics_path = metrics_dir / f"{method}.json"
        write_evaluation(
            result, episodes_path, out_dir / f"{method}-trajectories.parquet", metrics_path
        )
        content = evaluation_metrics(result)
        run.set_tag("method", method)
        run.log_metrics({m: v["mean"] for m, v in content["metrics"].items()})
        run.log_metrics({f"{m}_ci_low": v["low"] for m, v in content["metrics"].items()})
        run.log_metrics({f"{m}_ci_high": v["high"] for m, v in content["metrics"].items()})
        run.log_metrics({"wall_time_s": result.wall_time})
        run.log_artifact(metrics_path)
    success = content["metrics"]["success"]
    typer.echo(
        f"wrote {episodes_path}: {method} success {success['mean']:.1%} "
        f"[{success['low']:.1%}, {success['high']:.1%}] over {result.num_scenarios} scenarios "
        f"x {len(result.training_seeds)} seed(s) in {result.wall_time:.0f} s"
    )


@app.command()
@friendly_errors
def report(
    params_path: ParamsOption = Path("params.yaml"),
    overrides: SetOption = None,
    eval_dir: Annotated[Path, typer.Option(help="Evaluation files.")] = Path("data/eval"),
    training_dir: Annotated[Path, typer.Option(help="Training logs.")] = Path("data/training"),
    out_dir: Annotated[Path, typer.Option(help="Report folder.")] = Path("reports"),
    metrics: Annotated[Path, typer.Option(help="Machine-readable summary (JSON).")] = Path(
        "metrics/report.json"
    ),
    no_tracking: NoTrackingOption = False,
) -> None:
    """Table, paired tests, Pareto set, figures and the paper's claims checked (stage
    `report`)."""
    from pipeline.evaluation.report import build_report

    sections = ("env", "eval", "report", "agent")
    with _stage("report", params_path, overrides, no_tracking, sections) as (params, run):
        r = params.report
        result = build_report(
            eval_dir,
            training_dir,
            out_dir,
            metrics,
            env_params=params.env,
            scenario_seed=params.eval.scenario_seed,
            reference=r.reference,
            gif_scenarios=tuple(r.gif_scenarios),
            smoothing_window=r.smoothing_window,
            solved_window=params.agent.solved_window,
            solved_success_rate=params.agent.solved_success_rate,
            alpha=r.alpha,
        )
        for claim, verdict in result.verdicts.items():
            run.set_tag(f"claim.{claim}", verdict)
        run.set_tag("methods", ",".join(result.present))
        for path in (result.summary_path, result.pareto_path, result.claims_path, *result.figures):
            run.log_artifact(path, "figures" if path in result.figures else None)
    missing = f"; missing: {', '.join(result.absent)}" if result.absent else ""
    typer.echo(f"wrote {result.summary_path} ({len(result.present)} methods{missing})")


# --------------------------------------------------------------------------- render
@app.command()
@friendly_errors
def render(
    out: Annotated[Path, typer.Option(help="Animated GIF to write.")] = Path("episode.gif"),
    policy: Annotated[str, typer.Option(help="Robot policy: random.")] = "random",
    episodes: Annotated[int, typer.Option(min=1, help="Episodes, one after the other.")] = 3,
    seed: Annotated[int, typer.Option(min=0, help="Scenario seed.")] = 0,
    human_policy: Annotated[str, typer.Option(help="Human motion: mixed, sfm or orca.")] = "mixed",
    fps: Annotated[float, typer.Option(min=0.5, help="Frames per second.")] = 8.0,
    size: Annotated[int, typer.Option(min=64, help="Frame side in pixels.")] = 480,
) -> None:
    """Render episodes of a robot policy in the simulator as an animated GIF."""
    if policy != "random":
        raise UserError(f"--policy: unknown policy {policy!r} (available: random)")
    import numpy as np

    from pipeline.env import EnvParams
    from pipeline.env.render import write_gif
    from pipeline.env.rollout import episode_frames, random_policy, run_episodes

    params = EnvParams(human_policy=human_policy)
    runs = run_episodes(params, random_policy(seed), seed, np.arange(episodes))
    frames = []
    for index, episode in enumerate(runs, start=1):
        frames += episode_frames(episode, params, label=f"{policy} #{index}", size=size)
    write_gif(frames, out, fps=fps)
    outcomes = ", ".join(
        "success" if e.success else f"{e.collision} collision" if e.collision else "timeout"
        for e in runs
    )
    typer.echo(f"wrote {out} ({len(frames)} frames; {outcomes})")


# --------------------------------------------------------------------------- bench
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
    from pipeline.bench import ENV_BATCH_SIZES, ENV_POLICIES, bench_env, one_core

    policies = tuple(humans or ENV_POLICIES)
    for policy in policies:
        if policy not in ENV_POLICIES:
            raise UserError(f"--humans: must be one of {', '.join(ENV_POLICIES)}, got {policy!r}")
    with one_core() as where:
        rows = bench_env(tuple(batch or ENV_BATCH_SIZES), policies, seconds)
    _print_table(
        rows,
        f"socnav-wm bench env ({where}, {seconds:g} s per row)",
        {"steps_per_s": ",.0f", "peak_mb": ".1f"},
    )


@bench_app.command("collect")
@friendly_errors
def bench_collect_command(
    episodes: Annotated[int, typer.Option(min=1, help="Episodes per row.")] = 2000,
    num_envs: Annotated[
        list[int] | None, typer.Option(help="Batch sizes (repeatable).", min=1)
    ] = None,
) -> None:
    """Env-steps/s of the collect stage end to end, Parquet writing included, one core."""
    from pipeline.bench import bench_collect, one_core

    with one_core() as where:
        rows = bench_collect(episodes, tuple(num_envs or (256, 512)))
    _print_table(
        rows,
        f"socnav-wm bench collect ({where})",
        {"seconds": ".2f", "steps_per_s": ",.0f", "parquet_mb": ".1f"},
    )


@bench_app.command("train")
@friendly_errors
def bench_train_command(
    variant: Annotated[
        list[str] | None, typer.Option(help="Variants (repeatable; default: all five).")
    ] = None,
    params_path: ParamsOption = Path("params.yaml"),
    overrides: SetOption = None,
    seconds: Annotated[float, typer.Option(min=0.1, help="Timing budget per rate (s).")] = 3.0,
    device: DeviceOption = None,
) -> None:
    """Env-steps/s (act + simulate + world-model features + store) and gradient updates/s of
    the DQN learner, per variant, with the `agent` and `env` sections of the params file (e.g.
    `--set agent.num_envs=64`) and a random world model of the `vae`/`lstm` sections' sizes."""
    from pipeline.agents.params import VARIANT_NAMES, check_variant
    from pipeline.bench import bench_train
    from pipeline.config import load_params
    from pipeline.worldmodel.training import resolve_device

    names = [check_variant(v) for v in variant or VARIANT_NAMES]
    params = _with_device(load_params(params_path, overrides or []), "agent", device)
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
                "env_steps_per_s": r["env_steps_per_s"],
                "updates_per_s": r["updates_per_s"],
            }
        )
    _print_table(
        rows,
        f"socnav-wm bench train ({params_path}, {resolve_device(agent.device)}, "
        f"{torch.get_num_threads()} torch threads, {agent.update_backend} update, "
        f"preset {agent.preset}, "
        f"decode_latents {agent.resolved(names[0]).decode_latents}, "
        f"{seconds:g} s per rate)",
        {
            "features": "d",
            "envs": "d",
            "batch": "d",
            "env_steps_per_s": ",.0f",
            "updates_per_s": ",.0f",
        },
    )


def main() -> None:  # pragma: no cover - console entry point
    app()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(app())
