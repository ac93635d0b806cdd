"""What the machine can hold: a stage estimates the memory it will allocate and refuses, in one
line, what does not fit, instead of allocating until ``MemoryError`` (or the OOM killer)."""

from __future__ import annotations

import os
from pathlib import Path


class ResourceError(ValueError):
    """A stage would need more than the machine has (one line naming the setting)."""


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
    available = available_memory_bytes()
    if available is not None and needed_bytes > available:
        raise ResourceError(
            f"{setting}: {what} would take {needed_bytes / 2**30:,.1f} GiB, this machine has "
            f"{available / 2**30:,.1f} GiB available"
        )


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
            f"{setting}: {what} could take up to {needed_bytes / 2**30:,.1f} GiB, "
            f"{existing} has {free / 2**30:,.1f} GiB free"
        )
