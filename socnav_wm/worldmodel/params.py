"""The world models' sections of ``params.yaml``: the VAE (``vae``), the latent LSTM (``lstm``),
the planning world model (``planning_model``) and the k-step prediction errors
(``prediction``). :mod:`socnav_wm.config` composes them into the whole file."""

from __future__ import annotations

from typing import ClassVar

from pydantic import Field, field_validator

from socnav_wm.section import Device, Section, Seed, distinct_non_negative, seed_field

__all__ = ["LstmParams", "PlanningModelParams", "PredictionParams", "VaeParams"]


class VaeParams(Section):
    """The VAE that compresses the 23-d observation into a latent vector."""

    SECTION: ClassVar[str] = "vae"

    latent_dim: int = Field(16, gt=0)
    """Size of the latent vector z."""
    hidden_dim: int = Field(256, gt=0)
    """Width of the encoder and decoder hidden layers."""
    kl_weight: float = Field(0.01, ge=0, allow_inf_nan=False)
    """Weight of the KL term against the reconstruction loss (1 is the plain ELBO, the
    paper's)."""
    learning_rate: float = Field(1e-3, gt=0, allow_inf_nan=False)
    """Adam learning rate."""
    batch_size: int = Field(512, gt=0)
    """Observations per gradient step."""
    max_epochs: int = Field(20, gt=0)
    """Upper bound on passes over the training split."""
    patience: int = Field(5, gt=0)
    """Stop after this many epochs without a better validation loss."""
    val_fraction: float = Field(0.05, gt=0, le=0.5, allow_inf_nan=False)
    """Fraction of episodes held out for validation (split by episode, never by step)."""
    device: Device = "auto"
    """`auto` uses CUDA when available, else the CPU."""


class LstmParams(Section):
    """The LSTM that predicts the next latent from the latent and the action."""

    SECTION: ClassVar[str] = "lstm"

    hidden_dim: int = Field(256, gt=0)
    """Size of the LSTM hidden and cell states."""
    seq_len: int = Field(16, ge=2)
    """Length of the training windows (steps); at least 2 to have one transition."""
    learning_rate: float = Field(1e-3, gt=0, allow_inf_nan=False)
    """Adam learning rate."""
    batch_size: int = Field(256, gt=0)
    """Windows per gradient step."""
    max_epochs: int = Field(20, gt=0)
    """Upper bound on passes over the training split."""
    patience: int = Field(5, gt=0)
    """Stop after this many epochs without a better validation loss."""
    val_fraction: float = Field(0.05, gt=0, le=0.5, allow_inf_nan=False)
    """Fraction of episodes held out for validation (split by episode, never by step)."""
    device: Device = "auto"
    """`auto` uses CUDA when available, else the CPU."""


class PlanningModelParams(Section):
    """The planning world model (socnav_wm/worldmodel/residual.py): constant velocity with the
    robot's own motion exact, plus a learned per-human correction of each human's velocity,
    trained through open-loop rollouts of ``horizon`` steps on the collected rollouts."""

    SECTION: ClassVar[str] = "planning_model"

    seeds: list[int] = Field(default_factory=lambda: [0, 1, 2], min_length=1)
    """Training seeds (initialisation, shuffles, split); one model file per seed, seed 0's plans
    for ``wm-mpc``."""
    horizon: int = Field(16, gt=0)
    """Open-loop steps in the loss (the planner looks 12 ahead)."""
    stride: int = Field(4, gt=0)
    """Steps between the starts of consecutive training samples of an episode."""
    hidden_dim: int = Field(64, gt=0)
    """Width of the correction's two hidden layers."""
    learning_rate: float = Field(3e-3, gt=0, allow_inf_nan=False)
    """Adam's first step, decayed to zero over ``max_epochs`` (cosine)."""
    batch_size: int = Field(1024, gt=0)
    """Samples per update."""
    max_epochs: int = Field(14, ge=0)
    """Epochs at most; 0 writes the untrained model, constant velocity itself (a control:
    ``wm-mpc`` on it plans as ``cv-mpc``, ``wm-mpc-q`` as ``cv-mpc`` with the critic)."""
    patience: int = Field(5, gt=0)
    """Epochs without a better validation loss before stopping (the best epoch is kept)."""
    val_fraction: float = Field(0.05, gt=0, lt=1, allow_inf_nan=False)
    """Share of the rollout episodes held out for validation."""
    relative_weight: float = Field(0.5, ge=0, le=2, allow_inf_nan=False)
    """Step ``k``'s error counts ``1 / e_k^relative_weight`` in the loss, ``e_k`` being constant
    velocity's mean error at ``k`` (0: the plain mean, which the last steps' errors, 100× the
    first ones', decide alone; 1: every step relative to constant velocity; 0.5, between them,
    is better than constant velocity far ahead and as good near it: docs/worldmodel.md)."""
    near_robot_weight: float = Field(0.0, ge=0, le=1000, allow_inf_nan=False)
    """A human within ``near_robot_distance`` of the robot at a sample's start counts ``1 +
    near_robot_weight`` times in the loss (0: every human alike): where the planner's
    collisions are decided."""
    near_robot_distance: float = Field(1.5, gt=0, le=100, allow_inf_nan=False)
    """See ``near_robot_weight`` (m, between centres)."""
    neighbours: int | None = Field(None, gt=0)
    """How many other humans each human's correction sees: the K nearest, nearest first (what a
    crowd needs: fixed slots by distance, and a cost that grows with K, not with the crowd), or
    null: every other human in spawn order (the paper preset's 3 humans)."""
    room: bool = True
    """The model knows the room: each person's features include where it is in the room and
    how far ahead the area where goals are drawn ends (the robot's pose, known to a robot with
    a map, places them); wm-mpc then needs ``planning.walls``. False: observations only."""

    @field_validator("seeds")
    @classmethod
    def _distinct_seeds(cls, value: list[int]) -> list[int]:
        return distinct_non_negative(value)


class PredictionParams(Section):
    """The ``predict`` stage (socnav_wm/worldmodel/prediction.py): each world model's k-step
    errors in metres, open loop with the true actions after a warm-up on the real trajectory,
    under the random policy and a trained agent's or a planner's ε-greedy one, on fresh
    scenarios, split by what each human met in the window."""

    SECTION: ClassVar[str] = "prediction"

    episodes: int = Field(300, gt=0)
    """Scenarios per policy."""
    scenario_seed: Seed = seed_field(2_000_003)
    """Their seed: neither a training, a validation nor the test seed."""
    warmup: int = Field(5, gt=0)
    """Real steps before each open-loop rollout."""
    horizon: int = Field(16, gt=0)
    """Steps ahead: k = 1 … horizon."""
    epsilon: float = Field(0.2, ge=0, le=1, allow_inf_nan=False)
    """Exploration of the agent's and a planner's policy (a random action with this
    probability)."""
    starts: int = Field(1, gt=0, le=64)
    """Open-loop rollouts per episode: from step ``warmup``, then every ``horizon`` steps (the
    later ones see the humans the robot meets mid-episode)."""
    interaction_distance: float = Field(1.5, gt=0, le=100, allow_inf_nan=False)
    """The split by interaction (m): a human counts as avoiding another human, meeting the
    robot (when it sees the robot) or walking around an obstacle in a window when, at some
    step of it, their centres (the obstacle's outline) are this near."""
