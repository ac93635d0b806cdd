"""Hyper-parameters of the DQN agents and the variant names: a light module (no torch).

``params.yaml``'s ``agent`` section is validated into :class:`AgentParams` by
:mod:`pipeline.config`, and the library uses the same class, so both share one definition and
one set of one-line errors. Keeping it free of torch lets the CLI validate a configuration (and
list the variants) without the second it takes to import torch.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import asdict, dataclass, fields
from typing import Any, Literal

from pydantic import ConfigDict

VARIANT_NAMES: tuple[str, ...] = (
    "dueling-dqn",
    "wm-dueling-dqn",
    "2stepahead",
    "maspm",
    "2stepahead-maspm",
)
"""The five agent variants, in the paper's order (see :mod:`pipeline.agents.features`)."""

WORLD_MODEL_VARIANTS: tuple[str, ...] = VARIANT_NAMES[1:]
"""The variants that need the frozen VAE and LSTM."""

BASELINE_NAMES: tuple[str, ...] = ("orca", "sfm")
"""The two classic controllers evaluated next to the agents (:mod:`pipeline.agents.baselines`)."""

METHOD_NAMES: tuple[str, ...] = (*VARIANT_NAMES, *BASELINE_NAMES)
"""Every evaluated method: the agents (paper order), then the baselines. Listed here, in a
module without torch, so that the configuration can check method names cheaply."""


def check_variant(name: str) -> str:
    """``name`` if it is a known variant, else a one-line ValueError listing the valid names."""
    if name not in VARIANT_NAMES:
        raise ValueError(f"variant: unknown {name!r}; expected one of {', '.join(VARIANT_NAMES)}")
    return name


Preset = Literal["shared", "paper"]
Optimizer = Literal["adam", "adamw"]
DeviceName = Literal["auto", "cpu", "cuda"]

PRESETS: tuple[str, ...] = ("shared", "paper")
OPTIMIZERS: tuple[str, ...] = ("adam", "adamw")
DEVICES: tuple[str, ...] = ("auto", "cpu", "cuda")
UpdateBackend = Literal["torch", "native"]
UPDATE_BACKENDS: tuple[str, ...] = ("torch", "native")


