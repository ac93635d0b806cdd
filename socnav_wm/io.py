"""Atomic outputs: a stage's file is either the old one or the complete new one, never half.

Writers get a temporary path in the target's directory (same filesystem, so the final
``os.replace`` is atomic); on success the data is fsynced and renamed over the target, on error
the temporary is deleted and the target is left untouched. A process killed mid-write leaves at
most a hidden ``.name.tmp-<pid>-<random>`` file, which no reader (or DVC) takes for the output.
"""

from __future__ import annotations

import errno
import json
import math
import os
import pickle
import secrets
import shutil
import zipfile
from collections.abc import Collection, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

__all__ = [
    "DiskFullError",
    "ModelFileError",
    "OutputError",
    "atomic_path",
    "check_writable",
    "nearest_existing",
    "outputs_together",
    "read_json",
    "write_bytes_atomic",
    "write_json_atomic",
    "write_text_atomic",
]


class OutputError(ValueError):
    """An output location cannot be written (one line naming it)."""


class ModelFileError(ValueError):
    """A model file is missing, unreadable, not the expected kind, or made for other scenarios
    (one-line message naming it)."""


def _temp_sibling(target: Path, kind: str) -> Path:
    # The target's suffix is kept at the end because some writers pick the format from it
    # (matplotlib's savefig, PIL's save): `.vae.pt.tmp-123-9f2c.pt`.
    return target.with_name(
        f".{target.name}.{kind}-{os.getpid()}-{secrets.token_hex(4)}{target.suffix}"
    )


def _fsync_path(path: Path) -> None:
    """Flush a file, or a directory tree's files and directories, to disk."""
    if path.is_dir():
        for root, _dirs, files in os.walk(path):
            for name in files:
                _fsync_path(Path(root) / name)
            _fsync_dir(Path(root))
        return
    with open(path, "rb") as handle:
        os.fsync(handle.fileno())


def _fsync_dir(directory: Path) -> None:
    # Makes the rename itself durable. Not possible on every platform (Windows): best effort.
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _writer_is_gone(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except OSError:  # exists, owned by someone else
        return False
    return False


def remove_stale_temporaries(target: Path) -> list[Path]:
    """Delete the temporaries of ``target`` (``.name.tmp-<pid>-…``, ``.name.old-<pid>-…``) whose
    writing process no longer exists: what a killed run left. Returns what was removed."""
    removed = []
    prefix = f".{target.name}."
    if not target.parent.is_dir():
        return removed
    for entry in target.parent.iterdir():
        rest = entry.name[len(prefix) :] if entry.name.startswith(prefix) else ""
        kind, _, tail = rest.partition("-")
        pid = tail.partition("-")[0]
        if kind in ("tmp", "old") and pid.isdigit() and _writer_is_gone(int(pid)):
            _remove(entry)
            removed.append(entry)
    return removed


def nearest_existing(path: str | os.PathLike[str]) -> Path:
    """``path`` resolved, or its nearest ancestor that exists (what a writer would create
    the missing levels under)."""
    existing = Path(path).resolve()
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    return existing


def check_writable(
    *targets: str | os.PathLike[str], folders: Collection[str | os.PathLike[str]] = ()
) -> None:
    """Fail before any work when an output could not be written: for each target, its nearest
    existing ancestor must be a writable directory (the rest is created), and a target that is
    a file must not be an existing directory (``folders``: the targets that are directories).
    Raises :class:`OutputError` with one line naming the target."""
    folder_targets = {Path(folder) for folder in folders}
    for target in map(Path, targets):
        existing = nearest_existing(target.parent)
        if not existing.is_dir():
            raise OutputError(f"{target}: cannot be written ({existing} is not a directory)")
        if not os.access(existing, os.W_OK | os.X_OK):
            raise OutputError(f"{target}: cannot be written ({existing} is not writable)")
        if target.is_dir() and target not in folder_targets:
            raise OutputError(f"{target}: is a directory, cannot be written as a file")
        if target.exists() and target.is_file() and not os.access(target, os.W_OK):
            raise OutputError(f"{target}: cannot be written (the file is read-only)")


class DiskFullError(OutputError):
    """The disk filled up while an output was written (one line naming the output)."""

    def __init__(self, path: Path) -> None:
        super().__init__(f"no space left on device writing {path}")
        self.path = path


def _is_disk_full(exc: BaseException) -> bool:
    """``exc`` says that a write found the disk full: ENOSPC or EDQUOT, pyarrow's words, or
    PyTorch's zip writer cut short (``unexpected pos``)."""
    if isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT):
        return True
    text = str(exc)
    return "No space left on device" in text or (
        isinstance(exc, RuntimeError)
        and any(part in text for part in ("unexpected pos", "PytorchStreamWriter failed"))
    )


def _inside(path: Path, folder: Path) -> bool:
    path, folder = Path(os.path.abspath(path)), Path(os.path.abspath(folder))
    return path == folder or folder in path.parents


