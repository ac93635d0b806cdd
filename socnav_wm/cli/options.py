"""The options that the pipeline's commands share (``--params``, ``--set``, ``--overlay``,
``--device``, ``--threads``, ``--no-tracking``, ``--quiet``), declared once: a command decorated
with :func:`shared_options` gets the ones it names and receives them as one
:class:`SharedOptions`, its argument ``options``."""

from __future__ import annotations

import functools
import inspect
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from socnav_wm.cli.application import UserError
from socnav_wm.layout import LAYOUT
from socnav_wm.section import DEVICES

if TYPE_CHECKING:
    from socnav_wm.config import Params

_OPTIONS: dict[str, tuple[Any, Any]] = {
    "params_path": (
        Annotated[
            Path,
            typer.Option("--params", help="Parameters file (YAML), relative to the working dir."),
        ],
        LAYOUT.params,
    ),
    "overrides": (
        Annotated[
            list[str] | None,
            typer.Option("--set", help="Override a parameter: section.key=value (repeatable)."),
        ],
        None,
    ),
    "overlays": (
        Annotated[
            list[Path] | None,
            typer.Option(
                "--overlay",
                help="A YAML file merged over the params file, e.g. configs/paper.yaml "
                "(repeatable).",
            ),
        ],
        None,
    ),
    "device": (
        Annotated[
            str | None,
            typer.Option(help="auto, cpu or cuda; overrides the stage's `device` parameter."),
        ],
        None,
    ),
    "threads": (
        Annotated[
            int | None,
            typer.Option(
                min=1,
                help="PyTorch CPU threads (default: OMP_NUM_THREADS if set, else the cores this "
                "process may use; never more than those cores).",
            ),
        ],
        None,
    ),
    "no_tracking": (
        Annotated[bool, typer.Option("--no-tracking", help="Do not record an MLflow run.")],
        False,
    ),
    "quiet": (Annotated[bool, typer.Option("--quiet", help="No progress bar.")], False),
}
"""Each shared option: its parameter's annotation and default."""

OPTION_NAMES = {
    "params": "params_path",
    "set": "overrides",
    "overlay": "overlays",
    "device": "device",
    "threads": "threads",
    "no-tracking": "no_tracking",
    "quiet": "quiet",
}
"""The shared options by their command-line names (without ``--``)."""

_FIRST = ("params_path", "overrides", "overlays")
"""Listed where the command's ``options`` parameter stands; the others after its own."""


def documents_option(block: str) -> Any:
    """The type of a ``--document`` option: Markdown files whose ``block`` block gets a table."""
    return Annotated[
        list[Path] | None,
        typer.Option(help=f"Markdown file whose {block} block gets the table (repeatable)."),
    ]


def path_option(help: str) -> Any:
    """The type of an option naming one file or folder, with ``help``."""
    return Annotated[Path, typer.Option(help=help)]


Rollouts = path_option("Directory of rollout shards.")
ModelOut = path_option("Model file to write.")
ValidationMetrics = path_option("Validation metrics (JSON).")
History = path_option("Per-epoch losses (JSON, for plots).")
FrozenVae = path_option("Frozen VAE.")
FrozenLstm = path_option("Frozen LSTM.")
"""Options that several commands share, each with its help."""


def available_cores() -> int:
    """The CPU cores this process may run on (its affinity mask where the OS has one)."""

    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


def set_threads(threads: int | None) -> int:
    """Set PyTorch's intra-op thread count deliberately: ``threads``, else ``OMP_NUM_THREADS``,
    else every available core, capped at the available cores (more threads than cores spin
    against each other and against the neighbours on a shared machine). Returns the count.
    Results do not depend on it (tests/agents/test_training.py)."""

    cores = available_cores()
    if threads is None:
        env = os.environ.get("OMP_NUM_THREADS", "")
        threads = int(env) if env.isdigit() and int(env) > 0 else cores
    threads = min(threads, cores)
    import torch

    torch.set_num_threads(threads)
    return threads


