"""Atomic outputs: the target is the old content or the complete new one, never half; reading
back the files torch.save wrote, with one-line errors."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest
import torch

from socnav_wm.io import (
    OutputError,
    atomic_path,
    check_writable,
    load_saved,
    load_torch_file,
    outputs_together,
    write_bytes_atomic,
    write_json_atomic,
    write_text_atomic,
)


def test_replaces_the_target_and_leaves_no_temp(tmp_path: Path) -> None:
    target = tmp_path / "metrics.json"
    target.write_text("old")
    with atomic_path(target) as tmp:
        assert tmp.parent == tmp_path
        assert tmp.name.startswith(f".metrics.json.tmp-{os.getpid()}-")
        assert tmp.suffix == ".json"  # writers that read the format from the suffix still work
        assert not tmp.exists()
        tmp.write_text("new")
        assert target.read_text() == "old"  # nothing visible before the block ends
    assert target.read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["metrics.json"]


def test_exception_keeps_old_content_and_removes_temp(tmp_path: Path) -> None:
    target = tmp_path / "model.pt"
    target.write_bytes(b"old weights")
    with pytest.raises(RuntimeError, match="boom"), atomic_path(target) as tmp:
        tmp.write_bytes(b"half of the new weig")
        raise RuntimeError("boom")
    assert target.read_bytes() == b"old weights"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model.pt"]


def test_exception_before_any_write_creates_nothing(tmp_path: Path) -> None:
    target = tmp_path / "sub" / "out.bin"
    with pytest.raises(KeyError), atomic_path(target):
        raise KeyError("x")
    assert not target.exists()
    assert list(target.parent.iterdir()) == []


def test_creates_parent_directories(tmp_path: Path) -> None:
    target = tmp_path / "a" / "b" / "c.txt"
    write_text_atomic(target, "hello")
    assert target.read_text() == "hello"


def test_nothing_written_is_an_error(tmp_path: Path) -> None:
    target = tmp_path / "out.txt"
    with pytest.raises(FileNotFoundError, match="nothing was written"), atomic_path(target):
        pass
    assert not target.exists()


def test_a_directory_replaces_a_directory(tmp_path: Path) -> None:
    target = tmp_path / "rollouts"
    target.mkdir()
    (target / "shard-00000.parquet").write_text("old")
    (target / "shard-00001.parquet").write_text("old")
    with atomic_path(target) as tmp:
        tmp.mkdir()
        (tmp / "shard-00000.parquet").write_text("new")
    assert sorted(p.name for p in target.iterdir()) == ["shard-00000.parquet"]
    assert (target / "shard-00000.parquet").read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rollouts"]


def test_failed_directory_write_keeps_the_old_directory(tmp_path: Path) -> None:
    target = tmp_path / "rollouts"
    target.mkdir()
    (target / "shard-00000.parquet").write_text("old")
    with pytest.raises(ValueError), atomic_path(target) as tmp:
        tmp.mkdir()
        (tmp / "shard-00000.parquet").write_text("partial")
        raise ValueError
    assert (target / "shard-00000.parquet").read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rollouts"]


def test_write_bytes_atomic(tmp_path: Path) -> None:
    target = tmp_path / "blob.bin"
    write_bytes_atomic(target, b"\x00\x01")
    write_bytes_atomic(target, b"\x02")
    assert target.read_bytes() == b"\x02"


def test_write_json_atomic_sorted_indented_nan_as_null(tmp_path: Path) -> None:
    target = tmp_path / "metrics" / "vae.json"
    write_json_atomic(
        target,
        {
            "val_loss": float("nan"),
            "best": math.inf,
            "epochs": np.int64(3),
            "loss": np.float32(0.5),
            "curve": np.array([1.0, np.nan]),
            "a": [1, (2, None)],
        },
    )
    text = target.read_text()
    assert text.endswith("}\n")
    assert text.index('"a"') < text.index('"best"') < text.index('"val_loss"')
    assert '\n  "a": [' in text  # indent 2
    assert json.loads(text) == {
        "a": [1, [2, None]],
        "best": None,
        "curve": [1.0, None],
        "epochs": 3,
        "loss": 0.5,
        "val_loss": None,
    }


def test_write_json_atomic_rejects_unknown_types_and_keeps_old_file(tmp_path: Path) -> None:
    target = tmp_path / "m.json"
    write_json_atomic(target, {"ok": 1})
    with pytest.raises(TypeError):
        write_json_atomic(target, {"bad": object()})
    assert json.loads(target.read_text()) == {"ok": 1}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.json"]


class _Foreign:
    """An object the weights-only unpickler refuses (module-level so torch.save can pickle it)."""


class _FileError(ValueError):
    pass


def test_load_torch_file_reads_tensors_and_explains_what_it_cannot(tmp_path: Path) -> None:
    good = tmp_path / "good.pt"
    torch.save({"format": "x", "weights": torch.arange(3.0)}, good)
    payload = load_torch_file(good, "model file")
    assert payload["format"] == "x" and torch.equal(payload["weights"], torch.arange(3.0))

    text = tmp_path / "text.pt"
    text.write_text("garbage\n")
    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(good.read_bytes()[:300])
    foreign = tmp_path / "foreign.pt"
    torch.save({"object": _Foreign()}, foreign)
    cases = [
        (text, "(truncated, or not written by torch.save)"),
        (truncated, "(truncated, or not written by torch.save)"),
        (foreign, "(it holds objects other than tensors and plain values, which socnav-wm never "
                  "saves; not loaded)"),
    ]  # fmt: skip
    for path, reason in cases:
        with pytest.raises(_FileError) as error:
            load_torch_file(path, "model file", _FileError)
        assert str(error.value) == f"{path}: not a readable model file {reason}"


def test_load_saved_checks_existence_format_and_version(tmp_path: Path) -> None:
    good, foreign, old = tmp_path / "good.pt", tmp_path / "foreign.pt", tmp_path / "old.pt"
    torch.save({"format": "socnav-wm-x", "format_version": 2, "w": torch.ones(2)}, good)
    torch.save({"weights": torch.ones(2)}, foreign)
    torch.save({"format": "socnav-wm-x", "format_version": 1}, old)
    assert torch.equal(load_saved(good, "x file", "socnav-wm-x", 2)["w"], torch.ones(2))
    cases = [
        (tmp_path / "missing.pt", "no such x file"),
        (foreign, "not a socnav-wm x file"),
        (old, "x file format version 1, this code reads version 2"),
    ]
    for path, problem in cases:
        with pytest.raises(_FileError) as error:
            load_saved(path, "x file", "socnav-wm-x", 2, _FileError)
        assert str(error.value) == f"{path}: {problem}"


def test_a_killed_writers_temporaries_are_removed_by_the_next_write(tmp_path: Path) -> None:
    import subprocess
    import sys

    target = tmp_path / "vae.pt"
    # A writer that died: its pid no longer exists (a finished child process).
    child = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                           capture_output=True, text=True, check=True)  # fmt: skip
    dead = int(child.stdout)
    stale = tmp_path / f".vae.pt.tmp-{dead}-0a1b2c3d.pt"
    stale.write_bytes(b"half")
    stale_dir = tmp_path / f".vae.pt.old-{dead}-0a1b2c3d.pt"
    stale_dir.mkdir()
    alive = tmp_path / f".vae.pt.tmp-{os.getpid()}-0a1b2c3d.pt"  # a writer still running
    alive.write_bytes(b"in progress")
    other = tmp_path / f".lstm.pt.tmp-{dead}-0a1b2c3d.pt"  # another file's: not ours to judge
    other.write_bytes(b"x")
    write_bytes_atomic(target, b"new")
    assert target.read_bytes() == b"new"
    assert not stale.exists() and not stale_dir.exists()
    assert alive.exists() and other.exists()


def test_check_writable_names_the_output_that_cannot_be_written(tmp_path: Path) -> None:
    blocker = tmp_path / "metrics"
    blocker.write_text("a file where a folder should be")
    check_writable(tmp_path / "new" / "deep" / "a.json", tmp_path / "b.json")  # creatable
    with pytest.raises(OutputError) as error:
        check_writable(tmp_path / "ok.json", blocker / "vae.json")
    assert str(error.value).startswith(f"{blocker / 'vae.json'}: cannot be written")
    assert "\n" not in str(error.value)


def test_outputs_together_publishes_all_or_none(tmp_path: Path) -> None:
    a, b = tmp_path / "model.pt", tmp_path / "metrics.json"
    a.write_text("old model")
    b.write_text("old metrics")
    with pytest.raises(RuntimeError), outputs_together(a, b) as (ta, tb):
        ta.write_text("new model")
        raise RuntimeError("the metrics could not be computed")
    assert (a.read_text(), b.read_text()) == ("old model", "old metrics")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["metrics.json", "model.pt"]
    with outputs_together(a, b) as (ta, tb):
        ta.write_text("new model")
        tb.write_text("new metrics")
        assert a.read_text() == "old model"  # nothing published before the block ends
    assert (a.read_text(), b.read_text()) == ("new model", "new metrics")


def test_a_saved_model_has_the_same_bytes_whatever_its_temporary_name(tmp_path: Path) -> None:
    """torch.save names an archive's records after the file; every model is written under a
    temporary name first, so the bytes (and DVC's hash) must not depend on that name."""
    import torch

    from socnav_wm.io import atomic_path, torch_bytes

    payload = {"format": "x", "weights": torch.arange(6.0).reshape(2, 3)}
    for name in ("a.pt", "b.pt"):
        with atomic_path(tmp_path / name) as tmp:
            tmp.write_bytes(torch_bytes(payload))
    assert (tmp_path / "a.pt").read_bytes() == (tmp_path / "b.pt").read_bytes()
    loaded = torch.load(tmp_path / "a.pt", weights_only=True)
    assert torch.equal(loaded["weights"], payload["weights"])
