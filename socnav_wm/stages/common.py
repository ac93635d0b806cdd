"""What every stage does around its work: open the MLflow run with the params it reads, save
those params beside its outputs, and log per-epoch or per-episode curves."""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypedDict, TypeVar

import numpy as np
import torch

from socnav_wm.config import STAGE_SECTIONS, Params, params_dict, save_resolved, select_sections
from socnav_wm.io import check_writable, outputs_together, write_json_atomic
from socnav_wm.locks import stage_files
from socnav_wm.progress import progress
from socnav_wm.tracking import Run, stage_run

T = TypeVar("T")


@contextmanager
def open_stage(
    stage: str,
    run_name: str,
    params: Params,
    *,
    tracking: bool = True,
    inputs: Sequence[Path] = (),
    outputs: Sequence[Path] = (),
) -> Iterator[Run]:
    """The MLflow run of one stage invocation, logging the sections the stage reads, with its
    ``inputs`` and ``outputs`` locked against other socnav-wm processes (:func:`stage_files`:
    refused in one line while another process writes an input or uses an output)."""
    logged = select_sections(params_dict(params), STAGE_SECTIONS[stage])
    # The run first: its store is checked before a lock file is made (a refused start is a
    # FAILED run naming the process in the way).
    with stage_run(run_name, logged, enabled=tracking) as run, stage_files(inputs, outputs):
        yield run


def config_path(output: Path) -> Path:
    """Where a stage saves its resolved configuration: beside its main output."""
    return (
        output.with_name(output.stem + ".params.yaml") if output.suffix else output / "params.yaml"
    )


def save_stage_params(stage: str, params: Params, path: Path) -> None:
    """The sections ``stage`` reads (and only those), as YAML at ``path``."""
    save_resolved(params, path, sections=STAGE_SECTIONS[stage])


def epoch_logger(run: Run, bar: Any) -> Callable[[int, dict[str, float]], None]:
    """Per-epoch MLflow metrics and progress of a world-model training."""

    def on_epoch(epoch: int, values: dict[str, float]) -> None:
        run.log_metrics(values, step=epoch)
        bar.advance()
        bar.set_postfix(val_loss=values.get("val_loss"))

    return on_epoch


def training_logger(run: Run, every: int, window: int) -> Callable[[list[dict[str, Any]]], None]:
    """MLflow curves of an agent training: means over the last ``window`` episodes, every
    ``every`` episodes (the per-episode rows go to the Parquet log)."""
    history: list[dict[str, Any]] = []

    def on_episodes(rows: list[dict[str, Any]]) -> None:
        before = len(history)
        history.extend(rows)
        if len(history) // every == before // every:
            return
        recent = history[-window:]
        run.log_metrics(
            {
                "return": float(np.mean([r["return"] for r in recent])),
                "success_rate": float(np.mean([r["success"] for r in recent])),
                "collision_rate": float(np.mean([r["collision"] for r in recent])),
                "timeout_rate": float(np.mean([r["timeout"] for r in recent])),
                "length": float(np.mean([r["length"] for r in recent])),
                "epsilon": float(recent[-1]["epsilon"]),
            },
            step=len(history),
        )

    return on_episodes


@dataclass(frozen=True)
class WorldModelStage:
    """One world-model stage's open MLflow run and the files it publishes: the model, its
    metrics and its per-epoch history (JSON)."""

    stage: str
    run_name: str
    run: Run
    params: Params
    model: Path
    metrics: Path
    history: Path
    quiet: bool

    def fit(self, epochs: int, fit: Callable[..., T]) -> T:
        """``fit(on_epoch=…)`` under a progress bar of ``epochs`` epochs, each epoch's losses
        logged to MLflow."""
        with progress(epochs, self.run_name, quiet=self.quiet, unit="epochs") as bar:
            return fit(on_epoch=epoch_logger(self.run, bar))

    def publish(
        self,
        save_model: Callable[[Path], None],
        summary: dict[str, float],
        epochs: list[dict[str, float]],
    ) -> None:
        """The stage's outputs, published together: the model (``save_model(path)``), the
        params it read, the metrics (``summary``) and the per-epoch history (JSON); then
        logged to MLflow with the final metrics (without the per-epoch series, so their
        curves stay clean)."""
        model = self.model
        with outputs_together(model, config_path(model), self.metrics, self.history) as paths:
            save_model(paths[0])
            save_stage_params(self.stage, self.params, paths[1])
            write_json_atomic(paths[2], summary)
            write_json_atomic(paths[3], epochs)
        per_epoch = set().union(*(row.keys() for row in epochs))
        self.run.log_metrics({key: value for key, value in summary.items() if key not in per_epoch})
        self.run.log_artifact(model)
        self.run.log_artifact(config_path(model))


