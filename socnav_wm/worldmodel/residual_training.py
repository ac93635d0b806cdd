"""Training the planning world model (:mod:`socnav_wm.worldmodel.residual`): samples from the
rollouts (:func:`make_sequences`), the open-loop loss and the training loop.

The model is trained through open-loop rollouts of ``horizon`` steps: the loss averages every
step's Euclidean position error, as PlaNet's overshooting and TD-MPC's latent rollouts do, on
the random-policy rollouts of ``collect``. :func:`fit_residual` is the stage's entry point; the
result is saved by :func:`socnav_wm.worldmodel.planning_file.save_residual`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from socnav_wm.data.compatibility import made_with
from socnav_wm.env.core import discrete_commands
from socnav_wm.env.params import EnvParams
from socnav_wm.resources import build_trainable
from socnav_wm.worldmodel.ego import positions
from socnav_wm.worldmodel.fitting import EpochCallback, Fit, fit
from socnav_wm.worldmodel.params import PlanningModelParams
from socnav_wm.worldmodel.planning_file import ResidualTrainResult
from socnav_wm.worldmodel.residual import ResidualDynamics, present_state


@dataclass(frozen=True)
class Sequences:
    """Training samples: the present (``obs`` after ``previous_obs`` and ``previous_action``),
    the next ``horizon`` actions and the observed positions after each (``mask``: the step
    was inside the episode)."""

    previous_obs: np.ndarray  # (N, D)
    obs: np.ndarray  # (N, D)
    previous_action: np.ndarray  # (N,)
    actions: np.ndarray  # (N, K)
    targets: np.ndarray  # (N, K, 1 + H, 2)
    mask: np.ndarray  # (N, K) bool
    pose: np.ndarray | None = None  # (N, 3) the robot's room pose at ``obs``, when known

    def __len__(self) -> int:
        return len(self.obs)


def make_sequences(
    obs: np.ndarray,
    actions: np.ndarray,
    episode_ids: np.ndarray,
    next_obs: np.ndarray,
    horizon: int,
    stride: int,
    pose_after: np.ndarray | None = None,
) -> Sequences:
    """Samples from rollout rows (in episode order): one every ``stride`` steps of an episode,
    from its second step on (a velocity needs two views), each followed up to ``horizon``
    steps or the episode's end. ``pose_after`` (rows, 3): the robot's room pose after each
    row's step (collect's ``robot_x``, ``robot_y``, ``robot_theta``); a sample's present pose
    is the one after the step before it."""
    from socnav_wm.data.windows import _episode_runs

    starts, lengths = _episode_runs(np.asarray(episode_ids))
    # Each episode's observations o_0 … o_n: its rows' obs, then its last next_obs.
    full_start = starts + np.arange(len(starts))
    full = np.empty((len(obs) + len(starts), obs.shape[1]), dtype=np.float64)
    row_pos = np.arange(len(obs)) + np.repeat(np.arange(len(starts)), lengths)
    full[row_pos] = obs
    full[full_start + lengths] = next_obs[starts + lengths - 1]
    full_actions = np.zeros(len(full), dtype=np.int64)
    full_actions[row_pos] = actions
    episode_of, t = [], []
    for e, n in enumerate(lengths):
        ts = np.arange(1, n, stride)
        episode_of.append(np.full(len(ts), e))
        t.append(ts)
    episode = np.concatenate(episode_of) if episode_of else np.zeros(0, dtype=np.int64)
    step = np.concatenate(t) if t else np.zeros(0, dtype=np.int64)
    base = full_start[episode] + step  # index of o_t
    k = np.arange(horizon)
    mask = step[:, None] + k[None, :] < lengths[episode][:, None]
    ahead = np.minimum(base[:, None] + k[None, :], (full_start + lengths)[episode][:, None] - 1)
    return Sequences(
        previous_obs=full[base - 1],
        obs=full[base],
        previous_action=full_actions[base - 1],
        actions=np.where(mask, full_actions[ahead], 0),
        targets=positions(full[ahead + 1]),
        mask=mask,
        # Row starts[e] + t holds o_t; the row before it, the pose that o_t was seen from.
        pose=None
        if pose_after is None
        else np.asarray(pose_after, dtype=np.float64)[starts[episode] + step - 1],
    )


def _step_errors(
    predicted: torch.Tensor, target: torch.Tensor, humans: torch.Tensor | None = None
) -> torch.Tensor:
    """(B, K) the humans' mean Euclidean position error (m) at each step; ``humans`` (B, H):
    each human's weight in the mean (None: alike)."""
    squared = ((predicted[:, :, 1:] - target[:, :, 1:]) ** 2).sum(-1)
    error = torch.sqrt(squared + 1e-12)
    if humans is None:
        return error.mean(-1)
    return (error * humans[:, None]).sum(-1) / humans.sum(-1, keepdim=True)


