"""The ``socnav-wm`` command line: one thin command per pipeline stage, plus bench and render.

Commands parse options, load the validated configuration and call one library function. Heavy
modules (torch, mlflow, the simulator's compiled kernels) are imported inside the commands, so
``socnav-wm --help`` answers at once. Expected failures (bad params, a missing file, an
unreachable tracking server) end with one line on stderr and exit code 2, never a traceback.
"""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable
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
    errors: list[type[BaseException]] = [UserError, ValueError, FileNotFoundError]
    return tuple(errors)


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


def main() -> None:  # pragma: no cover - console entry point
    app()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(app())