class StageOptions(TypedDict, total=False):
    """How a stage runs, beside what it reads and writes."""

    tracking: bool
    """Record an MLflow run (default: yes)."""
    quiet: bool
    """No progress bar (default: none)."""


class WorldModelOutputs(StageOptions):
    """The keyword arguments that every world-model stage's ``run`` takes beside its inputs."""

    out: Path
    """The model file to write."""
    metrics: Path
    """Its validation metrics (JSON)."""
    history: Path
    """Its per-epoch losses (JSON)."""


_OUTPUT_KEYS = WorldModelOutputs.__required_keys__ | WorldModelOutputs.__optional_keys__


@contextmanager
def world_model_stage(
    stage: str,
    run_name: str,
    params: Params,
    outputs: WorldModelOutputs,
    inputs: Sequence[Path] = (),
) -> Iterator[WorldModelStage]:
    """A world-model stage's run: its ``outputs`` checked writable before any work, then the
    stage's MLflow run opened (:func:`open_stage`, with ``inputs`` and the outputs locked; its
    progress bar is named ``run_name``)."""
    given, required = set(outputs), WorldModelOutputs.__required_keys__
    if not required <= given <= _OUTPUT_KEYS:
        missing, unknown = sorted(required - given), sorted(given - _OUTPUT_KEYS)
        raise TypeError(f"{stage}: missing arguments {missing}, unknown arguments {unknown}")
    model, metrics, history = outputs["out"], outputs["metrics"], outputs["history"]
    check_writable(model, config_path(model), metrics, history)
    files = {"inputs": inputs, "outputs": (model, config_path(model), metrics, history)}
    with open_stage(
        stage, run_name, params, tracking=outputs.get("tracking", True), **files
    ) as run:
        quiet = outputs.get("quiet", True)
        yield WorldModelStage(stage, run_name, run, params, model, metrics, history, quiet)


def log_torch_model(
    run: Run,
    module: torch.nn.Module,
    example: torch.Tensor,
    names: tuple[str, str],
    *,
    name: str,
    model_type: str,
    variable_axes: int = 1,
) -> None:
    """Log a CPU copy of ``module`` (one tensor in, one out: the ``served`` forms of
    :mod:`socnav_wm.worldmodel.served` and :mod:`socnav_wm.agents.served`) as the MLflow logged
    model ``name`` of the run, with the signature of ``module(example)``; ``names`` describe
    its input and output, shown beside it as the tags ``input`` and ``output``."""
    if run.run_id is None:  # tracking is off
        return
    model = copy.deepcopy(module).cpu().eval()
    example = example.cpu()
    with torch.no_grad():
        out = model(example)
    axes = ("batch", "steps")[:variable_axes]
    tags = {
        role: f"{label} ({', '.join(map(str, (*axes, *tensor.shape[variable_axes:])))}), "
        f"{str(tensor.dtype).removeprefix('torch.')}"
        for role, label, tensor in (("input", names[0], example), ("output", names[1], out))
    }
    run.log_model(
        model,
        {names[0]: example.numpy()},
        {names[1]: out.numpy()},
        name=name,
        model_type=model_type,
        tags=tags,
        variable_axes=variable_axes,
    )