def _masked_loss(
    predicted: torch.Tensor,
    target: torch.Tensor,
    mask: torch.Tensor,
    weights: torch.Tensor | None = None,
    humans: torch.Tensor | None = None,
) -> torch.Tensor:
    """Mean Euclidean position error (m) of the humans over the real steps: the metric itself
    (a squared error rewards hedging, slowing every human down towards the mean turn, which
    raises the typical error of the many who walk straight); ``weights`` (K,): each step's
    weight; ``humans`` (B, H): each human's."""
    error = _step_errors(predicted, target, humans)
    if weights is not None:
        error = error * weights
    return (error * mask).sum() / mask.sum().clamp(min=1)


def train_residual(
    train: Sequences,
    val: Sequences,
    env_params: EnvParams,
    params: PlanningModelParams,
    *,
    seed: int,
    on_epoch: EpochCallback | None = None,
) -> ResidualTrainResult:
    """Adam on the open-loop rollout loss, its learning rate decayed to zero over
    ``max_epochs`` (cosine); the weights of the best validation epoch are kept (the untrained
    model, constant velocity, is epoch 0). ``params.room``: the model knows the room (the
    samples must carry the robot's poses). ``params.relative_weight`` ``p``: step ``k``'s error
    is weighted by ``1 / e_k^p`` (normalised to a mean of 1), where ``e_k`` is constant
    velocity's mean error at ``k`` on the training samples: with 0 the long steps' errors, 100×
    the first ones', decide alone; with 1 every step counts relative to constant velocity.
    Validation uses the plain mean (the metric). ``horizon``, ``stride`` and ``val_fraction``
    are the caller's (the samples are already made)."""
    room, relative_weight = params.room, params.relative_weight
    torch.manual_seed(seed)
    model = build_trainable(
        "planning_model.hidden_dim",
        f"the planning model (hidden_dim {params.hidden_dim})",
        lambda: ResidualDynamics(
            env_params.num_humans,
            params.hidden_dim,
            env_params.dt,
            env_params.human_max_speed,
            env_params.spawn_half_size if room else None,
            params.neighbours,
            env_params.kinematics == "holonomic",
        ),
    )
    if room and (train.pose is None or val.pose is None):
        raise ValueError("planning_model.room: the training samples carry no robot poses")
    table = torch.as_tensor(discrete_commands(env_params))

    def tensors(seqs: Sequences) -> tuple[torch.Tensor, ...]:
        points, velocity = present_state(
            seqs.previous_obs, seqs.obs, seqs.previous_action, env_params
        )
        actions = torch.as_tensor(seqs.actions)
        return (
            torch.as_tensor(points, dtype=torch.float32),
            torch.as_tensor(velocity, dtype=torch.float32),
            table[actions, 0].float(),
            table[actions, 1].float(),
            torch.as_tensor(seqs.targets, dtype=torch.float32),
            torch.as_tensor(seqs.mask, dtype=torch.float32),
            # A model that does not know the room ignores the pose (zeros when none was recorded).
            torch.as_tensor(
                np.zeros((len(seqs), 3)) if seqs.pose is None else seqs.pose, dtype=torch.float32
            ),
        )

    train_t, val_t = tensors(train), tensors(val)

    def validation_loss() -> float:
        model.eval()
        total, weight = 0.0, 0.0
        with torch.no_grad():
            for i in range(0, len(val), 4096):
                p, u, v, w, y, m, pose = (x[i : i + 4096] for x in val_t)
                predicted = model.rollout(p, u, v, w, pose)
                total += float(_masked_loss(predicted, y, m)) * float(m.sum())
                weight += float(m.sum())
        return total / max(weight, 1.0)

    weights = None
    if relative_weight:
        with torch.no_grad():
            p, u, v, w, y, m, pose = (x[:20_000] for x in train_t)
            error = _step_errors(model.rollout(p, u, v, w, pose), y)
            per_step = (error * m).sum(0) / m.sum(0).clamp(min=1)
        weights = per_step.clamp(min=1e-6) ** -relative_weight
        weights = weights / weights.mean()

    near = None
    if params.near_robot_weight:
        # In the robot's frame: a human's distance from the robot is its position's length.
        distance = torch.linalg.vector_norm(train_t[0][:, 1:], dim=-1)  # (N, H)
        near = 1.0 + params.near_robot_weight * (distance <= params.near_robot_distance)

    def batch_loss(rows: torch.Tensor) -> tuple[torch.Tensor, float]:
        p, u, v, w, y, m, pose = (x[rows] for x in train_t)
        humans = None if near is None else near[rows]
        return _masked_loss(model.rollout(p, u, v, w, pose), y, m, weights, humans), 1.0

    optimizer = torch.optim.Adam(model.parameters(), lr=params.learning_rate)
    updates = params.max_epochs * -(-len(train) // params.batch_size)
    task = Fit(
        name="planning model",
        model=model,
        optimizer=optimizer,
        rows=len(train),
        batch_size=params.batch_size,
        generator=torch.Generator().manual_seed(seed),
        device=torch.device("cpu"),
        batch_loss=batch_loss,
        validate=lambda: {"val_loss": validation_loss()},
        max_grad_norm=1.0,
        scheduler=torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, T_max=updates),
        train_loss=lambda losses, _: float(np.mean(losses)),
        validate_untrained=True,
    )

    def report(epoch: int, row: dict[str, float]) -> None:
        if on_epoch is not None:
            on_epoch(epoch, {"train_loss": row["train_loss"], "val_loss": row["val_loss"]})

    start = time.process_time()
    fitted = fit(task, max_epochs=params.max_epochs, patience=params.patience, on_epoch=report)
    history = [
        {"epoch": int(row["epoch"]), "train_loss": row["train_loss"], "val_loss": row["val_loss"]}
        for row in fitted.history
    ]
    metrics = {
        "best_epoch": fitted.best_epoch,
        "val_loss": fitted.best_loss,
        "val_loss_constant_velocity": history[0]["val_loss"],
        "epochs": len(history) - 1,
        "train_samples": len(train),
        "cpu_seconds": time.process_time() - start,
    }
    return ResidualTrainResult(
        model=model, history=history, metrics=metrics, env=made_with(env_params)
    )


