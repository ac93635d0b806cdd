"""Hyper-parameters of the DQN agents and the variant names: a light module (no torch).

Every method's name (agents, baselines, planners) is in :mod:`socnav_wm.method_names`.

``params.yaml``'s ``agent`` section is validated into :class:`AgentParams` by
:mod:`socnav_wm.config`, and the library uses the same class, so both share one definition and
one set of one-line errors. Keeping it free of torch lets the CLI validate a configuration (and
list the variants) without the second it takes to import torch.

The paper's per-variant hyper-parameters (paper_spec §5) are the overlay ``configs/paper.yaml``:
``socnav-wm <stage> --overlay configs/paper.yaml`` (or ``load_params(overlays=[...])``) fills
:attr:`AgentParams.per_variant`, which :meth:`AgentParams.resolved` applies.
"""

from __future__ import annotations

from typing import Annotated, Any, ClassVar, Literal, Self

from pydantic import AfterValidator, BeforeValidator, Field, field_validator, model_validator

from socnav_wm.section import Device, Section, as_tuple, distinct_non_negative

VARIANT_NAMES: tuple[str, ...] = (
    "dueling-dqn",
    "wm-dueling-dqn",
    "2stepahead",
    "maspm",
    "2stepahead-maspm",
)
"""The five agent variants, in the paper's order (see :mod:`socnav_wm.agents.features`)."""

WORLD_MODEL_VARIANTS: tuple[str, ...] = VARIANT_NAMES[1:]
"""The variants that need the frozen VAE and LSTM."""


def check_variant(name: str) -> str:
    """``name`` if it is a known variant, else a one-line ValueError listing the valid names."""
    if name not in VARIANT_NAMES:
        raise ValueError(f"variant: unknown {name!r}; expected one of {', '.join(VARIANT_NAMES)}")
    return name


Optimizer = Literal["adam", "adamw"]

OPTIMIZERS: tuple[str, ...] = ("adam", "adamw")


def _in_unit(value: float) -> float:
    if not 0.0 <= value <= 1.0:
        raise ValueError(f"must be in [0, 1], got {value!r}")
    return value


def _below_one(value: float) -> float:
    if not 0.0 <= value < 1.0:
        raise ValueError(f"must be in [0, 1), got {value!r}")
    return value


def _layer_sizes(value: tuple[int, ...]) -> tuple[int, ...]:
    if not value or any(size <= 0 for size in value):
        raise ValueError(f"expected a non-empty list of positive integers, got {list(value)!r}")
    return value


Unit = Annotated[float, Field(allow_inf_nan=False), AfterValidator(_in_unit)]
"""A finite float in [0, 1]."""
LayerSizes = Annotated[tuple[int, ...], BeforeValidator(as_tuple), AfterValidator(_layer_sizes)]
"""Widths of fully connected layers: a non-empty list of positive integers."""


