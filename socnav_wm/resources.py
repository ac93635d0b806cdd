"""What the machine can hold: a stage estimates the memory it will allocate and refuses, in one
line, what does not fit, instead of allocating until ``MemoryError`` (or the OOM killer)."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

__all__ = [
    "Need",
    "ResourceError",
    "allocating",
    "available_memory_bytes",
    "build_trainable",
    "check_disk",
    "check_fits",
    "check_fits_together",
    "format_bytes",
    "is_out_of_memory",
]

Need = tuple[str, float, str]
"""One allocation of a run: (the setting that sizes it, its bytes, what it is in words)."""

_ALLOCATION_FAILED = (
    "can't allocate memory",  # torch's DefaultCPUAllocator
    "CUDA out of memory",
    "out of memory",
    "Cannot allocate memory",
)


class ResourceError(ValueError):
    """A stage would need more than the machine has (one line naming the setting)."""


def format_bytes(size: float) -> str:
    """``size`` bytes in the largest unit that keeps it at least 1: ``13.1 GiB``, ``340.0 KiB``,
    ``12 bytes`` (so that a small size never reads ``0.0 GiB``)."""
    for unit, scale in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if abs(size) >= scale:
            return f"{size / scale:,.1f} {unit}"
    return f"{size:,.0f} bytes"


def available_memory_bytes() -> int | None:
    """Memory available to new allocations (Linux ``MemAvailable``), else physical memory;
    None where neither can be read."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (OSError, ValueError, AttributeError):
        return None


def check_fits(setting: str, needed_bytes: float, what: str) -> None:
    """Raise :class:`ResourceError` when ``needed_bytes`` exceed the available memory."""
    check_fits_together([(setting, needed_bytes, what)])


def check_fits_together(needs: Sequence[Need]) -> None:
    """Raise :class:`ResourceError` when the allocations of one run (``needs``), together,
    exceed the available memory: each check passing alone does not make them fit at once.

    The line names the one setting whose need alone does not fit, else every setting with
    its share and the sum.
    """
    available = available_memory_bytes()
    needs = [need for need in needs if need[1] > 0]
    if available is None or not needs:
        return
    has = f"this machine has {format_bytes(available)} available"
    for setting, needed, what in needs:
        if needed > available:
            raise ResourceError(f"{setting}: {what} would take {format_bytes(needed)}, {has}")
    total = sum(need[1] for need in needs)
    if total > available:
        settings = ", ".join(dict.fromkeys(need[0] for need in needs))
        parts = " + ".join(f"{what} ({format_bytes(needed)})" for _, needed, what in needs)
        raise ResourceError(f"{settings}: together {parts} would take {format_bytes(total)}, {has}")


def is_out_of_memory(exc: BaseException) -> bool:
    """``exc`` is an allocation that failed: ``MemoryError``, or PyTorch's ``RuntimeError`` (CPU
    allocator, CUDA out of memory)."""
    if isinstance(exc, MemoryError):
        return True
    if type(exc).__name__ == "OutOfMemoryError":  # torch.OutOfMemoryError, torch.cuda's
        return True
    return isinstance(exc, RuntimeError) and any(text in str(exc) for text in _ALLOCATION_FAILED)


@contextlib.contextmanager
def allocating(setting: str, what: str) -> Iterator[None]:
    """Turn an allocation that fails inside the block into :class:`ResourceError`: ``<setting>:
    out of memory <what>`` (e.g. ``planning_model.hidden_dim: out of memory building the
    planning model (hidden_dim 1000000)``)."""
    try:
        yield
    except (MemoryError, RuntimeError) as exc:
        if not is_out_of_memory(exc):
            raise
        raise ResourceError(f"{setting}: out of memory {what}; lower it") from None


def check_disk(
    setting: str, needed_bytes: float, folder: str | os.PathLike[str], what: str
) -> None:
    """Raise :class:`ResourceError` when ``needed_bytes`` exceed the free space where ``folder``
    (or its nearest existing parent) lives."""
    import shutil

    from socnav_wm.io import nearest_existing

    existing = nearest_existing(folder)
    free = shutil.disk_usage(existing).free
    if needed_bytes > free:
        raise ResourceError(
            f"{setting}: {what} could take up to {format_bytes(needed_bytes)}, "
            f"{existing} has {format_bytes(free)} free"
        )


TRAINING_COPIES = 5
"""Copies of a network's weights that training holds: the weights, their gradients, Adam's two
moments and the best epoch's weights."""


def build_trainable(setting: str, what: str, build: Callable[[], Any]) -> Any:
    """``build()``, a PyTorch module to train, once it is known to fit: built first on PyTorch's
    meta device (no memory) to count its parameters, refused in one line when training it
    would exceed the available memory (:data:`TRAINING_COPIES` copies), then built for real,
    where an allocation that still fails is one line too (:func:`allocating`).

    Raises:
        ResourceError: ``<setting>: training <what> would take …`` or ``<setting>: out of
            memory building <what>``.
    """
    import torch

    with torch.device("meta"):
        numel = sum(parameter.numel() for parameter in build().parameters())
    check_fits(setting, TRAINING_COPIES * 4 * numel, f"training {what}")
    with allocating(setting, f"building {what}"):
        return build()