@dataclass(frozen=True)
class AgentParams:
    """Hyper-parameters of the DQN agents (``params.yaml``'s ``agent`` section).

    The defaults are the ``shared`` set, used for every variant. ``preset: paper`` replaces the
    fields of :data:`PAPER_PRESET` by the paper's per-variant values (see :meth:`resolved`).
    """

    # Unknown keys are an error when pydantic validates this dataclass inside params.yaml.
    __pydantic_config__ = ConfigDict(extra="forbid")

    preset: Preset = "shared"
    """`shared`: these values for every variant; `paper`: paper_spec §5's per-variant table."""
    episodes: int = 10_000
    """Training episodes (finished episodes over all environments)."""
    num_envs: int = 32
    """Environments stepped together; each vector step adds num_envs transitions."""
    gamma: float = 0.95
    """Discount factor per step (1 s). With the progress reward, 0.95 learned faster and better
    than the paper's 0.99 (a 20-step horizon is what avoiding a person takes)."""
    learning_rate: float = 5e-4
    """Optimiser learning rate."""
    optimizer: Optimizer = "adam"
    """`adam` or `adamw` (the paper used AdamW with amsgrad for two variants)."""
    amsgrad: bool = False
    """Use the AMSGrad variant of the optimiser."""
    weight_decay: float = 0.0
    """Decoupled weight decay (AdamW) or L2 penalty (Adam)."""
    batch_size: int = 64
    """Transitions per gradient update."""
    buffer_size: int = 100_000
    """Replay capacity (transitions); the oldest are overwritten."""
    learning_starts: int = 5_000
    """Transitions collected before the first gradient update (at least batch_size)."""
    n_step: int = 1
    """Steps per replayed transition: the TD target sums n discounted rewards before
    bootstrapping (1: the paper's one-step target)."""
    updates_per_step: int = 8
    """Gradient updates per vector step (updates per transition = this / num_envs)."""
    polyak: float = 0.995
    """Target network update after every gradient step: θ′ ← polyak·θ′ + (1 − polyak)·θ."""
    epsilon_start: float = 1.0
    """Exploration rate of the first episodes."""
    epsilon_decay: float = 0.995
    """ε ← max(epsilon_min, ε·epsilon_decay) once per finished episode (the paper's rule)."""
    epsilon_min: float = 0.05
    """Floor of the exploration rate."""
    grad_clip: float = 10.0
    """Maximum global gradient norm (0 disables clipping)."""
    huber: bool = False
    """Huber (smooth L1) loss instead of the paper's mean squared TD error."""
    trunk_sizes: tuple[int, ...] = (512, 128)
    """Widths of the Q-network's shared layers (the paper: 512, 128; also tried 128, 128)."""
    stream_size: int = 128
    """Width of the hidden layer of the value and advantage streams."""
    progress_reward: float = 1.0
    """Learning-only reward per metre the robot gets closer to its goal, added to the env's
    reward (SocNavGym's distance reward, paper_spec §3.2; the paper's runs: 0, which learns
    nothing within this project's compute budget). Logged returns are always the env's."""
    bootstrap_truncation: bool = True
    """Bootstrap through time-limit truncations (true) or treat timeouts as terminal (paper)."""
    sort_humans: bool = True
    """Order the observation's humans nearest first before any variant sees it (the simulator
    lists them in spawn order). The single largest gain measured: greedy success 66% → 83%
    after 4000 episodes of `dueling-dqn`. A world model should be trained on the same order."""
    horizon: int = 2
    """Imagined steps of `2stepahead` and `2stepahead-maspm` (the paper tried 2, 4, 8, 16)."""
    maspm_hidden_features: bool = False
    """`2stepahead-maspm`: feed per-action LSTM hidden states (1040-d, the original code)
    instead of the predicted latents (80-d)."""
    carry_imagined: bool = False
    """`2stepahead`: carry the imagined LSTM state to the next real step (the original code)."""
    decode_latents: bool = False
    """World-model variants: give the Q-network each latent (the current `z` and the predicted
    ones) decoded by the VAE into observation units, 23 values each, instead of the 16-d code
    (the paper's input). The same information, in the observation's geometry."""
    solved_success_rate: float = 0.9
    """`episodes_to_solve` is the first episode where the rolling success rate reaches this."""
    solved_window: int = 100
    """Episodes in the rolling success rate of `episodes_to_solve`."""
    checkpoint_every: int = 1000
    """Write a resumable checkpoint every this many finished episodes."""
    eval_episodes: int = 500
    """Scenarios of the greedy check at the end of training (validation scenarios, neither
    training nor test ones)."""
    select_every: int = 0
    """Every this many episodes, and at the end, run the current network greedily on
    `select_episodes` selection scenarios (their own seed: neither training, validation nor test
    ones) and keep the weights that succeed most often (ties: the later). 0: keep the final
    weights (the paper's way)."""
    select_episodes: int = 500
    """Selection scenarios of each of those greedy runs."""
    device: DeviceName = "auto"
    """`auto` uses CUDA when available, else the CPU."""
    update_backend: UpdateBackend = "torch"
    """How a gradient update is computed: `torch` (PyTorch operations, any device) or `native`
    (one call of a compiled C kernel, CPU only, about twice as fast at batch 64: README
    "Speed"). The two round differently, so a training changes with the backend; the shipped
    runs use `torch`."""

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.type in ("int", "float") and (
                isinstance(value, bool) or not isinstance(value, int | float)
            ):
                raise ValueError(f"agent.{f.name}: expected a number, got {value!r}")
            if f.type == "int" and not float(value).is_integer():
                raise ValueError(f"agent.{f.name}: expected an integer, got {value!r}")
            if f.type == "bool" and not isinstance(value, bool):
                raise ValueError(f"agent.{f.name}: expected true or false, got {value!r}")
            if f.type == "float" and not math.isfinite(value):
                raise ValueError(f"agent.{f.name}: must be finite, got {value!r}")
        for name, choices in (
            ("preset", PRESETS),
            ("optimizer", OPTIMIZERS),
            ("device", DEVICES),
            ("update_backend", UPDATE_BACKENDS),
        ):
            if getattr(self, name) not in choices:
                raise ValueError(
                    f"agent.{name}: must be one of {', '.join(choices)}, "
                    f"got {getattr(self, name)!r}"
                )
        positive = (
            "episodes", "num_envs", "learning_rate", "batch_size", "buffer_size", "n_step",
            "updates_per_step", "epsilon_decay", "stream_size", "horizon", "solved_success_rate",
            "solved_window", "checkpoint_every", "eval_episodes", "select_episodes",
        )  # fmt: skip
        for name in positive:
            if getattr(self, name) <= 0:
                raise ValueError(f"agent.{name}: must be > 0, got {getattr(self, name)!r}")
        for name in ("weight_decay", "grad_clip", "progress_reward", "select_every"):
            if getattr(self, name) < 0:
                raise ValueError(f"agent.{name}: must be >= 0, got {getattr(self, name)!r}")
        unit = ("gamma", "epsilon_decay", "solved_success_rate", "epsilon_start", "epsilon_min")
        for name in unit:
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"agent.{name}: must be in [0, 1], got {getattr(self, name)!r}")
        if not 0.0 <= self.polyak < 1.0:
            raise ValueError(f"agent.polyak: must be in [0, 1), got {self.polyak!r}")
        if self.epsilon_min > self.epsilon_start:
            raise ValueError(
                f"agent.epsilon_min: must be <= epsilon_start ({self.epsilon_start}), "
                f"got {self.epsilon_min!r}"
            )
        if self.buffer_size < self.batch_size:
            raise ValueError(
                f"agent.buffer_size: must be >= batch_size ({self.batch_size}), "
                f"got {self.buffer_size}"
            )
        if self.buffer_size < self.num_envs:
            raise ValueError(
                f"agent.buffer_size: must be >= num_envs ({self.num_envs}), got {self.buffer_size}"
            )
        if not self.batch_size <= self.learning_starts <= self.buffer_size:
            raise ValueError(
                f"agent.learning_starts: must be between batch_size ({self.batch_size}) and "
                f"buffer_size ({self.buffer_size}), got {self.learning_starts}"
            )
        sizes = self.trunk_sizes
        if (
            not isinstance(sizes, tuple | list)
            or not sizes
            or any(isinstance(s, bool) or not isinstance(s, int) or s <= 0 for s in sizes)
        ):
            raise ValueError(
                f"agent.trunk_sizes: expected a non-empty list of positive integers, got {sizes!r}"
            )
        # A list from YAML becomes a tuple, so the frozen dataclass stays hashable.
        object.__setattr__(self, "trunk_sizes", tuple(sizes))

    def to_dict(self) -> dict[str, Any]:
        values = asdict(self)
        values["trunk_sizes"] = list(self.trunk_sizes)
        return values

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> AgentParams:
        """Build from a mapping, naming any unknown key in the error."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"agent: unknown option(s) {', '.join(unknown)}")
        return cls(**values)

    def resolved(self, variant: str) -> AgentParams:
        """The values a run of ``variant`` uses: ``self``, or with the paper's table applied."""
        check_variant(variant)
        if self.preset == "shared":
            return self
        return dataclasses.replace(self, **PAPER_PRESET[variant])


