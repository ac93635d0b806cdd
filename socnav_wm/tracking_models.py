"""MLflow logged models: a stage's torch module as a logged model of its run (MLflow 3), and
the experiment's description, which names them.

:meth:`socnav_wm.tracking.Run.log_model` calls :func:`log_logged_model`; like
:mod:`socnav_wm.tracking`, this module imports mlflow only inside its functions.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import Any

DESCRIPTION_TAG = "mlflow.note.content"
"""The tag MLflow's UI shows as an experiment's or a run's description."""
HEADLINE_TAG = "headline_metrics"
EXPERIMENT_DESCRIPTION = (
    "socnav-wm: predictive world models for social robot navigation. One run per stage "
    "invocation (tag `stage`; dvc.yaml runs them). Each run's description and its "
    "`headline_metrics` tag name the metrics to compare first: an evaluation's success, "
    "human_collision, discomfort and simulation_time (means over the test scenarios; "
    "`*_ci_low` / `*_ci_high` are their 95% interval bounds), a training's final validation "
    "loss or greedy success rate. Every training's network is a logged model of its run "
    "(the Models tab): `mlflow.pyfunc.load_model('models:/<model id>').predict(array)`."
)
"""What MLflow's UI shows as the experiment's description."""

_MAX_PARAM_VALUE = 500
"""MLflow's most conservative limit on a param value (older servers)."""

Examples = tuple[Mapping[str, Any], Mapping[str, Any], int]
"""A model's example inputs and outputs (numpy arrays by name) and how many of their leading
dimensions may vary (1: the batch; 2: the batch and the steps of a sequence)."""


def model_requirements() -> list[str]:
    """What a logged model needs to load: torch, numpy and this package (its modules are
    pickled by reference: ``pip install -e .`` of this repository), at the versions here."""
    import numpy
    import torch

    from socnav_wm import __version__

    return [
        f"torch=={torch.__version__.split('+')[0]}",
        f"numpy=={numpy.__version__}",
        f"socnav-wm=={__version__}",
    ]


def signature(inputs: Mapping[str, Any], outputs: Mapping[str, Any], variable_axes: int) -> Any:
    """The MLflow signature of the example arrays: their dtypes, and their shapes with the
    first ``variable_axes`` dimensions free. One input (one output) is an unnamed tensor, so
    that ``mlflow.pyfunc``'s ``predict`` hands a numpy array to ``forward`` as it is."""
    import numpy as np
    from mlflow.models import ModelSignature
    from mlflow.types import Schema, TensorSpec

    def schema(arrays: Mapping[str, Any]) -> Any:
        named = len(arrays) > 1
        specs = []
        for key, value in arrays.items():
            array = np.asarray(value)
            shape = (-1,) * variable_axes + tuple(array.shape[variable_axes:])
            specs.append(TensorSpec(array.dtype, shape, key if named else None))
        return Schema(specs)

    return ModelSignature(schema(inputs), schema(outputs))


def log_logged_model(
    client: Any,
    run_id: str,
    module: Any,
    examples: Examples,
    *,
    name: str,
    model_type: str | None,
    tags: Mapping[str, str],
) -> str:
    """Log ``module`` as the logged model ``name`` of run ``run_id`` (through ``client``, an
    ``MlflowClient``), in MLflow's PyTorch format; returns its id.

    The model carries the run's params, ``tags``, ``model_type``, the signature of
    ``examples`` and, linked by MLflow, the run's metrics logged at step 0 (the final ones).
    """
    import mlflow.pytorch
    from mlflow.tracking._tracking_service.utils import _use_tracking_uri

    run = client.get_run(run_id)
    params = {key: value[:_MAX_PARAM_VALUE] for key, value in run.data.params.items()}
    # Pickle, not MLflow's pt2 graph (traced at the example's fixed batch size): the module is
    # the pipeline's own, so its warning on loading untrusted pickles is left out here.
    pytorch_log = logging.getLogger("mlflow.pytorch")
    level = pytorch_log.level
    pytorch_log.setLevel(logging.ERROR)
    try:
        # mlflow.pytorch.log_model writes through MLflow's global client: it is pointed at this
        # run's store for the call only.
        with _use_tracking_uri(client.tracking_uri):
            model = client.create_logged_model(
                run.info.experiment_id,
                name=name,
                source_run_id=run_id,
                params=params,
                tags=dict(tags),
                model_type=model_type,
            )
            mlflow.pytorch.log_model(
                module,
                name=name,
                signature=signature(*examples),
                input_example=None,
                # Given, not inferred: inferring would load the model in a subprocess.
                pip_requirements=model_requirements(),
                serialization_format="pickle",  # the nn.Module, as load_model returns it
                run_id=run_id,
                model_id=model.model_id,  # links the run to it, and its step-0 metrics
            )
    finally:
        pytorch_log.setLevel(level)
    return model.model_id