def fit_residual(
    rollouts: Any,
    env_params: EnvParams,
    params: PlanningModelParams,
    *,
    seed: int,
    on_epoch: EpochCallback | None = None,
) -> ResidualTrainResult:
    """Train on the rollouts' training episodes, validate on the held-out ones (split as the
    VAE's and the LSTM's, by episode with ``seed`` and ``params.val_fraction``); the rollouts
    must have been collected in the scenarios of ``env_params``. Saved by
    :func:`socnav_wm.worldmodel.planning_file.save_residual`."""
    from socnav_wm.data.shards import column_to_numpy, read_rollouts
    from socnav_wm.data.windows import split_episodes

    horizon, stride = params.horizon, params.stride
    for name, value in (("horizon", horizon), ("stride", stride)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"{name}: expected an integer >= 1, got {value!r}")
    poses = ["robot_x", "robot_y", "robot_theta"]
    columns = ["episode_id", "obs", "action", "next_obs", *poses]
    table = read_rollouts(rollouts, columns=columns, env_params=env_params)
    ids = column_to_numpy(table, "episode_id")
    obs = column_to_numpy(table, "obs")
    actions = column_to_numpy(table, "action").astype(np.int64)
    next_obs = column_to_numpy(table, "next_obs")
    pose_after = np.stack([column_to_numpy(table, name) for name in poses], axis=-1)
    train, val = split_episodes(ids, params.val_fraction, seed)

    def sequences(rows: np.ndarray) -> Sequences:
        return make_sequences(
            obs[rows], actions[rows], ids[rows], next_obs[rows], horizon, stride, pose_after[rows]
        )

    return train_residual(
        sequences(train), sequences(val), env_params, params, seed=seed, on_epoch=on_epoch
    )
