"""``socnav-wm bench``: speed and memory of the hot paths, printed as tables
(:mod:`socnav_wm.bench` measures)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from socnav_wm.cli.application import UserError, bench_app, command, print_table
from socnav_wm.cli.options import SharedOptions, available_cores, set_threads, shared_options
from socnav_wm.layout import LAYOUT


def print_machine(torch_build: bool = False) -> None:
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


@command("env", group=bench_app)
def bench_env_command(
    batch: Annotated[
        list[int] | None, typer.Option(help="Batch sizes (repeatable).", min=1)
    ] = None,
    humans: Annotated[
        list[str] | None, typer.Option(help="Human policies: sfm, orca, mixed (repeatable).")
    ] = None,
    seconds: Annotated[float, typer.Option(min=0.1, help="Timing budget per row (s).")] = 2.0,
    overlay: Annotated[
        list[Path] | None,
        typer.Option(
            help="A scenario preset (configs/scenarios/NAME.yaml; repeatable): rows per preset, "
            "with its own humans, or per preset and --humans policy when both are given."
        ),
    ] = None,
) -> None:
    """Env-steps/s and peak memory of the simulator, random actions, one core."""
    from socnav_wm.bench import ENV_BATCH_SIZES, ENV_POLICIES, bench_env, one_core
    from socnav_wm.config import load_params

    # With presets, --humans replaces each preset's humans; without it, a preset keeps its own.
    policies = tuple(humans or (() if overlay else ENV_POLICIES))
    for policy in policies:
        if policy not in ENV_POLICIES:
            raise UserError(f"--humans: must be one of {', '.join(ENV_POLICIES)}, got {policy!r}")
    scenarios = None
    if overlay:
        scenarios = {
            path.stem: load_params(LAYOUT.params, overlays=[path]).env.to_dict() for path in overlay
        }
    with one_core() as where:
        rows = bench_env(tuple(batch or ENV_BATCH_SIZES), policies, seconds, scenarios=scenarios)
    print_table(
        rows,
        f"socnav-wm bench env ({where}, one thread, {seconds:g} CPU-s per row)",
        {"steps_per_cpu_s": ",.0f", "peak_mb": ".1f"},
    )
    print_machine()


@command("collect", group=bench_app)
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
    print_table(
        rows,
        f"socnav-wm bench collect ({where})",
        {"cpu_seconds": ".2f", "steps_per_cpu_s": ",.0f", "parquet_mb": ".1f"},
    )
    print_machine()


@command("train", group=bench_app)
@shared_options("params", "set", "overlay", "threads", device="agent")
def bench_train_command(
    *,
    variant: Annotated[
        list[str] | None, typer.Option(help="Variants (repeatable; default: all five).")
    ] = None,
    options: SharedOptions,
    seconds: Annotated[float, typer.Option(min=0.1, help="Timing budget per rate (s).")] = 3.0,
) -> None:
    """Env-steps/s (act + simulate + world-model features + store) and gradient updates/s of
    the DQN learner, per variant, with the `agent` and `env` sections of the params file (e.g.
    `--set agent.num_envs=64`) and a random world model of the `vae`/`lstm` sections' sizes."""
    from socnav_wm.agents.params import VARIANT_NAMES, check_variant
    from socnav_wm.bench import bench_train
    from socnav_wm.devices import resolve_device

    names = [check_variant(v) for v in variant or VARIANT_NAMES]
    params = options.load()
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
    print_table(
        rows,
        f"socnav-wm bench train ({options.params_path}, {resolve_device(agent.device)}, "
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
    print_machine(torch_build=True)


@command("plan", group=bench_app)
@shared_options("params", "set", "overlay")
def bench_plan_command(
    *,
    method: Annotated[
        list[str] | None,
        typer.Option(help="Planners (repeatable) \\[default: every planner whose models exist]."),
    ] = None,
    batch: Annotated[
        list[int] | None, typer.Option(help="Episodes planned together (repeatable).", min=1)
    ] = None,
    options: SharedOptions,
    seconds: Annotated[float, typer.Option(min=0.1, help="Timing budget per row (CPU-s).")] = 2.0,
    planning_model: Annotated[
        Path | None,
        typer.Option(
            help="wm-mpc's planning model (another preset's: --overlay's) "
            f"[default: {LAYOUT.planning_model(0).as_posix()}]."
        ),
    ] = None,
    critic: Annotated[
        Path | None,
        typer.Option(
            help="wm-mpc-q's critic, a dueling-dqn agent (another preset's: --overlay's) "
            f"[default: {LAYOUT.agent('dueling-dqn').as_posix()}]."
        ),
    ] = None,
) -> None:
    """Decisions per CPU-second of each planner, one core and one torch thread, at the shipped
    batch (`eval.batch_size`) and at 1, 64 and 512 episodes planned together; `--overlay` a
    scenario preset for its humans."""
    from socnav_wm.bench import PLAN_BATCH_SIZES, bench_plan, one_core
    from socnav_wm.method_names import PLANNER_NAMES
    from socnav_wm.methods import method as registered

    config = options.load_or_defaults()
    for name in method or ():
        if name not in PLANNER_NAMES:
            raise UserError(
                f"--method: unknown {name!r}; expected one of {', '.join(PLANNER_NAMES)}"
            )
    methods = list(method or PLANNER_NAMES)
    files: dict[str, dict[str, Path]] = {}
    if planning_model:
        files["wm-mpc"] = files["wm-mpc-q"] = {"planning_model": planning_model}
    if critic:
        files["wm-mpc-q"] = {**files.get("wm-mpc-q", {}), "critic": critic}
    if not method:  # by default, skip the learned planners whose models are not there or are
        for name in list(methods):  # another preset's (the loader's one line says which)
            entry = registered(name)
            try:
                entry.policies(
                    config.env, files=entry.files(files.get(name)), planning=config.planning
                )
            except (FileNotFoundError, ValueError) as exc:
                typer.echo(f"skipped {name}: {exc}")
                methods.remove(name)
    sizes = tuple(batch or sorted({config.eval.batch_size, *PLAN_BATCH_SIZES}))
    set_threads(1)
    with one_core() as where:
        rows = bench_plan(
            tuple(methods), sizes, env_params=config.env, planning=config.planning,
            files=files or None, seconds=seconds,
        )  # fmt: skip
    print_table(
        rows,
        f"socnav-wm bench plan ({where}, one thread, {seconds:g} CPU-s per row; futures: "
        "prefixes x continuations, each imagined horizon steps)",
        {"decisions_per_cpu_s": ",.1f", "cpu_ms_per_decision": ".2f"},
    )


@command("contention", group=bench_app)
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
    print_table(
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
    print_machine(torch_build=True)
