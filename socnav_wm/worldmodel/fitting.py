"""The one training loop of every world model (the VAE, the latent LSTM and the planning model).

Each epoch shuffles the training rows with a seeded generator, takes one optimiser step per
batch (gradient-norm clipping and a learning-rate schedule when the model asks for them),
validates, records a history row and calls the caller's ``on_epoch``; training stops once the
validation loss has not improved for ``patience`` epochs, and the weights of the best
validation epoch are restored. A NaN or infinite training loss, validation loss or weight stops
the training with one line (:class:`NonFiniteTrainingError`).

A model supplies what is its own (:class:`Fit`): its loss on a batch, its validation metrics,
and how the batch losses make the epoch's training loss.
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import torch

EpochCallback = Callable[[int, dict[str, float]], None]
"""Called after each epoch with (epoch number from 1, that epoch's metrics)."""


class NonFiniteTrainingError(ValueError):
    """A training loss or the weights became NaN or infinite; training stopped (one line)."""


def check_finite_loss(what: str, loss: float, epoch: int, batch: int | None = None) -> None:
    """Stop training at the first non-finite training (``batch`` given) or validation loss."""
    if math.isfinite(loss):
        return
    where = f"epoch {epoch}" + ("" if batch is None else f" (batch {batch})")
    kind = "training" if batch is not None else "validation"
    raise NonFiniteTrainingError(
        f"{what} training stopped: {kind} loss became {loss} at {where}; no model was written"
    )


def check_finite_weights(what: str, model: torch.nn.Module, epoch: int) -> None:
    """Stop training when any weight is NaN or infinite at the end of an epoch."""
    for name, parameter in model.named_parameters():
        if not bool(torch.isfinite(parameter).all()):
            raise NonFiniteTrainingError(
                f"{what} training stopped: weight {name} became non-finite at epoch {epoch}; "
                "no model was written"
            )


class EarlyStopping:
    """Keeps the best weights (by validation loss) and says when patience has run out."""

    def __init__(self, patience: int) -> None:
        self.patience = patience
        self.best_loss = math.inf
        self.best_epoch = 0
        self.best_state: dict[str, torch.Tensor] | None = None
        self.epochs_without_improvement = 0

    def update(self, epoch: int, val_loss: float, model: torch.nn.Module) -> bool:
        """Record an epoch; return True when training should stop."""
        if val_loss < self.best_loss:
            self.best_loss, self.best_epoch = val_loss, epoch
            self.best_state = copy.deepcopy(model.state_dict())
            self.epochs_without_improvement = 0
        else:
            self.epochs_without_improvement += 1
        return self.epochs_without_improvement >= self.patience

    def restore(self, model: torch.nn.Module) -> None:
        if self.best_state is not None:
            model.load_state_dict(self.best_state)


def weighted_mean(losses: Sequence[float], weights: Sequence[float]) -> float:
    """The epoch's training loss: the batch losses weighted by their rows (or steps)."""
    total, count = 0.0, 0.0
    for loss, weight in zip(losses, weights, strict=True):
        total += loss * weight
        count += weight
    return total / max(count, 1.0)


@dataclass
class Fit:
    """One model's training, as the loop needs it.

    Attributes:
        name: the model's name in error messages (``"VAE"``).
        model: the network (its parameters are checked, its best weights kept).
        optimizer: steps the model's parameters.
        rows: how many training rows (samples, windows) an epoch shuffles.
        batch_size: rows per step.
        generator: the seeded generator of the shuffles.
        device: where the shuffled indices go.
        batch_loss: rows (a 1-d index tensor) → (the loss to minimise, its weight in the
            epoch's training loss).
        validate: the validation metrics of the present weights, ``val_loss`` first (the one
            that decides); they go into the history rows.
        max_grad_norm: clip the gradient norm to this before each step (None: no clipping).
        scheduler: stepped after each optimiser step (a learning-rate schedule), or None.
        train_loss: the epoch's training loss from its batch losses and weights.
        validate_untrained: validate before the first epoch too: the untrained model is then
            a candidate (epoch 0, a history row without a training loss, no ``on_epoch``).
    """

    name: str
    model: torch.nn.Module
    optimizer: torch.optim.Optimizer
    rows: int
    batch_size: int
    generator: torch.Generator
    device: torch.device
    batch_loss: Callable[[torch.Tensor], tuple[torch.Tensor, float]]
    validate: Callable[[], dict[str, float]]
    max_grad_norm: float | None = None
    scheduler: Any | None = None
    train_loss: Callable[[Sequence[float], Sequence[float]], float] = weighted_mean
    validate_untrained: bool = False


@dataclass
class Fitted:
    """What :func:`fit` returns; the model itself holds the best weights, in eval mode.

    Attributes:
        history: one row per epoch: epoch (float), train_loss, the validation metrics, seconds.
        best_epoch: the epoch whose weights were kept (0: the untrained model).
        best_loss: its validation loss.
    """

    history: list[dict[str, float]] = field(default_factory=list)
    best_epoch: int = 0
    best_loss: float = math.inf


def _validate(task: Fit, epoch: int) -> dict[str, float]:
    val = task.validate()
    check_finite_loss(task.name, val["val_loss"], epoch)
    return val


def _train_epoch(task: Fit, epoch: int) -> float:
    """One pass over the shuffled training rows; the epoch's training loss."""
    task.model.train()
    losses: list[float] = []
    weights: list[float] = []
    order = torch.randperm(task.rows, generator=task.generator).to(task.device)
    for batch_number, index in enumerate(order.split(task.batch_size), start=1):
        loss, weight = task.batch_loss(index)
        loss_value = float(loss.detach())
        check_finite_loss(task.name, loss_value, epoch, batch_number)
        task.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        if task.max_grad_norm is not None:
            torch.nn.utils.clip_grad_norm_(task.model.parameters(), max_norm=task.max_grad_norm)
        task.optimizer.step()
        if task.scheduler is not None:
            task.scheduler.step()
        losses.append(loss_value)
        weights.append(weight)
    check_finite_weights(task.name, task.model, epoch)
    return task.train_loss(losses, weights)


def fit(
    task: Fit, *, max_epochs: int, patience: int, on_epoch: EpochCallback | None = None
) -> Fitted:
    """Train ``task.model`` for at most ``max_epochs`` epochs, stopping after ``patience``
    epochs without a lower validation loss; the best epoch's weights are restored.

    Raises:
        NonFiniteTrainingError: a training or validation loss, or a weight at the end of an
            epoch, is NaN or infinite (before ``on_epoch`` sees that epoch).
    """
    stopping = EarlyStopping(patience)
    history: list[dict[str, float]] = []
    if task.validate_untrained:
        started = time.perf_counter()
        val = _validate(task, 0)
        history.append(
            {"epoch": 0.0, "train_loss": math.nan, **val, "seconds": time.perf_counter() - started}
        )
        stopping.update(0, val["val_loss"], task.model)
    for epoch in range(1, max_epochs + 1):
        started = time.perf_counter()
        train_loss = _train_epoch(task, epoch)
        val = _validate(task, epoch)
        row = {
            "epoch": float(epoch),
            "train_loss": train_loss,
            **val,
            "seconds": time.perf_counter() - started,
        }
        history.append(row)
        if on_epoch is not None:
            on_epoch(epoch, dict(row))
        if stopping.update(epoch, val["val_loss"], task.model):
            break
    stopping.restore(task.model)
    task.model.eval()
    return Fitted(history=history, best_epoch=stopping.best_epoch, best_loss=stopping.best_loss)