class AgentParams(Section):
    """Hyper-parameters of the DQN agents (``params.yaml``'s ``agent`` section).

    The values are shared by every variant, except what :attr:`per_variant` overrides for one
    (the paper's table: ``configs/paper.yaml``); :meth:`resolved` gives a variant's values.
    """

    SECTION: ClassVar[str] = "agent"

    episodes: int = Field(10_000, gt=0)
    """Training episodes (finished episodes over all environments)."""
    num_envs: int = Field(32, gt=0)
    """Environments stepped together; each vector step adds num_envs transitions."""
    gamma: Unit = 0.95
    """Discount factor per step (1 s). With the progress reward, 0.95 learned faster and better
    than the paper's 0.99 (a 20-step horizon is what avoiding a person takes)."""
    learning_rate: float = Field(5e-4, gt=0, allow_inf_nan=False)
    """Optimiser learning rate."""
    optimizer: Optimizer = "adam"
    """`adam` or `adamw` (the paper used AdamW with amsgrad for two variants)."""
    amsgrad: bool = False
    """Use the AMSGrad variant of the optimiser."""
    weight_decay: float = Field(0.0, ge=0, allow_inf_nan=False)
    """Decoupled weight decay (AdamW) or L2 penalty (Adam)."""
    batch_size: int = Field(128, gt=0)
    """Transitions per gradient update. 128 with 4 updates per vector step replays as many
    transitions as the earlier 64 with 8, in half the updates (an update of 128 costs about
    1.3× one of 64 on a CPU core: `socnav-wm bench train`)."""
    buffer_size: int = Field(100_000, gt=0)
    """Replay capacity (transitions); the oldest are overwritten."""
    learning_starts: int = 5_000
    """Transitions collected before the first gradient update (at least batch_size)."""
    n_step: int = Field(1, gt=0)
    """Steps per replayed transition: the TD target sums n discounted rewards before
    bootstrapping (1: the paper's one-step target)."""
    updates_per_step: int = Field(4, gt=0)
    """Gradient updates per vector step (updates per transition = this / num_envs)."""
    polyak: Annotated[float, Field(allow_inf_nan=False), AfterValidator(_below_one)] = 0.995
    """Target network update after every gradient step: θ′ ← polyak·θ′ + (1 − polyak)·θ."""
    epsilon_start: Unit = 1.0
    """Exploration rate of the first episodes."""
    epsilon_decay: Annotated[Unit, Field(gt=0)] = 0.995
    """ε ← max(epsilon_min, ε·epsilon_decay) once per finished episode (the paper's rule)."""
    epsilon_min: Unit = 0.05
    """Floor of the exploration rate."""
    grad_clip: float = Field(10.0, ge=0, allow_inf_nan=False)
    """Maximum global gradient norm (0 disables clipping)."""
    huber: bool = False
    """Huber (smooth L1) loss instead of the paper's mean squared TD error."""
    trunk_sizes: LayerSizes = (512, 128)
    """Widths of the Q-network's shared layers (the paper: 512, 128; also tried 128, 128)."""
    stream_size: int = Field(128, gt=0)
    """Width of the hidden layer of the value and advantage streams."""
    progress_reward: float = Field(1.0, ge=0, allow_inf_nan=False)
    """Learning-only reward per metre the robot gets closer to its goal, added to the env's
    reward (SocNavGym's distance reward, paper_spec §3.2; the paper's runs: 0, which learns
    nothing within this project's compute budget). Logged returns are always the env's."""
    bootstrap_truncation: bool = True
    """Bootstrap through time-limit truncations (true) or treat timeouts as terminal (paper)."""
    sort_humans: bool = True
    """Order the observation's humans nearest first before any variant sees it (the simulator
    lists them in spawn order; the `sort_humans` study in params.yaml measures what it is worth).
    A world model should be trained on the same order."""
    horizon: int = Field(2, gt=0)
    """Imagined steps of `2stepahead` and `2stepahead-maspm` (the paper tried 2, 4, 8, 16)."""
    maspm_hidden_features: bool = False
    """`2stepahead-maspm`: feed per-action LSTM hidden states (1040-d, the original code)
    instead of the predicted latents (80-d)."""
    carry_imagined: bool = False
    """`2stepahead`: carry the imagined LSTM state to the next real step (the original code)."""
    decode_latents: bool = True
    """World-model variants: give the Q-network each latent (the current `z` and the predicted
    ones) decoded by the VAE into observation units, 23 values each, instead of the 16-d code
    (the paper's input). The same information, in the observation's geometry."""
    solved_success_rate: Annotated[Unit, Field(gt=0)] = 0.9
    """`episodes_to_solve` is the first episode where the rolling success rate reaches this."""
    solved_window: int = Field(100, gt=0)
    """Episodes in the rolling success rate of `episodes_to_solve`."""
    checkpoint_every: int = Field(1000, gt=0)
    """Write a resumable checkpoint every this many finished episodes."""
    eval_episodes: int = Field(500, gt=0)
    """Scenarios of the greedy check at the end of training (validation scenarios, neither
    training nor test ones)."""
    select_every: int = Field(1000, ge=0)
    """Every this many episodes, and at the end, run the current network greedily on
    `select_episodes` selection scenarios (their own seed: neither training, validation nor test
    ones) and keep the weights that succeed most often (ties: the later). 0: keep the final
    weights (the paper's way)."""
    select_episodes: int = Field(500, gt=0)
    """Selection scenarios of each of those greedy runs."""
    device: Device = "auto"
    """`auto` uses CUDA when available, else the CPU."""
    per_variant: dict[str, dict[str, Any]] = Field(default_factory=dict)
    """Per-variant overrides of the fields above, e.g. `maspm: {gamma: 0.98}` (empty: every
    variant uses the shared values). `configs/paper.yaml` holds the paper's table."""

    @model_validator(mode="after")
    def _consistent(self) -> Self:
        if self.epsilon_min > self.epsilon_start:
            raise ValueError(
                f"epsilon_min: must be <= epsilon_start ({self.epsilon_start}), "
                f"got {self.epsilon_min!r}"
            )
        if self.buffer_size < self.batch_size:
            raise ValueError(
                f"buffer_size: must be >= batch_size ({self.batch_size}), got {self.buffer_size}"
            )
        if self.buffer_size < self.num_envs:
            raise ValueError(
                f"buffer_size: must be >= num_envs ({self.num_envs}), got {self.buffer_size}"
            )
        if not self.batch_size <= self.learning_starts <= self.buffer_size:
            raise ValueError(
                f"learning_starts: must be between batch_size ({self.batch_size}) and "
                f"buffer_size ({self.buffer_size}), got {self.learning_starts}"
            )
        self._check_overrides("per_variant", VARIANT_NAMES, "variant")
        return self

    def resolved(self, variant: str) -> AgentParams:
        """The values a run of ``variant`` uses: ``self`` with ``per_variant[variant]`` applied
        (and ``per_variant`` emptied); ``self`` itself when ``per_variant`` is empty."""
        check_variant(variant)
        return self._overridden("per_variant", variant)


def known_distinct_variants(value: list[str]) -> list[str]:
    """``value`` if every name is a variant and none is listed twice, else a ValueError."""
    for name in value:
        if name not in VARIANT_NAMES:
            raise ValueError(f"unknown {name!r}; expected some of {', '.join(VARIANT_NAMES)}")
    if len(set(value)) != len(value):
        raise ValueError(f"a variant is listed twice in {value}")
    return value


class ExperimentParams(Section):
    """Which agents the pipeline trains: every variant × every seed (``dvc.yaml``'s matrix)."""

    SECTION: ClassVar[str] = "experiment"

    variants: list[str] = Field(default_factory=lambda: list(VARIANT_NAMES), min_length=1)
    """Agent variants to train and evaluate (socnav_wm/agents/params.py lists them)."""
    seeds: list[int] = Field(default_factory=lambda: [0, 1, 2], min_length=1)
    """Training seeds of every variant; results are reported over seeds and scenarios."""

    @field_validator("variants")
    @classmethod
    def _known_variants(cls, value: list[str]) -> list[str]:
        return known_distinct_variants(value)

    @field_validator("seeds")
    @classmethod
    def _distinct_seeds(cls, value: list[int]) -> list[int]:
        return distinct_non_negative(value)
