"""Progress bars for long loops: rich on a terminal, nothing at all otherwise.

Under DVC, CI, a pipe or ``--quiet`` the bar is a shared no-op object, so a hot loop can call
``bar.advance()`` every step at the cost of one empty method call. rich is imported only when a
bar is actually drawn.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any, Protocol

__all__ = ["ProgressBar", "progress"]


class ProgressBar(Protocol):
    """What :func:`progress` yields."""

    def advance(self, n: float = 1) -> None:
        """Mark ``n`` more units done."""

    def set_postfix(self, **values: Any) -> None:
        """Show ``key=value`` pairs after the bar (replacing the previous ones)."""

    def set_description(self, description: str) -> None:
        """Change the text before the bar."""


class _NullBar:
    __slots__ = ()

    def advance(self, n: float = 1) -> None:
        pass

    def set_postfix(self, **values: Any) -> None:
        pass

    def set_description(self, description: str) -> None:
        pass


_NULL_BAR = _NullBar()


class _RichBar:
    __slots__ = ("_progress", "_task")

    def __init__(self, progress: Any, task: Any) -> None:
        self._progress = progress
        self._task = task

    def advance(self, n: float = 1) -> None:
        self._progress.advance(self._task, n)

    def set_postfix(self, **values: Any) -> None:
        text = " ".join(f"{key}={_format_value(value)}" for key, value in values.items())
        self._progress.update(self._task, postfix=text)

    def set_description(self, description: str) -> None:
        self._progress.update(self._task, description=description)


def _format_value(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def _format_rate(per_second: float | None, unit: str) -> str:
    if per_second is None:
        return f"? {unit}/s"
    if per_second >= 1:
        for scale, prefix in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
            if per_second >= scale:
                return f"{per_second / scale:.1f}{prefix} {unit}/s"
        return f"{per_second:.1f} {unit}/s"
    if per_second > 0:  # slow loops (epochs): seconds per unit reads better
        return f"{1 / per_second:.1f} s/{unit}"
    return f"0 {unit}/s"


def _stderr_is_terminal() -> bool:
    isatty = getattr(sys.stderr, "isatty", None)
    try:
        return bool(isatty and isatty())
    except ValueError:  # closed stream
        return False


@contextmanager
def progress(
    total: int, description: str, *, quiet: bool = False, unit: str = "it"
) -> Iterator[ProgressBar]:
    """A progress bar over ``total`` units, with rate and ETA, drawn on stderr.

    Yields a no-op bar when ``quiet`` is set or stderr is not a terminal.

    >>> with progress(1000, "collect", unit="episodes") as bar:
    ...     for _ in range(1000):
    ...         bar.advance()
    """
    if quiet or not _stderr_is_terminal():
        yield _NULL_BAR
        return

    from rich.console import Console
    from rich.progress import (
        BarColumn,
        Column,
        MofNCompleteColumn,
        Progress,
        ProgressColumn,
        Task,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )
    from rich.text import Text

    class RateColumn(ProgressColumn):
        def render(self, task: Task) -> Text:
            return Text(_format_rate(task.speed, unit), style="progress.data.speed")

    columns = (
        TextColumn("[progress.description]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        RateColumn(table_column=Column(no_wrap=True)),
        TimeElapsedColumn(),
        TextColumn("eta"),
        TimeRemainingColumn(),
        TextColumn(
            "{task.fields[postfix]}", table_column=Column(no_wrap=True, overflow="ellipsis")
        ),
    )
    # A low refresh rate: the machine has two cores and the bar must not compete with the work.
    with Progress(*columns, console=Console(stderr=True), refresh_per_second=4) as bar:
        task = bar.add_task(description, total=total, postfix="")
        yield _RichBar(bar, task)
