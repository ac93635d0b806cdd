"""Double Dueling DQN on the batched simulator: the update rule, the training loop,
checkpoints, agent files, greedy evaluation and a speed benchmark (hyper-parameters:
:mod:`pipeline.agents.params`).

The loop (:func:`train_agent`) reads top to bottom, cleanrl-style: act ε-greedily on
``num_envs`` environments at once → step the simulator → compute the next features (the
variant's business, :mod:`pipeline.agents.features`) → store the transitions → sample → Double-DQN
target → loss → optimiser step → Polyak target update. It knows nothing about variants beyond
``variant.reset`` / ``variant.step`` and the feature size.

Decisions that differ from the paper's code (paper_spec §5, §8), each documented where it lives:

* **Time limits bootstrap** (``bootstrap_truncation=True``): the observation carries no clock,
  so the 201-step limit is not a property of the state; treating it as terminal (the paper)
  teaches the network that ordinary mid-room states are worth ≈ −1 (Pardo et al., 2018, "Time
  Limits in Reinforcement Learning"). The episode's reward is unchanged (a timeout still pays −1),
  only the target bootstraps from the final observation. ``bootstrap_truncation=False`` is the
  paper's choice.
* **One shared hyper-parameter set** for all variants, so that they are compared fairly; the
  ``paper`` preset restores the per-variant table of paper_spec §5
  (:data:`pipeline.agents.params.PAPER_PRESET`).
* **Model selection** (``select_every`` > 0; off in the library's defaults, on in
  ``params.yaml``): every ``select_every`` episodes and at the end, the current network runs
  greedily on held-out selection scenarios, and the agent keeps the weights that succeeded most
  often. The paper keeps the last weights, which with ε-greedy DQN are one draw from a
  fluctuating sequence. The greedy check after training and the test evaluation use other
  scenarios, so their numbers are not biased by the choice.
* Many environments are stepped together; ε still decays once per *finished episode*, as in the
  paper, so the schedule is in episodes whatever ``num_envs`` is.
"""

from __future__ import annotations

import copy
import hashlib
import json
import random
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import torch
import torch.nn.functional as F

from pipeline.agents.dueling import DuelingQNetwork
from pipeline.agents.features import VARIANTS, Variant, make_variant
from pipeline.agents.params import AgentParams, check_variant
from pipeline.agents.replay import Batch, NStepAccumulator, ReplayBuffer
from pipeline.env.core import NUM_ACTIONS, Simulator, StepResult
from pipeline.env.params import EnvParams
from pipeline.env.state import COLLISION_HUMAN, COLLISION_NAMES, COLLISION_WALL, BatchState
from pipeline.io import atomic_path, first_line, load_saved
from pipeline.progress import progress
from pipeline.worldmodel.lstm import LatentLSTM
from pipeline.worldmodel.training import load_lstm, load_vae, resolve_device
from pipeline.worldmodel.vae import VAE

AGENT_FORMAT = "socnav-wm-agent"
CHECKPOINT_FORMAT = "socnav-wm-agent-checkpoint"
AGENT_FORMAT_VERSION = 1
CHECKPOINT_FORMAT_VERSION = 3
"""2: the optimiser steps one flat buffer of weights (version 1 had one tensor per layer).
3: the model selection's greedy runs and best weights (``agent.select_every``)."""


def goal_distances(obs: np.ndarray) -> np.ndarray:
    """Robot–goal centre distances (N,) in metres from observations (N, obs_dim).

    The observation starts with the goal's position in the robot frame (paper_spec §2).
    """
    return np.hypot(obs[:, 0], obs[:, 1]).astype(np.float64)


def training_env_seed(seed: int) -> int:
    """Simulator seed of the training scenarios of run ``seed`` (distinct from test seeds).

    Derived through a SeedSequence so that training scenarios never coincide with the
    evaluation's scenarios, which use the plain test seed.
    """
    return int(np.random.SeedSequence([seed, 0x50C1A1]).generate_state(1)[0])


