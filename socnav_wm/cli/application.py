"""The typer application, its ``bench`` group, and what every command shares: expected errors as
one line and exit status 2, SIGTERM as Ctrl-C, and the tables commands print."""

from __future__ import annotations

import functools
import re
from collections.abc import Callable
from typing import Any

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
    from socnav_wm.tracking import TrackingError

    return (UserError, ValueError, FileNotFoundError, TrackingError)


def one_line_error(exc: BaseException) -> str | None:
    """The line an expected exception ends the command with: a problem with the input (its
    own message), or with the machine (:func:`environment_problem`); None for anything else,
    a bug, which keeps its traceback."""
    if isinstance(exc, OSError) and exc.errno is not None:  # the OS's words, not "[Errno 2] …"
        return environment_problem(exc)
    if isinstance(exc, _expected_errors()):
        text = str(exc).strip()
        return text.splitlines()[0] if text else repr(exc)
    return environment_problem(exc)


def environment_problem(exc: BaseException) -> str | None:
    """One line for a fault of the machine rather than of the code: an allocation that failed
    (``MemoryError``, PyTorch's allocator), a full disk, a file or folder that cannot be used;
    None for anything else (a bug, shown with its traceback)."""
    import errno

    from socnav_wm.resources import format_bytes, is_out_of_memory

    if is_out_of_memory(exc):
        tried = re.search(r"tried to allocate (\d+) bytes", str(exc))
        size = f" (PyTorch could not allocate {format_bytes(int(tried.group(1)))})" if tried else ""
        return f"out of memory{size}; lower the sizes in params.yaml"
    if not isinstance(exc, OSError):
        return None
    where = exc.filename if exc.filename is not None else None
    if exc.errno in (errno.ENOSPC, errno.EDQUOT) or "No space left on device" in str(exc):
        return "no space left on device" + (f" writing {where}" if where else "")
    if exc.errno is None or exc.strerror is None:
        return " ".join(str(exc).split()) or type(exc).__name__
    what = exc.strerror[0].lower() + exc.strerror[1:]
    return f"{where}: {what}" if where is not None else what


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
        except Exception as exc:
            message = one_line_error(exc)
            if message is None:
                raise
            typer.echo(f"error: {message}", err=True)
            raise typer.Exit(code=2) from None
        finally:
            signal.signal(signal.SIGTERM, previous)

    return wrapper


def command(
    name: str | None = None, *, group: typer.Typer = app
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Register a command on ``group`` (the application by default), with friendly errors."""

    def register(function: Callable[..., Any]) -> Callable[..., Any]:
        wrapped = friendly_errors(function)
        group.command(name)(wrapped)
        return wrapped

    return register


def print_table(rows: list[dict[str, Any]], title: str, formats: dict[str, str]) -> None:
    """``rows`` as a table titled ``title``; ``formats``: the format of each numeric column."""
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