_PAPER_COMMON: dict[str, Any] = {
    "learning_rate": 1e-4,
    "batch_size": 64,
    "learning_starts": 64,
    "grad_clip": 0.5,
    "huber": False,
    "trunk_sizes": (512, 128),
    "stream_size": 128,
    "progress_reward": 0.0,
    "n_step": 1,
    "sort_humans": False,
    "decode_latents": False,
}
_PAPER_ADAM: dict[str, Any] = {"optimizer": "adam", "amsgrad": False, "weight_decay": 0.0}
# torch.optim.AdamW's default weight decay, which the paper's code left in place.
_PAPER_ADAMW: dict[str, Any] = {"optimizer": "adamw", "amsgrad": True, "weight_decay": 0.01}
_PAPER_VANILLA: dict[str, Any] = {
    "gamma": 0.99,
    "buffer_size": 200_000,
    "polyak": 0.995,
    "epsilon_start": 1.0,
    "epsilon_decay": 0.995,
    "epsilon_min": 0.01,
}
_PAPER_MASPM: dict[str, Any] = {
    "gamma": 0.98,
    "buffer_size": 1_000_000,
    "polyak": 0.99,
    "epsilon_start": 1.0,
    "epsilon_decay": 0.998,
    "epsilon_min": 0.01,
}
PAPER_PRESET: dict[str, dict[str, Any]] = {
    "dueling-dqn": {**_PAPER_COMMON, **_PAPER_ADAM, **_PAPER_VANILLA},
    "wm-dueling-dqn": {**_PAPER_COMMON, **_PAPER_ADAMW, **_PAPER_VANILLA},
    "2stepahead": {
        **_PAPER_COMMON,
        **_PAPER_ADAMW,
        **_PAPER_VANILLA,
        "epsilon_decay": 0.9995,
        "epsilon_min": 0.1,
    },
    "maspm": {**_PAPER_COMMON, **_PAPER_ADAM, **_PAPER_MASPM},
    # ADTSPHSM waited for 2 batches before its first update.
    "2stepahead-maspm": {**_PAPER_COMMON, **_PAPER_ADAM, **_PAPER_MASPM, "learning_starts": 128},
}
"""Per-variant values of paper_spec §5's table (and its update rule: lr 1e-4, batch 64, first
update once the buffer holds a batch, gradient-norm clip 0.5, MSE loss, 512-128 trunk; and the
paper's reward alone: no progress reward). Run scale
(``episodes``, ``num_envs``, ``updates_per_step``) and the bug-compatibility flags
(``bootstrap_truncation``, ``carry_imagined``, ``maspm_hidden_features``) are not part of the
preset: the paper's exact setting is additionally ``num_envs: 1``, ``updates_per_step: 1``,
``episodes: 200000``, ``bootstrap_truncation: false``, ``carry_imagined: true``,
``maspm_hidden_features: true``, and ``select_every: 0`` (the final weights)."""