@dataclass(frozen=True)
class SharedOptions:
    """The shared options of one command's invocation (those it does not have: their
    defaults)."""

    params_path: Path = LAYOUT.params
    overrides: tuple[str, ...] = ()
    overlays: tuple[Path, ...] = ()
    device: str | None = None
    threads: int | None = None
    no_tracking: bool = False
    quiet: bool = False
    device_section: str | None = None
    """The params section whose ``device`` ``--device`` replaces."""
    sets_threads: bool = False
    """Whether :meth:`load` sets PyTorch's threads (the command has ``--threads``)."""
    has_quiet: bool = False
    """Whether the command has ``--quiet`` (its stage draws a progress bar)."""

    @property
    def tracking(self) -> bool:
        return not self.no_tracking

    def stage_options(self) -> dict[str, bool]:
        """The keyword arguments that a stage's ``run`` takes from these options: ``tracking``,
        and ``quiet`` where the command has ``--quiet``."""
        return {"tracking": self.tracking, **({"quiet": self.quiet} if self.has_quiet else {})}

    def load(self) -> Params:
        """The validated params (before any heavy import), with ``--device`` applied, then
        PyTorch's threads set (:func:`set_threads`) if the command has ``--threads``.

        ``--device`` replaces the ``device`` of the command's section before the params are
        logged, and the device is checked (CUDA asked for on a machine without it is an error
        before any run opens).
        """
        from socnav_wm.config import load_params

        params = load_params(self.params_path, list(self.overrides), list(self.overlays))
        if self.device_section is not None:
            params = self._with_device(params)
            from socnav_wm.devices import resolve_device

            resolve_device(getattr(params, self.device_section).device)
        if self.sets_threads:
            set_threads(self.threads)
        return params

    def load_or_defaults(self) -> Params:
        """:meth:`load`, or where the params file is not there the defaults, with the overlays
        and ``--set`` applied all the same."""
        if self.params_path.exists():
            return self.load()
        from socnav_wm.config import load_params

        # An empty file (the null device) is "all defaults".
        return load_params(os.devnull, list(self.overrides), list(self.overlays))

    def _with_device(self, params: Params) -> Params:
        if self.device is None:
            return params
        if self.device not in DEVICES:
            raise UserError(f"--device: must be one of {', '.join(DEVICES)}, got {self.device!r}")
        updated = getattr(params, self.device_section).replace(device=self.device)
        return params.model_copy(update={self.device_section: updated})


def shared_options(
    *names: str, device: str | None = None
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Give the decorated command the shared options ``names`` (command-line names: ``params``,
    ``set``, ``overlay``, ``threads``, ``no-tracking``, ``quiet``), and ``--device`` for params
    section ``device``; the command receives them as one :class:`SharedOptions`, its keyword
    argument ``options``.

    In ``--help``, ``--params``, ``--set`` and ``--overlay`` stand where ``options`` stands among
    the command's parameters, the others after them all, in the order of ``names``.
    """
    chosen = [OPTION_NAMES[name] for name in names]
    first = [name for name in chosen if name in _FIRST]
    last = (["device"] if device else []) + [name for name in chosen if name not in _FIRST]

    def parameter(name: str) -> inspect.Parameter:
        annotation, default = _OPTIONS[name]
        return inspect.Parameter(
            name, inspect.Parameter.KEYWORD_ONLY, default=default, annotation=annotation
        )

    def decorate(function: Callable[..., Any]) -> Callable[..., Any]:
        parameters: list[inspect.Parameter] = []
        for own in inspect.signature(function, eval_str=True).parameters.values():
            if own.name == "options":
                parameters += [parameter(name) for name in first]
            else:
                parameters.append(own.replace(kind=inspect.Parameter.KEYWORD_ONLY))
        parameters += [parameter(name) for name in last]

        @functools.wraps(function)
        def wrapper(**kwargs: Any) -> Any:
            values = {name: kwargs.pop(name) for name in first + last}
            options = SharedOptions(
                **{
                    **values,
                    "overrides": tuple(values.get("overrides") or ()),
                    "overlays": tuple(values.get("overlays") or ()),
                },
                device_section=device,
                sets_threads="threads" in last,
                has_quiet="quiet" in last,
            )
            return function(options=options, **kwargs)

        signature = inspect.Signature(parameters)
        wrapper.__signature__ = signature  # type: ignore[attr-defined]
        wrapper.__annotations__ = {p.name: p.annotation for p in signature.parameters.values()}
        return wrapper

    return decorate
