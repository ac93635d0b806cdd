"""The ``socnav-wm`` command line: one thin command per pipeline stage, plus bench and render.

Commands parse options, load the validated configuration and call one library function. Heavy
modules (torch, mlflow, the simulator's compiled kernels) are imported inside the commands, so
``socnav-wm --help`` answers at once. Expected failures (bad params, a missing file, an
unreachable tracking server) end with one line on stderr and exit code 2, never a traceback.

This module imports only the standard library: :func:`main`, the console script, first checks
that the ``pipeline`` extra (typer and the rest) is installed, which a core
``pip install socnav-wm`` does not bring. The commands are in :mod:`~socnav_wm.cli.stages`,
:mod:`~socnav_wm.cli.studies`, :mod:`~socnav_wm.cli.render` and :mod:`~socnav_wm.cli.bench`;
``socnav_wm.cli.app`` is the typer application with all of them.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import sys
from typing import Any, NoReturn

# OpenMP threads that wait for work spin a little (1,000 iterations), then sleep. libgomp reads
# this when torch loads it, so it is set before any import of torch. Threads that spin for
# long burn the CPU a neighbour on a shared machine needs, and wait for it in turn. On two
# threads beside two busy processes (`socnav-wm bench contention --threads 2 --hogs 2`), the
# CPU-seconds over those alone were, for train-vae and train-agent: 1.72x and 1.92x with 10,000
# spins; 0.97x and 0.87x with none (OMP_WAIT_POLICY=PASSIVE alone), but train-agent then took
# 29.6 s alone instead of 18.0; 1.09x and 1.12x with this, 21.4 s alone (docs/performance.md).
# Results do not depend on it. Set either variable to override.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
os.environ.setdefault("GOMP_SPINCOUNT", "1000")

COMMAND_MODULES = ("stages", "models", "render", "studies", "bench")
"""The modules of ``socnav_wm.cli`` whose commands the application has, in ``--help`` order."""

PIPELINE_MODULES = frozenset(
    {"typer", "rich", "yaml", "torch", "pyarrow", "matplotlib", "scipy", "dvc", "mlflow"}
)
"""The top-level modules of the ``pipeline`` extra (pyproject.toml) that the commands import."""

MISSING_EXTRA = (
    "socnav-wm: the command line needs the pipeline extra: pip install 'socnav-wm[pipeline]'"
)


def _application() -> Any:
    for name in COMMAND_MODULES:  # each registers its commands on the application
        importlib.import_module(f"{__name__}.{name}")
    return importlib.import_module(f"{__name__}.application").app


def __getattr__(name: str) -> Any:
    if name == "app":
        return _application()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _missing_extra() -> NoReturn:
    print(MISSING_EXTRA, file=sys.stderr)
    sys.exit(2)


def main() -> None:
    """The ``socnav-wm`` console script: the application, or one line on stderr and exit
    status 2 where the ``pipeline`` extra is not installed."""
    try:
        if importlib.util.find_spec("typer") is None:
            _missing_extra()
        app = _application()
    except ModuleNotFoundError as exc:
        if (exc.name or "").partition(".")[0] not in PIPELINE_MODULES:
            raise
        _missing_extra()
    try:
        app()
    except ModuleNotFoundError as exc:  # a command's own import of torch, pyarrow, …
        if (exc.name or "").partition(".")[0] not in PIPELINE_MODULES:
            raise
        _missing_extra()
