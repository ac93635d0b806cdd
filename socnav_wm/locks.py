"""Locks between socnav-wm processes: a stage's inputs are not rewritten while it runs, and a
SQLite tracking store is created by one process at a time.

A path's lock is ``flock`` on its lock file, kept out of the repository in the temporary
folder (``socnav-wm-locks-<uid>/``, one file per absolute path: :func:`lock_path`), so that no
output folder, git or DVC ever sees one. A stage holds a shared lock on each input and an
exclusive one on each output for as long as it runs (:func:`stage_files`): it refuses to start,
in one line, while another process writes what it reads (``dvc repro train_vae`` during a
direct ``socnav-wm collect`` would train on the old rollouts while ``dvc.lock`` recorded the
new ones), or reads or writes what it would write. The kernel releases a process's locks when
it ends, killed or not: no stale lock is left. One user's processes on one machine see each
other's locks (not other users', nor other machines sharing a folder); where ``fcntl`` is
missing (Windows) nothing is locked.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import tempfile
import time
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

__all__ = ["LOCK_FOLDER", "BusyError", "LockTimeout", "lock_path", "stage_files", "waiting_lock"]

LOCK_FOLDER = "socnav-wm-locks"
"""The lock files' folder in the temporary folder, one per user (``socnav-wm-locks-<uid>``)."""


class BusyError(ValueError):
    """Another socnav-wm process is writing a stage's input, or using its output (one line)."""


_HELD: dict[str, list[Any]] = {}
"""This process's locks: lock file → [file descriptor, exclusive, holders]."""


def _fcntl() -> Any:
    try:
        import fcntl
    except ImportError:  # Windows
        return None
    return fcntl


def lock_path(path: str | os.PathLike[str]) -> Path:
    """The lock file of ``path``: in this user's :data:`LOCK_FOLDER` of the temporary folder,
    named by a hash of the absolute path (symbolic links resolved) and its last part."""
    real = os.path.realpath(os.fspath(path))
    digest = hashlib.sha256(real.encode("utf-8", "surrogateescape")).hexdigest()[:24]
    user = os.getuid() if hasattr(os, "getuid") else 0
    folder = Path(tempfile.gettempdir()) / f"{LOCK_FOLDER}-{user}"
    return folder / f"{digest}-{Path(real).name[:64]}.lock"


def _open(lock: Path) -> int:
    """A descriptor of ``lock``, made where missing (in a folder only this user can use)."""
    lock.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
    return os.open(lock, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o600)


def _holder(fd: int) -> str:
    """`` (pid N)`` where the lock file names a writer that still runs, else empty."""
    with contextlib.suppress(OSError, ValueError, IndexError):
        pid = int(os.pread(fd, 32, 0).decode().split()[0])
        os.kill(pid, 0)
        return f" (pid {pid})"
    return ""


def _acquire(path: Path, exclusive: bool, stack: contextlib.ExitStack) -> None:
    fcntl = _fcntl()
    if fcntl is None:
        return
    key = os.fspath(lock_path(path))
    held = _HELD.get(key)
    if held is not None and (held[1] or not exclusive):  # held here already, strongly enough
        held[2] += 1
        stack.callback(_release, key)
        return
    try:
        fd = held[0] if held is not None else _open(Path(key))
    except OSError:
        return  # no temporary folder to lock in: nothing is checked
    try:
        fcntl.flock(fd, (fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH) | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = _holder(fd)
        if held is None:
            os.close(fd)
        if exclusive:
            raise BusyError(
                f"{path}: another socnav-wm process is reading or writing it; wait for it to "
                "finish, then rerun"
            ) from None
        raise BusyError(
            f"{path}: being written by another socnav-wm process{holder}; wait for it to "
            "finish, then rerun"
        ) from None
    if exclusive:  # who writes, for the message of a stage that must wait
        with contextlib.suppress(OSError):
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    if held is None:
        _HELD[key] = [fd, exclusive, 1]
    else:
        held[1], held[2] = True, held[2] + 1
    stack.callback(_release, key)


def _release(key: str) -> None:
    held = _HELD[key]
    held[2] -= 1
    if held[2] == 0:
        del _HELD[key]
        os.close(held[0])  # closing the descriptor releases the lock


@contextmanager
def stage_files(
    inputs: Iterable[str | os.PathLike[str]] = (), outputs: Iterable[str | os.PathLike[str]] = ()
) -> Iterator[None]:
    """Hold, for the block, a shared lock on each of a stage's ``inputs`` and an exclusive one
    on each of its ``outputs``: refused at once, one line, where another process holds one
    that conflicts (this process may hold its own again).

    Raises:
        BusyError: naming the path another socnav-wm process is using.
    """
    with contextlib.ExitStack() as stack:
        for path in outputs:
            _acquire(Path(path), True, stack)
        for path in inputs:
            _acquire(Path(path), False, stack)
        yield


class LockTimeout(TimeoutError):
    """:func:`waiting_lock` waited in vain."""


@contextmanager
def waiting_lock(path: str | os.PathLike[str] | None, timeout_s: float) -> Iterator[None]:
    """Hold an exclusive lock on ``path`` (its lock file) for the block, waiting up to
    ``timeout_s`` for another process to release it; nothing is locked where ``path`` is
    None.

    MLflow's SQLite store (socnav_wm/tracking.py) is opened under it: opening creates or
    migrates the store, and stages started together on a new store would all create its
    tables (``table … already exists``, alembic errors), leaving a store that every later run
    fails on.

    Raises:
        LockTimeout: the lock was not free within ``timeout_s``.
    """
    fcntl = _fcntl()
    if fcntl is None or path is None:
        yield
        return
    fd = _open(lock_path(path))
    try:
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() > deadline:
                    raise LockTimeout(f"{path}: locked for more than {timeout_s:g} s") from None
                time.sleep(0.05)
        yield
    finally:
        os.close(fd)  # releases the lock
