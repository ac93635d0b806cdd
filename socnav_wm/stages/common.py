"""What every stage does around its work: open the MLflow run with the params it reads, save
those params beside its outputs, and log per-epoch or per-episode curves."""

from __future__ import annotations

import copy
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import torch

from socnav_wm.config import STAGE_SECTIONS, Params, params_dict, save_resolved, select_sections
from socnav_wm.io import outputs_together, write_json_atomic
from socnav_wm.tracking import Run, stage_run


@contextmanager
def open_stage(
    stage: str, run_name: str, params: Params, *, tracking: bool = True
) -> Iterator[Run]:
    """The MLflow run of one stage invocation, logging the sections the stage reads."""
    logged = select_sections(params_dict(params), STAGE_SECTIONS[stage])
    with stage_run(run_name, logged, enabled=tracking) as run:
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


def world_model_outputs(
    stage: str,
    run: Run,
    params: Params,
    save_model: Callable[[Path], None],
    model: Path,
    metrics: Path,
    history: Path,
    summary: dict[str, float],
    epochs: list[dict[str, float]],
) -> None:
    """A world-model stage's outputs, published together: the model (``save_model(path)``), the
    params it read, the metrics and the per-epoch history (JSON); then logged to MLflow with
    the final metrics (without the per-epoch series, so their curves stay clean)."""
    with outputs_together(model, config_path(model), metrics, history) as paths:
        save_model(paths[0])
        save_stage_params(stage, params, paths[1])
        write_json_atomic(paths[2], summary)
        write_json_atomic(paths[3], epochs)
    per_epoch = set().union(*(row.keys() for row in epochs))
    run.log_metrics({key: value for key, value in summary.items() if key not in per_epoch})
    run.log_artifact(model)
    run.log_artifact(config_path(model))


def log_torch_model(
    run: Run,
    module: torch.nn.Module,
    inputs: Mapping[str, torch.Tensor],
    output_names: Sequence[str],
) -> None:
    """Log a CPU copy of ``module`` in MLflow's PyTorch format (the run's ``model`` artifact),
    with the signature of ``module(*inputs.values())``: the example ``inputs`` by name, and the
    outputs (a tensor, or the first elements of a tuple) named ``output_names``."""
    if run.run_id is None:  # tracking is off
        return
    model = copy.deepcopy(module).cpu().eval()
    with torch.no_grad():
        out = model(*inputs.values())
    out = out if isinstance(out, tuple) else (out,)
    run.log_model(
        model,
        {name: tensor.cpu().numpy() for name, tensor in inputs.items()},
        {name: tensor.numpy() for name, tensor in zip(output_names, out, strict=False)},
    )