def _next_multiple(done: int, every: int) -> int:
    """The first multiple of ``every`` above ``done`` (when the next periodic event is due)."""
    return (done // every + 1) * every


def episodes_to_solve(success: Sequence[bool] | np.ndarray, window: int, rate: float) -> int | None:
    """First episode (1-based) at which the mean success of the last ``window`` episodes
    reaches ``rate``; None if it never does. Needs ``window`` complete episodes.

    The paper's "solved in about 3200 episodes" is never defined (paper_spec §8.18); this is the
    project's definition.
    """
    s = np.asarray(success, dtype=np.float64)
    if s.size < window:
        return None
    rolling = np.convolve(s, np.ones(window), mode="valid") / window  # rolling[i] ends at i+window
    hits = np.flatnonzero(rolling >= rate - 1e-12)
    return int(hits[0] + window) if hits.size else None


# =============================================================================================
# The learner: network, target network, optimiser, update rule
# =============================================================================================


def double_dqn_targets(
    rewards: torch.Tensor,
    terminals: torch.Tensor,
    next_q_online: torch.Tensor,
    next_q_target: torch.Tensor,
    discounts: torch.Tensor | float,
) -> torch.Tensor:
    """``y = r + γᵏ·Q_target(s′, argmax_a Q_online(s′, a))·(1 − terminal)``.

    Args:
        rewards, terminals: (batch,); terminals is 1 where nothing is bootstrapped.
        next_q_online, next_q_target: (batch, actions), the two networks' Q-values at s′.
        discounts: γᵏ, (batch,) or one number (γ for one-step transitions).

    Returns:
        (batch,) TD targets. The online network picks the action, the target network values it,
        which removes most of DQN's over-estimation (van Hasselt et al., 2016).
    """
    best = next_q_online.argmax(dim=1, keepdim=True)
    next_value = next_q_target.gather(1, best).squeeze(1)
    return rewards + discounts * next_value * (1.0 - terminals)


def flat_views(flat: torch.Tensor, params: Sequence[torch.Tensor]) -> list[torch.Tensor]:
    """Consecutive slices of the 1-d ``flat``, shaped like ``params`` (views, no copies)."""
    views, offset = [], 0
    for param in params:
        views.append(flat[offset : offset + param.numel()].view_as(param))
        offset += param.numel()
    return views


def flatten_parameters(module: torch.nn.Module) -> torch.Tensor:
    """Move every parameter of ``module`` into one contiguous buffer; returns the buffer.

    Each parameter becomes a view of its slice, so the module computes as before while
    element-wise work over all of its weights (optimiser step, gradient norm, Polyak averaging)
    is one call on one tensor instead of one per layer: on the CPU, per-tensor dispatch was a
    large share of an update of these small networks.
    """
    params = list(module.parameters())
    flat = torch.cat([param.detach().reshape(-1) for param in params])
    for param, view in zip(params, flat_views(flat, params), strict=True):
        param.data = view
    return flat


class DQNLearner:
    """Online and target Q-networks, the optimiser and one gradient update.

    The online network's parameters, their gradients and the target network's parameters each
    live in one flat buffer (:func:`flatten_parameters`); the optimiser steps the flat buffer.
    The modules still see ordinary parameters (views), so ``state_dict`` and agent files are
    unchanged.
    """

    def __init__(self, feature_dim: int, params: AgentParams, device: torch.device) -> None:
        if params.update_backend == "native" and device.type != "cpu":
            raise ValueError(
                f"agent.update_backend: native runs on the CPU, got device {device.type} "
                "(set agent.device: cpu, or update_backend: torch)"
            )
        self.params = params
        self.device = device
        self.q_network = DuelingQNetwork(
            feature_dim, NUM_ACTIONS, params.trunk_sizes, params.stream_size
        ).to(device)
        self.target_network = copy.deepcopy(self.q_network).requires_grad_(False)
        self._weights = flatten_parameters(self.q_network)
        self._target_weights = flatten_parameters(self.target_network)
        # Each parameter's .grad is a view of one buffer, which the backward pass overwrites.
        self._grads = torch.zeros_like(self._weights)
        online = list(self.q_network.parameters())
        for param, view in zip(online, flat_views(self._grads, online), strict=True):
            param.grad = view
        self._weights.grad = self._grads
        optimizer_type = torch.optim.AdamW if params.optimizer == "adamw" else torch.optim.Adam
        self.optimizer = optimizer_type(
            [self._weights],
            lr=params.learning_rate,
            amsgrad=params.amsgrad,
            weight_decay=params.weight_decay,
            # The fused kernel does Adam's element-wise algebra in one pass over the buffer.
            fused=device.type in ("cpu", "cuda"),
        )
        self._native = None
        if params.update_backend == "native":
            from pipeline.agents.native import NativeUpdate

            self._native = NativeUpdate(self)

    @torch.no_grad()
    def act(self, features: torch.Tensor, epsilon: float, rng: np.random.Generator) -> np.ndarray:
        """ε-greedy actions (N,) for features (N, feature_dim).

        Both random draws are made every step whatever ε is, so the generator's stream (and a
        resumed run) does not depend on the outcomes.
        """
        n = features.shape[0]
        explore = rng.random(n) < epsilon
        random_actions = rng.integers(0, NUM_ACTIONS, size=n)
        greedy = self.q_network(features).argmax(dim=1).cpu().numpy()
        return np.where(explore, random_actions, greedy)

    @torch.no_grad()
    def update(self, batch: Batch) -> torch.Tensor:
        """One gradient step on a batch, then the Polyak target update; returns the loss.

        The gradient comes from the network's hand-written backward pass
        (:meth:`DuelingQNetwork.backward_cached`, tested against autograd), straight into the
        flat gradient buffer. The online network reads ``s`` and ``s′`` in one pass of twice
        the batch (each example's row is computed on its own, so the Q-values are those of two
        passes; ``tests/agents/test_dqn.py`` checks the whole update against the textbook one),
        and the backward pass uses the ``s`` half of its activations.

        With ``update_backend: native`` the same update is one call of a compiled kernel
        (:class:`pipeline.agents.native.NativeUpdate`).
        """
        if self._native is not None:
            return self._native(batch)
        p = self.params
        n = batch.features.shape[0]
        q_both, cache = self.q_network.forward_cached(
            torch.cat((batch.features, batch.next_features))
        )
        q_values = q_both[:n]
        targets = double_dqn_targets(
            batch.rewards,
            batch.terminals,
            q_both[n:],
            self.target_network(batch.next_features),
            batch.discounts,
        )
        taken = batch.actions.unsqueeze(1)
        error = q_values.gather(1, taken).squeeze(1) - targets
        # The loss is the mean over the batch of ℓ(error); d(loss)/d(error) by hand.
        if p.huber:  # smooth L1 with β = 1
            loss = F.smooth_l1_loss(error, torch.zeros_like(error))
            grad_error = error.clamp(-1.0, 1.0) / error.numel()
        else:
            loss = error.square().mean()
            grad_error = error * (2.0 / error.numel())
        grad_q = torch.zeros_like(q_values).scatter_(1, taken, grad_error.unsqueeze(1))
        self.q_network.backward_cached(cache.head(n), grad_q)
        if p.grad_clip > 0:
            # clip_grad_norm_ on the one buffer: scale by min(1, max_norm / (‖g‖ + 1e-6)).
            norm = torch.linalg.vector_norm(self._grads)
            scale = (p.grad_clip / (norm + 1e-6)).clamp_(max=1.0)
            # A scale of exactly 1 changes nothing (a NaN norm still poisons every gradient, as
            # in clip_grad_norm_). On the CPU, reading the scale is free and skipping the pass
            # over the buffer saves up to a tenth of an update (README, "Speed"); on a GPU the
            # read would wait for the device, so the multiplication is always queued there.
            if self.device.type != "cpu" or scale.item() != 1.0:
                self._grads.mul_(scale)
        self.optimizer.step()
        # θ′ ← θ′ + (1 − p)(θ − θ′) = p·θ′ + (1 − p)·θ, the whole network in one call.
        self._target_weights.lerp_(self._weights, 1.0 - p.polyak)
        return loss

    def weights(self) -> torch.Tensor:
        """A copy of the online network's weights, as one flat tensor."""
        return self._weights.detach().clone()

    def load_weights(self, flat: torch.Tensor) -> None:
        """Give the online network the weights of :meth:`weights` (target and optimiser stay)."""
        self._weights.copy_(flat)

    def state_dict(self) -> dict[str, Any]:
        return {
            "q_network": self.q_network.state_dict(),
            "target_network": self.target_network.state_dict(),
            "optimizer": self.optimizer.state_dict(),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.q_network.load_state_dict(state["q_network"])
        self.target_network.load_state_dict(state["target_network"])
        self.optimizer.load_state_dict(state["optimizer"])


# =============================================================================================
# Training
# =============================================================================================

EpisodeCallback = Callable[[list[dict[str, Any]]], None]
"""Receives the rows of the episodes that finished in the last vector step."""

EPISODE_COLUMNS = (
    "episode",
    "scenario_id",
    "return",
    "length",
    "success",
    "collision",
    "human_collision",
    "wall_collision",
    "timeout",
    "epsilon",
    "env_steps",
    "updates",
    "wall_time",
)
"""Keys of a training-log row (one per finished episode)."""


@dataclass
class TrainResult:
    """Outcome of :func:`train_agent`.

    Attributes:
        q_network: the trained online network (eval mode).
        variant: the variant's name.
        params: the resolved hyper-parameters (after the preset).
        env_params: the training scenario parameters.
        seed: the run's seed.
        episodes: one row per training episode (keys :data:`EPISODE_COLUMNS`): ``episode``
            (1-based), ``return`` (sum of env rewards), ``length`` (steps), ``success``,
            ``collision`` (any), ``human_collision``, ``wall_collision``, ``timeout``,
            ``epsilon`` (ε while it ran), ``env_steps`` and ``updates`` (totals when it ended),
            ``wall_time`` (s since the start of training, resumed runs included).
        episodes_to_solve: see :func:`episodes_to_solve`; None if never reached.
        env_steps, updates: totals over the run.
        wall_time: seconds of training (over all sessions of a resumed run).
        vae, lstm: the frozen world model (None for ``dueling-dqn``), saved with the agent.
        selection: with ``select_every`` > 0, one ``{"episode", "success_rate"}`` per greedy run
            on the selection scenarios; empty otherwise.
        selected_episode: the episode after which ``q_network``'s weights were taken (the best
            greedy run, ties to the later); None without selection (the final weights).
    """

    q_network: DuelingQNetwork
    variant: str
    params: AgentParams
    env_params: EnvParams
    seed: int
    episodes: list[dict[str, Any]]
    episodes_to_solve: int | None
    env_steps: int
    updates: int
    wall_time: float
    vae: VAE | None = None
    lstm: LatentLSTM | None = None
    selection: list[dict[str, Any]] = field(default_factory=list)
    selected_episode: int | None = None


def variant_for(
    name: str,
    vae: VAE | None,
    lstm: LatentLSTM | None,
    params: AgentParams,
    *,
    obs_dim: int,
    device: torch.device | str,
) -> Variant:
    """The variant ``name`` with the feature options of ``params``."""
    return make_variant(
        name,
        vae,
        lstm,
        obs_dim=obs_dim,
        device=device,
        horizon=params.horizon,
        hidden_features=params.maspm_hidden_features,
        carry_imagined=params.carry_imagined,
        sort_humans=params.sort_humans,
        decode_latents=params.decode_latents,
    )


def load_world_model(
    variant: str,
    vae_path: str | Path | None,
    lstm_path: str | Path | None,
    device: torch.device | str,
) -> tuple[VAE | None, LatentLSTM | None]:
    """The frozen VAE and LSTM a variant needs (None, None for ``dueling-dqn``)."""
    if not VARIANTS[check_variant(variant)].needs_world_model:
        return None, None
    if vae_path is None or lstm_path is None:
        raise ValueError(f"variant {variant!r} needs the VAE and LSTM files (got no path)")
    return load_vae(vae_path, device), load_lstm(lstm_path, device)


class VectorStep(NamedTuple):
    """One step of every environment, finished episodes restarted (:func:`step_and_restart`)."""

    result: StepResult
    done: np.ndarray  # (N,) bool: the episode ended (terminated or truncated)
    finished_scenarios: np.ndarray  # scenario ids of the episodes that ended, in env order
    first_obs: np.ndarray | None  # (k, obs_dim) the new episodes' first observations (or None)
    next_features: torch.Tensor  # (N, feature_dim) features of result.obs (the replay's s′)
    features: torch.Tensor  # (N, feature_dim) features to act on next (new episodes' t = 0)


def step_and_restart(sim: Simulator, features_of: Variant, actions: np.ndarray) -> VectorStep:
    """Step ``sim`` with ``actions``, start a new episode in every env whose episode ended, and
    advance the variant's world-model state over both (what the training loop and
    ``socnav-wm bench train`` do each vector step)."""
    result = sim.step(actions)
    done = result.terminated | result.truncated
    finished_scenarios = sim.state.scenario_id[done].copy()
    reset_obs = None
    if done.any():
        sim.reset_envs(done)
        reset_obs = sim.observation[done]
    next_features, features = features_of.step(
        result.obs, actions, reset_mask=done, reset_obs=reset_obs
    )
    return VectorStep(result, done, finished_scenarios, reset_obs, next_features, features)


def _seed_everything(seed: int) -> None:
    # cleanrl's seeding block. The loop itself draws only from explicit numpy Generators (the
    # project never uses numpy's legacy global generator); torch's global generator seeds the
    # network initialisation, Python's anything a library might draw.
    random.seed(seed)
    torch.manual_seed(seed)


def _sim_state_dict(sim: Simulator) -> dict[str, Any]:
    return {
        "state": {
            f.name: torch.from_numpy(getattr(sim.state, f.name).copy()) for f in fields(BatchState)
        },
        "seed": sim.seed,
        "next_scenario": sim.next_scenario,
    }


def _load_sim_state(sim: Simulator, state: dict[str, Any]) -> None:
    for f in fields(BatchState):
        getattr(sim.state, f.name)[...] = state["state"][f.name].numpy()
    sim.seed = int(state["seed"])
    sim.next_scenario = int(state["next_scenario"])


def _global_rng_state() -> dict[str, Any]:
    return {"python": random.getstate(), "torch": torch.get_rng_state()}


def _load_global_rng_state(state: dict[str, Any]) -> None:
    random.setstate(state["python"])
    torch.set_rng_state(state["torch"])


def _file_digest(path: str | Path | None) -> str | None:
    if path is None:
        return None
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return None  # load_world_model reports the missing file


def run_identity(
    variant: str,
    params: AgentParams,
    env_params: EnvParams,
    seed: int,
    vae_path: str | Path | None = None,
    lstm_path: str | Path | None = None,
) -> dict[str, Any]:
    """What makes two training runs the same run: a checkpoint resumes only its own run.

    ``params`` are resolved for the variant (the ``paper`` preset applied); the world model
    enters by the content of its files, so retraining the VAE or LSTM invalidates checkpoints.
    The checkpoint format version is part of it too: a checkpoint written by an older version
    of this code has another file name, and a run started by newer code begins afresh.
    """
    p = params.resolved(variant)
    world = VARIANTS[check_variant(variant)].needs_world_model
    return {
        "checkpoint_format": CHECKPOINT_FORMAT_VERSION,
        "variant": variant,
        "params": p.to_dict(),
        "env_params": env_params.to_dict(),
        "seed": seed,
        "world_model": {
            "vae": _file_digest(vae_path) if world else None,
            "lstm": _file_digest(lstm_path) if world else None,
        },
    }


def checkpoint_file(directory: str | Path, identity: dict[str, Any]) -> Path:
    """``{directory}/{variant}/seed-{seed}-{digest}.ckpt``: one file per distinct run, so a
    changed parameter never resumes (or overwrites) another run's checkpoint."""
    digest = hashlib.sha256(json.dumps(identity, sort_keys=True).encode()).hexdigest()[:12]
    return Path(directory) / identity["variant"] / f"seed-{identity['seed']}-{digest}.ckpt"


def _load_checkpoint(path: Path, identity: dict[str, Any]) -> dict[str, Any]:
    payload = load_saved(path, "agent checkpoint", CHECKPOINT_FORMAT, CHECKPOINT_FORMAT_VERSION)
    saved = payload["run"]
    for key in ("variant", "seed", "params", "env_params", "world_model"):
        if saved.get(key) != identity[key]:
            differing = key
            if isinstance(saved.get(key), dict):
                names = sorted(k for k in identity[key] if saved[key].get(k) != identity[key][k])
                differing = ", ".join(f"{key}.{name}" for name in names)
            raise ValueError(
                f"{path}: checkpoint of a different run ({differing} differs); "
                "delete it or train without --resume"
            )
    return payload


def train_agent(
    variant: str,
    params: AgentParams,
    env_params: EnvParams,
    vae_path: str | Path | None,
    lstm_path: str | Path | None,
    *,
    seed: int,
    checkpoint_path: str | Path | None = None,
    resume: bool = False,
    on_episodes: EpisodeCallback | None = None,
    quiet: bool = True,
) -> TrainResult:
    """Train one variant with one seed; see the module docstring for the loop.

    Args:
        variant: one of :data:`~pipeline.agents.features.VARIANTS`.
        params: hyper-parameters (the ``paper`` preset is applied here).
        env_params: training scenarios; the simulator seed is :func:`training_env_seed`.
        vae_path, lstm_path: the frozen world model (unused, may be None, for ``dueling-dqn``).
        seed: seeds the network initialisation, exploration, replay sampling and scenarios.
        checkpoint_path: where a resumable checkpoint is written every
            ``params.checkpoint_every`` episodes and at the end (None: no checkpoints).
        resume: continue from ``checkpoint_path`` if it exists (else start afresh). A resumed
            run ends with exactly the weights of an uninterrupted one.
        on_episodes: called after each vector step in which episodes finished, with their rows.
        quiet: no progress bar.
    """
    check_variant(variant)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"seed: expected a non-negative integer, got {seed!r}")
    p = params.resolved(variant)
    device = resolve_device(p.device)
    vae, lstm = load_world_model(variant, vae_path, lstm_path, device)
    identity = run_identity(variant, p, env_params, seed, vae_path, lstm_path)
    checkpoint_path = Path(checkpoint_path) if checkpoint_path is not None else None

    # -- seeding: one generator per purpose, all derived from `seed` -------------------------
    _seed_everything(seed)
    explore_seed, replay_seed = np.random.SeedSequence(seed).spawn(2)
    explore_rng = np.random.default_rng(explore_seed)

    # -- the pieces --------------------------------------------------------------------------
    sim = Simulator(p.num_envs, env_params)
    features_of = variant_for(variant, vae, lstm, p, obs_dim=sim.obs_dim, device=device)
    learner = DQNLearner(features_of.feature_dim, p, device)
    replay = ReplayBuffer(p.buffer_size, features_of.feature_dim, device, seed=replay_seed)
    accumulator = NStepAccumulator(p.num_envs, features_of.feature_dim, p.n_step, p.gamma)

    obs, _ = sim.reset(seed=training_env_seed(seed))
    features = features_of.reset(obs)
    goal_distance = goal_distances(obs)
    episode_return = np.zeros(p.num_envs)
    episode_length = np.zeros(p.num_envs, dtype=np.int64)
    epsilon = p.epsilon_start
    rows: list[dict[str, Any]] = []
    env_steps = updates = 0
    elapsed_before = 0.0  # wall time of earlier sessions of a resumed run
    # Model selection (select_every > 0): greedy runs on held-out scenarios, the best weights.
    selection: list[dict[str, Any]] = []
    best_weights: torch.Tensor | None = None

    def save_checkpoint() -> None:
        payload = {
            "format": CHECKPOINT_FORMAT,
            "format_version": CHECKPOINT_FORMAT_VERSION,
            "run": identity,
            "learner": learner.state_dict(),
            "replay": replay.state_dict(),
            "n_step": accumulator.state_dict(),
            "variant_state": features_of.state_dict(),
            "features": features.cpu().clone(),
            "episode_return": torch.from_numpy(episode_return.copy()),
            "episode_length": torch.from_numpy(episode_length.copy()),
            "goal_distance": torch.from_numpy(goal_distance.copy()),
            "sim": _sim_state_dict(sim),
            "rng": {"explore": explore_rng.bit_generator.state, **_global_rng_state()},
            "counters": {
                "epsilon": epsilon,
                "env_steps": env_steps,
                "updates": updates,
                "wall_time": elapsed_before + time.perf_counter() - start,
            },
            "rows": rows,
            "selection": {"runs": selection, "best_weights": best_weights},
        }
        with atomic_path(checkpoint_path) as tmp:
            torch.save(payload, tmp)

    if resume and checkpoint_path is not None and checkpoint_path.exists():
        saved = _load_checkpoint(checkpoint_path, identity)
        learner.load_state_dict(saved["learner"])
        replay.load_state_dict(saved["replay"])
        accumulator.load_state_dict(saved["n_step"])
        features_of.load_state_dict(saved["variant_state"])
        features = saved["features"].to(device)
        episode_return = saved["episode_return"].numpy().copy()
        episode_length = saved["episode_length"].numpy().copy()
        goal_distance = saved["goal_distance"].numpy().copy()
        _load_sim_state(sim, saved["sim"])
        explore_rng.bit_generator.state = saved["rng"]["explore"]
        _load_global_rng_state(saved["rng"])
        counters = saved["counters"]
        epsilon = float(counters["epsilon"])
        env_steps, updates = int(counters["env_steps"]), int(counters["updates"])
        elapsed_before = float(counters["wall_time"])
        rows = list(saved["rows"])
        selection = list(saved["selection"]["runs"])
        best_weights = saved["selection"]["best_weights"]
        if best_weights is not None:
            best_weights = best_weights.to(device)

    def select() -> None:
        """Run the current network greedily on the selection scenarios; keep it if best."""
        nonlocal best_weights
        greedy = Agent(learner.q_network, features_of, p, env_params)  # acts on its own copies
        runs = evaluate_agent(
            greedy, env_params, seed=selection_seed(seed), scenario_ids=np.arange(p.select_episodes)
        )
        selection.append(
            {"episode": len(rows), "success_rate": float(np.mean([r["success"] for r in runs]))}
        )
        if best_selection_run(selection) is selection[-1]:
            best_weights = learner.weights()

    start = time.perf_counter()
    next_checkpoint = _next_multiple(len(rows), p.checkpoint_every)
    next_selection = _next_multiple(len(rows), p.select_every) if p.select_every else 0
    solved_at: int | None = None
    with progress(p.episodes, f"train-agent {variant}", quiet=quiet, unit="episodes") as bar:
        bar.advance(min(len(rows), p.episodes))
        while len(rows) < p.episodes:
            # -- act and step ----------------------------------------------------------------
            actions = learner.act(features, epsilon, explore_rng)
            result, done, scenario_ids, first_obs, next_features, new_features = step_and_restart(
                sim, features_of, actions
            )

            # -- store -----------------------------------------------------------------------
            terminal = result.terminated if p.bootstrap_truncation else done
            next_distance = goal_distances(result.obs)
            learning_reward = result.reward + p.progress_reward * (goal_distance - next_distance)
            replay.add(
                *accumulator.push(features, actions, learning_reward, next_features, terminal, done)
            )
            features = new_features
            goal_distance = next_distance
            if first_obs is not None:
                goal_distance[done] = goal_distances(first_obs)
            env_steps += p.num_envs
            episode_return += result.reward
            episode_length += 1

            # -- learn -----------------------------------------------------------------------
            if len(replay) >= p.learning_starts:
                for _ in range(p.updates_per_step):
                    learner.update(replay.sample(p.batch_size))
                    updates += 1

            # -- finished episodes: log rows, decay ε ----------------------------------------
            if done.any():
                now = elapsed_before + time.perf_counter() - start
                collision = result.info["collision"]
                finished = []
                for slot_index, env in enumerate(np.flatnonzero(done)):
                    if len(rows) + len(finished) >= p.episodes:
                        break
                    finished.append(
                        {
                            "episode": len(rows) + len(finished) + 1,
                            "scenario_id": int(scenario_ids[slot_index]),
                            "return": float(episode_return[env]),
                            "length": int(episode_length[env]),
                            "success": bool(result.info["success"][env]),
                            "collision": bool(collision[env] != 0),
                            "human_collision": bool(collision[env] == COLLISION_HUMAN),
                            "wall_collision": bool(collision[env] == COLLISION_WALL),
                            "timeout": bool(result.truncated[env]),
                            "epsilon": float(epsilon),
                            "env_steps": env_steps,
                            "updates": updates,
                            "wall_time": now,
                        }
                    )
                episode_return[done] = 0.0
                episode_length[done] = 0
                epsilon = max(p.epsilon_min, epsilon * p.epsilon_decay ** int(done.sum()))
                rows.extend(finished)
                bar.advance(len(finished))
                if on_episodes is not None and finished:
                    on_episodes(finished)
                recent = [row["success"] for row in rows[-p.solved_window :]]
                bar.set_postfix(success=float(np.mean(recent)), epsilon=epsilon)
                # Before the checkpoint, so that a checkpoint holds every run up to its episode.
                if p.select_every and (len(rows) >= next_selection or len(rows) >= p.episodes):
                    select()
                    next_selection = _next_multiple(len(rows), p.select_every)
                if checkpoint_path is not None and len(rows) >= next_checkpoint:
                    if len(rows) < p.episodes:
                        save_checkpoint()
                    next_checkpoint = _next_multiple(len(rows), p.checkpoint_every)

    wall_time = elapsed_before + time.perf_counter() - start
    if checkpoint_path is not None:
        save_checkpoint()  # the finished run: resuming it just returns this result
    selected = best_selection_run(selection)
    if best_weights is not None:  # the weights of `selected`
        learner.load_weights(best_weights)
    solved_at = episodes_to_solve(
        [row["success"] for row in rows], p.solved_window, p.solved_success_rate
    )
    learner.q_network.eval()
    return TrainResult(
        q_network=learner.q_network,
        variant=variant,
        params=p,
        env_params=env_params,
        seed=seed,
        episodes=rows,
        episodes_to_solve=solved_at,
        env_steps=env_steps,
        updates=updates,
        wall_time=wall_time,
        vae=vae,
        lstm=lstm,
        selection=selection,
        selected_episode=selected["episode"] if selected is not None else None,
    )


# =============================================================================================
# Agent files, greedy acting and evaluation
# =============================================================================================


class AgentFileError(ValueError):
    """An agent file is missing, unreadable or not an agent (one-line message)."""


@dataclass
class Agent:
    """A trained agent ready to act greedily: its Q-network and its variant (with world model).

    Attributes:
        q_network: the Dueling Q-network (eval mode).
        variant: the feature builder (holds the frozen VAE + LSTM; its per-env state is used by
            :meth:`policy` copies, not by :meth:`act`).
        params: the hyper-parameters it was trained with.
        env_params: the scenario parameters it was trained on.
        extra: what was saved alongside (seed, episodes_to_solve, …).
    """

    q_network: DuelingQNetwork
    variant: Variant
    params: AgentParams
    env_params: EnvParams
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def variant_name(self) -> str:
        return self.variant.name

    @property
    def device(self) -> torch.device:
        return self.variant.device

    @torch.no_grad()
    def act(self, features: torch.Tensor) -> torch.Tensor:
        """Greedy actions (N,) int64 for features (N, feature_dim)."""
        return self.q_network(features).argmax(dim=1)

    def fresh_variant(self) -> Variant:
        """A new feature builder sharing the frozen world model, with its own per-env state."""
        v = self.variant
        return variant_for(v.name, v.vae, v.lstm, self.params, obs_dim=v.obs_dim, device=v.device)

    def policy(self) -> Callable[[np.ndarray], np.ndarray]:
        """A greedy policy ``obs (N, obs_dim) → actions (N,)`` for episodes that start together.

        It keeps its own world-model state: the first call starts every env's episode, each
        later call is the next step of the same episodes (what
        :func:`pipeline.env.rollout.run_episodes` does; finished slots are simply carried along).
        """
        features_of = self.fresh_variant()
        last_actions: list[np.ndarray] = []

        def act(obs: np.ndarray) -> np.ndarray:
            if not last_actions:
                features = features_of.reset(obs)
            else:
                features, _ = features_of.step(obs, last_actions[0])
            actions = self.act(features).cpu().numpy()
            last_actions[:] = [actions]
            return actions

        return act


def _world_model_payload(model: torch.nn.Module | None) -> dict[str, Any] | None:
    if model is None:
        return None
    return {
        "hyperparameters": model.hyperparameters(),  # type: ignore[operator]
        "state_dict": {k: v.detach().cpu() for k, v in model.state_dict().items()},
    }


def save_agent(path: str | Path, result: TrainResult, extra: dict[str, Any] | None = None) -> None:
    """Write a trained agent to ``path`` atomically: Q-network, variant settings, parameters,
    and the frozen VAE + LSTM weights, so the file evaluates on its own and can never be paired
    with another world model by mistake.
    """
    payload = {
        "format": AGENT_FORMAT,
        "format_version": AGENT_FORMAT_VERSION,
        "variant": result.variant,
        "params": result.params.to_dict(),
        "env_params": result.env_params.to_dict(),
        "q_network": {
            "hyperparameters": result.q_network.hyperparameters(),
            "state_dict": {k: v.detach().cpu() for k, v in result.q_network.state_dict().items()},
        },
        "vae": _world_model_payload(result.vae),
        "lstm": _world_model_payload(result.lstm),
        "extra": {
            "seed": result.seed,
            "episodes_to_solve": result.episodes_to_solve,
            "env_steps": result.env_steps,
            "updates": result.updates,
            "wall_time": result.wall_time,
            **(extra or {}),
        },
    }
    with atomic_path(path) as tmp:
        torch.save(payload, tmp)


def load_agent(path: str | Path, device: torch.device | str = "cpu") -> Agent:
    """Load an agent written by :func:`save_agent`, on ``device`` (``auto``/``cpu``/``cuda``).

    Raises:
        AgentFileError: one line naming the file when it is missing, unreadable, not an agent
            file, of another format version, or when its weights do not fit.
    """
    path = Path(path)
    payload = load_saved(path, "agent file", AGENT_FORMAT, AGENT_FORMAT_VERSION, AgentFileError)
    target = resolve_device(device)
    try:
        params = AgentParams.from_dict(payload["params"])
        env_params = EnvParams.from_dict(payload["env_params"])
        q_network = DuelingQNetwork(**payload["q_network"]["hyperparameters"])
        q_network.load_state_dict(payload["q_network"]["state_dict"])
        world: dict[str, torch.nn.Module | None] = {}
        for name, model_type in (("vae", VAE), ("lstm", LatentLSTM)):
            saved = payload[name]
            world[name] = None
            if saved is not None:
                model = model_type(**saved["hyperparameters"])
                model.load_state_dict(saved["state_dict"])
                world[name] = model
        variant = variant_for(
            payload["variant"],
            world["vae"],  # type: ignore[arg-type]
            world["lstm"],  # type: ignore[arg-type]
            params,
            obs_dim=env_params_obs_dim(env_params),
            device=target,
        )
    except (KeyError, TypeError, ValueError, RuntimeError) as exc:
        raise AgentFileError(f"{path}: agent does not load ({first_line(exc)})") from exc
    if variant.feature_dim != q_network.input_dim:
        raise AgentFileError(
            f"{path}: the Q-network reads {q_network.input_dim} features, "
            f"variant {variant.name!r} gives {variant.feature_dim}"
        )
    return Agent(
        q_network=q_network.to(target).eval(),
        variant=variant,
        params=params,
        env_params=env_params,
        extra=dict(payload.get("extra") or {}),
    )


def agent_from_result(result: TrainResult) -> Agent:
    """The :class:`Agent` of a finished training run (without going through a file)."""
    device = next(result.q_network.parameters()).device
    p = result.params
    variant = variant_for(
        result.variant,
        result.vae,
        result.lstm,
        p,
        obs_dim=env_params_obs_dim(result.env_params),
        device=device,
    )
    return Agent(result.q_network.eval(), variant, p, result.env_params, {"seed": result.seed})


def env_params_obs_dim(env_params: EnvParams) -> int:
    """Size of the observation for these scenario parameters (2 + 7 per human)."""
    return 2 + 7 * env_params.num_humans


EVAL_COLUMNS = ("scenario_id", "return", "length", "success", "collision", "timeout")
"""Keys of an evaluation row; ``collision`` is ``"none"``, ``"human"`` or ``"wall"``."""


def evaluate_agent(
    agent: Agent,
    env_params: EnvParams,
    *,
    seed: int,
    scenario_ids: Sequence[int] | np.ndarray,
    batch_size: int = 500,
) -> list[dict[str, Any]]:
    """Greedy (ε = 0) episodes of scenarios ``scenario_ids`` of ``seed``, one row each.

    Episodes run in batches of ``batch_size`` environments; each env keeps its scenario to the
    end (no resets), so the result depends only on (agent, env_params, seed, scenario ids).
    Returns rows with the keys :data:`EVAL_COLUMNS`, in the order of ``scenario_ids``.
    """
    ids = np.asarray(scenario_ids, dtype=np.int64)
    rows: list[dict[str, Any]] = []
    for start in range(0, ids.size, batch_size):
        chunk = ids[start : start + batch_size]
        sim = Simulator(chunk.size, env_params)
        obs, _ = sim.reset(seed=seed, scenario_ids=chunk)
        act = agent.policy()
        total = np.zeros(chunk.size)
        length = np.zeros(chunk.size, dtype=np.int64)
        success = np.zeros(chunk.size, dtype=bool)
        collision = np.zeros(chunk.size, dtype=np.int8)
        timeout = np.zeros(chunk.size, dtype=bool)
        while not sim.state.done.all():
            result = sim.step(act(obs))
            obs = result.obs
            active = result.info["active"]
            total += np.where(active, result.reward, 0.0)
            length += active
            success |= result.info["success"]
            collision = np.where(active, result.info["collision"], collision)
            timeout |= result.truncated
        for i, scenario in enumerate(chunk):
            rows.append(
                {
                    "scenario_id": int(scenario),
                    "return": float(total[i]),
                    "length": int(length[i]),
                    "success": bool(success[i]),
                    "collision": COLLISION_NAMES[int(collision[i])],
                    "timeout": bool(timeout[i]),
                }
            )
    return rows


def write_training_log(rows: Sequence[dict[str, Any]], path: str | Path) -> None:
    """The training log (one row per episode, :data:`EPISODE_COLUMNS`) as Parquet, atomically."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.table({name: [row[name] for row in rows] for name in EPISODE_COLUMNS})
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp, compression="zstd")


def validation_seed(seed: int) -> int:
    """Simulator seed of the greedy check at the end of training run ``seed``: scenarios that are
    neither the run's training scenarios nor any evaluation's test scenarios."""
    return int(np.random.SeedSequence([seed, 0x7A11D]).generate_state(1)[0])


def selection_seed(seed: int) -> int:
    """Simulator seed of the model selection of training run ``seed`` (``select_every``): its
    own scenarios, so that the greedy check on :func:`validation_seed`'s scenarios and the test
    evaluation stay unbiased by the choice."""
    return int(np.random.SeedSequence([seed, 0x5E1EC7]).generate_state(1)[0])


def best_selection_run(selection: Sequence[dict[str, Any]]) -> dict[str, Any] | None:
    """The model selection's greedy run whose weights are kept: the highest success rate, the
    later run on ties; None before any run."""
    return max(reversed(selection), key=lambda run: run["success_rate"], default=None)


def training_metrics(result: TrainResult, greedy: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Summary of a training run: totals, the last episodes' rates, the model selection (None
    without it; its best rate is biased upwards by the choice) and the greedy check."""
    last = result.episodes[-result.params.solved_window :]
    selected = best_selection_run(result.selection)
    return {
        "episodes": len(result.episodes),
        "episodes_to_solve": result.episodes_to_solve,
        "env_steps": result.env_steps,
        "updates": result.updates,
        "wall_time_s": result.wall_time,
        "env_steps_per_s": result.env_steps / max(result.wall_time, 1e-9),
        "final_success_rate": float(np.mean([row["success"] for row in last])),
        "final_return": float(np.mean([row["return"] for row in last])),
        "selected_episode": result.selected_episode,
        "selected_success_rate": selected["success_rate"] if selected is not None else None,
        "greedy_episodes": len(greedy),
        "greedy_success_rate": float(np.mean([row["success"] for row in greedy])),
        "greedy_collision_rate": float(np.mean([row["collision"] != "none" for row in greedy])),
        "greedy_timeout_rate": float(np.mean([row["timeout"] for row in greedy])),
    }