def _last_written(path: Path) -> float:
    """When ``path`` (a file, or a folder's newest entry) was last written; -1 if absent."""
    if not path.exists():
        return -1.0
    times = [path.stat().st_mtime]
    if path.is_dir():
        times += [p.stat().st_mtime for p in path.rglob("*") if p.exists()]
    return max(times)


def _disk_full_target(exc: BaseException, pairs: Sequence[tuple[Path, Path]]) -> Path | None:
    """The output whose writing ``exc`` interrupted because the disk is full (None if ``exc``
    is not about a full disk): the one whose temporary ``exc`` names, else the one written
    last."""
    named = exc.path if isinstance(exc, DiskFullError) else getattr(exc, "filename", None)
    if not (isinstance(exc, DiskFullError) or _is_disk_full(exc)):
        return None
    if named is not None:
        for target, tmp in pairs:
            if _inside(Path(os.fsdecode(named)), tmp):
                return target
        if isinstance(exc, DiskFullError):
            return exc.path
    latest = max(pairs, key=lambda pair: _last_written(pair[1]))
    return latest[0]


def _check_written(target: Path, tmp: Path) -> None:
    if not tmp.exists():
        raise FileNotFoundError(f"atomic_path: nothing was written for {target}")
    if target.is_dir() and not target.is_symlink() and not tmp.is_dir():
        raise OutputError(f"{target}: is a directory, cannot be replaced by a file")


def _swap_in(target: Path, tmp: Path, keep_old: bool) -> Path | None:
    """Rename ``tmp`` over ``target``; return where the old target now is (``keep_old``: a
    copy to restore it from; a replaced directory is always moved aside), or None."""
    old = None
    if tmp.is_dir() and (target.exists() or target.is_symlink()):
        # rename() cannot replace a non-empty directory: move the old one aside first, so the
        # window without a complete target is one rename long.
        old = _temp_sibling(target, "old")
        os.replace(target, old)
    elif keep_old and target.is_file():
        old = _temp_sibling(target, "old")
        try:
            os.link(target, old)  # the old content stays under a second name: no copy
        except OSError:
            shutil.copy2(target, old)
    try:
        os.replace(tmp, target)
    except BaseException:
        if old is not None and tmp.is_dir():
            os.replace(old, target)
        elif old is not None:
            _remove(old)
        raise
    return old


def _restore(target: Path, old: Path | None) -> None:
    """Undo :func:`_swap_in`: the old target back (or none, where there was none)."""
    if old is None:
        _remove(target)
        return
    if old.is_dir() and (target.exists() or target.is_symlink()):
        new = _temp_sibling(target, "old")
        os.replace(target, new)
        os.replace(old, target)
        _remove(new)
    else:
        os.replace(old, target)


def _publish(pairs: Sequence[tuple[Path, Path]]) -> None:
    """Rename every temporary over its target, or, if one rename fails, none: the targets
    already replaced get their old content back."""
    for target, tmp in pairs:
        _check_written(target, tmp)
    for _target, tmp in pairs:
        _fsync_path(tmp)
    replaced: list[tuple[Path, Path | None]] = []
    try:
        for target, tmp in pairs:
            replaced.append((target, _swap_in(target, tmp, keep_old=len(pairs) > 1)))
    except BaseException:
        for target, old in reversed(replaced):
            _restore(target, old)
        raise
    for _target, old in replaced:
        if old is not None:
            _remove(old)
    for folder in dict.fromkeys(target.parent for target, _ in pairs):
        _fsync_dir(folder)


@contextmanager
def outputs_together(*targets: str | os.PathLike[str]) -> Iterator[list[Path]]:
    """Temporary paths for a stage's outputs, published together or not at all.

    The block writes every output at its temporary path; when it succeeds, each temporary is
    renamed over its target, one right after the other (the window in which some outputs are
    new and others old is a few renames long, not the length of the work). When the block
    raises, every temporary is removed and every target keeps its old content; when a rename
    fails, the targets already renamed get their old content back.

    Raises:
        DiskFullError: the disk filled up: one line naming the output being written.
        OutputError: a target is a directory where a file was written.
    """
    pairs = []
    for target in map(Path, targets):
        target.parent.mkdir(parents=True, exist_ok=True)
        remove_stale_temporaries(target)
        pairs.append((target, _temp_sibling(target, "tmp")))
    try:
        try:
            yield [tmp for _, tmp in pairs]
            _publish(pairs)
        except BaseException as exc:
            full = _disk_full_target(exc, pairs)
            if full is None:
                raise
            raise DiskFullError(full) from exc
    except BaseException:
        for _, tmp in pairs:
            _remove(tmp)
        raise


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


@contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success it replaces ``path``.

    Write a file at the yielded path (or create a directory there: a directory replaces the
    target directory as a whole, e.g. a folder of Parquet shards). Parent directories are
    created. If the block raises, the temporary is removed and ``path`` keeps its old content;
    a full disk is :class:`DiskFullError`, one line naming ``path``.

    >>> with atomic_path("metrics/vae.json") as tmp:
    ...     tmp.write_text("{}")
    """
    with outputs_together(path) as (tmp,):
        yield tmp


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def write_text_atomic(path: str | os.PathLike[str], text: str) -> None:
    """Write UTF-8 ``text`` to ``path`` atomically."""
    write_bytes_atomic(path, text.encode("utf-8"))


def write_json_atomic(path: str | os.PathLike[str], obj: Any) -> None:
    """Write ``obj`` as JSON (sorted keys, indent 2, trailing newline) atomically.

    NaN and ±inf become ``null`` (JSON has no such numbers and DVC's metrics reader rejects
    them); numpy scalars and arrays become plain numbers and lists; paths become strings.
    """
    text = json.dumps(_jsonable(obj), sort_keys=True, indent=2, allow_nan=False)
    write_text_atomic(path, text + "\n")


def _jsonable(value: Any) -> Any:
    if isinstance(value, float):  # also numpy.float64, a float subclass
        return float(value) if math.isfinite(value) else None
    if value is None or isinstance(value, str | bool | int):
        return value
    if isinstance(value, Mapping):
        return {str(key): _jsonable(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(item) for item in value]
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if hasattr(value, "tolist"):  # numpy scalars and arrays, torch tensors
        return _jsonable(value.tolist())
    raise TypeError(f"cannot write {type(value).__name__} as JSON: {value!r}")


def read_json(
    path: str | os.PathLike[str], what: str = "JSON file", error: type[ValueError] = ValueError
) -> Any:
    """The content of the JSON file ``path``; otherwise ``error``, one line naming the file: it
    is missing, unreadable, or not valid JSON (with the place of the first fault)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise error(f"{path}: no such {what}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise error(f"{path}: not a readable {what} ({first_line(exc)})") from None
    try:
        return json.loads(text)
    except ValueError as exc:
        raise error(f"{path}: not valid JSON ({first_line(exc)})") from None


def torch_bytes(payload: Any) -> bytes:
    """``torch.save``'s archive of ``payload``, the same bytes for the same payload wherever it
    is written. Saved to a file, torch names the archive's records after that file, and every
    output here is first written under a temporary name (:func:`atomic_path`): the same model
    would get other bytes, and another DVC hash, on every run. In memory it gets torch's one
    name for unnamed archives."""
    import io

    import torch

    buffer = io.BytesIO()
    torch.save(payload, buffer)
    return buffer.getvalue()


def load_torch_file(
    path: str | os.PathLike[str], what: str, error: type[ValueError] = ValueError
) -> Any:
    """``torch.load`` of a file that socnav-wm wrote: tensors and plain values, loaded on the CPU
    with PyTorch's weights-only unpickler (never arbitrary objects).

    Raises:
        error: one line naming the file and, in words, why it cannot be read as a ``what``:
            truncated or not a ``torch.save`` archive, or holding objects this project never
            saves (PyTorch's own message would suggest ``weights_only=False``, which would run
            whatever the file holds).
    """
    import torch

    path = Path(path)
    if not zipfile.is_zipfile(path):
        raise error(f"{path}: not a readable {what} (truncated, or not written by torch.save)")
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as exc:
        raise error(
            f"{path}: not a readable {what} (it holds objects other than tensors and plain "
            "values, which socnav-wm never saves; not loaded)"
        ) from exc
    except Exception as exc:  # torch raises many types for damaged archives
        raise error(f"{path}: not a readable {what} ({first_line(exc)})") from exc


def load_saved(
    path: str | os.PathLike[str],
    what: str,
    file_format: str,
    version: int,
    error: type[ValueError] = ValueError,
) -> dict[str, Any]:
    """The dict of a socnav-wm file (model, agent, checkpoint), read by :func:`load_torch_file`
    and checked: it exists, its ``format`` is ``file_format`` and its ``format_version`` is
    ``version``; otherwise ``error`` with one line naming the file."""
    path = Path(path)
    if not path.is_file():
        raise error(f"{path}: no such {what}")
    payload = load_torch_file(path, what, error)
    check_format(payload, path, what, file_format, version, error)
    return payload


def check_format(
    header: object,
    path: str | os.PathLike[str],
    what: str,
    file_format: str,
    version: int,
    error: type[ValueError] = ValueError,
) -> None:
    """``header`` (a saved dict, or a Parquet file's metadata) names ``file_format`` and
    ``version``; otherwise ``error``: not a socnav-wm ``what``, or of another format version."""
    if not isinstance(header, dict) or header.get("format") != file_format:
        raise error(f"{path}: not a socnav-wm {what}")
    if header.get("format_version") != version:
        raise error(
            f"{path}: {what} format version {header.get('format_version')!r}, "
            f"this code reads version {version}"
        )


def first_line(exc: BaseException) -> str:
    """An exception's message cut to one line of at most 200 characters (its type if empty)."""
    text = str(exc).strip().splitlines()
    return text[0][:200] if text else type(exc).__name__
