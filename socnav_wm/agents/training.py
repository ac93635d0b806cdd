"""Double Dueling DQN training on the batched simulator (hyper-parameters:
:mod:`socnav_wm.agents.params`; the update: :mod:`socnav_wm.agents.learner`).

The loop (:func:`train_agent`) reads top to bottom, cleanrl-style: act ε-greedily on
``num_envs`` environments at once → step the simulator → compute the next features (the
variant's business, :mod:`socnav_wm.agents.features`) → store the transitions → sample → update.
It knows nothing about variants beyond ``variant.reset`` / ``variant.step`` and the feature size.
Everything the loop changes lives in one :class:`TrainState`, so a checkpoint is one
``state_dict()`` saved and one ``load_state_dict()`` read (:mod:`socnav_wm.agents.checkpoint`),
and a resumed run ends with exactly the weights of an uninterrupted one.

Decisions that differ from the paper's code (paper_spec §5, §8), each documented where it lives:

* **Time limits bootstrap** (``bootstrap_truncation=True``): the observation carries no clock,
  so the 201-step limit is not a property of the state; treating it as terminal (the paper)
  teaches the network that ordinary mid-room states are worth ≈ −1 (Pardo et al., 2018, "Time
  Limits in Reinforcement Learning"). The episode's reward is unchanged (a timeout still pays −1),
  only the target bootstraps from the final observation.
* **One shared hyper-parameter set** for all variants, so that they are compared fairly; the
  overlay ``configs/paper.yaml`` restores the per-variant table of paper_spec §5
  (``agent.per_variant``).
* **Model selection** (``select_every`` > 0): every ``select_every`` episodes and at the end,
  the current network runs greedily on held-out selection scenarios, and the agent keeps the
  weights that succeeded most often. The paper keeps the last weights, which with ε-greedy DQN
  are one draw from a fluctuating sequence. The greedy check after training and the test
  evaluation use other scenarios, so their numbers are not biased by the choice.
* Many environments are stepped together; ε still decays once per *finished episode*, as in the
  paper, so the schedule is in episodes whatever ``num_envs`` is.
"""

from __future__ import annotations

import random
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import torch

from socnav_wm.agents.agent_file import (
    TrainResult,
    load_world_model,
    variant_for,
)
from socnav_wm.agents.checkpoint import (
    UnreadableCheckpoint,
    load_checkpoint,
    run_identity,
    save_checkpoint,
    set_aside,
)
from socnav_wm.agents.features import Variant
from socnav_wm.agents.learner import DQNLearner
from socnav_wm.agents.memory import GREEDY_BATCH, training_needs
from socnav_wm.agents.params import AgentParams
from socnav_wm.agents.replay import NStepAccumulator, ReplayBuffer
from socnav_wm.devices import resolve_device
from socnav_wm.env.core import Simulator, StepResult
from socnav_wm.env.episode import Episode
from socnav_wm.env.observation_layout import observation_size
from socnav_wm.env.params import EnvParams
from socnav_wm.env.state import COLLISION_HUMAN, COLLISION_WALL, BatchState
from socnav_wm.env.wrappers import goal_distance, progress_shaping
from socnav_wm.io import atomic_path
from socnav_wm.metrics import episodes_to_solve
from socnav_wm.progress import progress
from socnav_wm.resources import check_fits_together
from socnav_wm.worldmodel.fitting import NonFiniteTrainingError

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


# -- seeds of the scenario sets of a run ------------------------------------------------------


def training_env_seed(seed: int) -> int:
    """Simulator seed of the training scenarios of run ``seed`` (distinct from test seeds)."""
    return int(np.random.SeedSequence([seed, 0x50C1A1]).generate_state(1)[0])


def validation_seed(seed: int) -> int:
    """Simulator seed of the greedy check at the end of training run ``seed``: scenarios that are
    neither the run's training scenarios nor any evaluation's test scenarios."""
    return int(np.random.SeedSequence([seed, 0x7A11D]).generate_state(1)[0])


def selection_seed(seed: int) -> int:
    """Simulator seed of the model selection of training run ``seed`` (``select_every``): its
    own scenarios, so that the greedy check on :func:`validation_seed`'s scenarios and the test
    evaluation stay unbiased by the choice."""
    return int(np.random.SeedSequence([seed, 0x5E1EC7]).generate_state(1)[0])


# -- small pure helpers -----------------------------------------------------------------------


def best_selection_run(selection: Sequence[dict[str, Any]]) -> dict[str, Any] | None:
    """The model selection's greedy run whose weights are kept: the highest success rate, the
    later run on ties; None before any run."""
    return max(reversed(selection), key=lambda run: run["success_rate"], default=None)


def success_rate(episodes: Sequence[Episode]) -> float:
    return float(np.mean([e.success for e in episodes]))


def greedy_success_rate(
    q_network: torch.nn.Module,
    variant: Variant,
    env_params: EnvParams,
    *,
    seed: int,
    episodes: int,
    batch_size: int = GREEDY_BATCH,
) -> float:
    """Success rate of the greedy policy on scenarios ``0..episodes-1`` of ``seed``: what
    :func:`greedy_episodes` gives (the same scenarios, ``batch_size`` started together, the same
    simulator, the same ``argmax`` of the Q-values; ``variant`` holds the episodes' state),
    without recording trajectories and without computing the features and actions of the
    episodes that have ended: the batch shrinks as they end (on average about a third of a
    greedy run's rows are still running). The one difference is floating-point: a matrix
    product over fewer rows may round differently in the last bit."""
    success = np.zeros(episodes, dtype=bool)
    for start in range(0, episodes, batch_size):
        ids = np.arange(start, min(start + batch_size, episodes))
        sim = Simulator(ids.size, env_params)
        obs, _ = sim.reset(seed=seed, scenario_ids=ids)
        running = np.arange(ids.size)  # the slots whose episode goes on
        actions = np.zeros(ids.size, dtype=np.int64)  # a finished slot's action is ignored
        with torch.inference_mode():
            features = variant.reset(obs)
            while running.size:
                chosen = q_network(features).argmax(dim=1).cpu().numpy()
                actions[running] = chosen
                result = sim.step(actions)
                ended = (result.terminated | result.truncated)[running]
                success[ids[running[ended]]] = result.info["success"][running[ended]]
                going_on = np.flatnonzero(~ended)
                running = running[going_on]
                variant.keep(going_on)
                if running.size:
                    features, _ = variant.step(result.obs[running], chosen[going_on])
    return float(success.mean())


def _next_multiple(done: int, every: int) -> int:
    """The first multiple of ``every`` above ``done`` (when the next periodic event is due)."""
    return (done // every + 1) * every


def check_finite_updates(
    learner: DQNLearner, losses: Sequence[torch.Tensor], updates: int, params: AgentParams
) -> None:
    """Stop training at the first NaN or infinite loss, or non-finite weight, of the updates
    just made (``losses``, the last of which was update number ``updates``): one check for a
    vector step's updates, no ``.item()`` per update.

    Raises:
        NonFiniteTrainingError: one line naming the update and the learning rate.
    """
    hint = f"(agent.learning_rate {params.learning_rate:g} too high?); no agent was written"
    stacked = torch.stack(list(losses))
    finite = torch.isfinite(stacked)
    if not bool(finite.all()):
        first = int((~finite).nonzero()[0, 0])
        number = updates - len(losses) + first + 1
        raise NonFiniteTrainingError(
            f"agent training stopped: loss became {float(stacked[first])} at update {number} {hint}"
        )
    if not learner.weights_finite():
        raise NonFiniteTrainingError(
            f"agent training stopped: weight {learner.first_nonfinite_weight()} became "
            f"non-finite by update {updates} {hint}"
        )


# -- one vector step --------------------------------------------------------------------------


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
    reset_obs = sim.autoreset(done)[done] if done.any() else None
    next_features, features = features_of.step(
        result.obs, actions, reset_mask=done, reset_obs=reset_obs
    )
    return VectorStep(result, done, finished_scenarios, reset_obs, next_features, features)


# -- the training state -----------------------------------------------------------------------


@dataclass
class TrainState:
    """Everything a training run changes as it goes: what a checkpoint holds.

    The components (learner, replay, n-step accumulator, variant, simulator) save their own
    state; the rest are the per-env accumulators, the counters, the training log, the model
    selection's runs and best weights, and the random generators.
    """

    learner: DQNLearner
    replay: ReplayBuffer
    accumulator: NStepAccumulator
    variant: Variant
    sim: Simulator
    explore_rng: np.random.Generator
    features: torch.Tensor
    goal_distance: np.ndarray
    episode_return: np.ndarray
    episode_length: np.ndarray
    epsilon: float
    env_steps: int = 0
    updates: int = 0
    wall_time: float = 0.0  # seconds of training up to the last save (earlier sessions)
    rows: list[dict[str, Any]] = field(default_factory=list)
    selection: list[dict[str, Any]] = field(default_factory=list)
    best_weights: dict[str, torch.Tensor] | None = None

    def state_dict(self) -> dict[str, Any]:
        sim = self.sim
        return {
            "learner": self.learner.state_dict(),
            "replay": self.replay.state_dict(),
            "n_step": self.accumulator.state_dict(),
            "variant": self.variant.state_dict(),
            "sim": {
                "state": {
                    f.name: torch.from_numpy(getattr(sim.state, f.name).copy())
                    for f in fields(BatchState)
                },
                "seed": sim.seed,
                "next_scenario": sim.next_scenario,
            },
            "rng": {
                "explore": self.explore_rng.bit_generator.state,
                "python": random.getstate(),
                "torch": torch.get_rng_state(),
            },
            "features": self.features.cpu().clone(),
            "goal_distance": torch.from_numpy(self.goal_distance.copy()),
            "episode_return": torch.from_numpy(self.episode_return.copy()),
            "episode_length": torch.from_numpy(self.episode_length.copy()),
            "counters": {
                "epsilon": self.epsilon,
                "env_steps": self.env_steps,
                "updates": self.updates,
                "wall_time": self.wall_time,
            },
            "rows": list(self.rows),
            "selection": list(self.selection),
            "best_weights": self.best_weights,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        device = self.features.device
        self.learner.load_state_dict(state["learner"])
        self.replay.load_state_dict(state["replay"])
        self.accumulator.load_state_dict(state["n_step"])
        self.variant.load_state_dict(state["variant"])
        for f in fields(BatchState):
            getattr(self.sim.state, f.name)[...] = state["sim"]["state"][f.name].numpy()
        self.sim.seed = int(state["sim"]["seed"])
        self.sim.next_scenario = int(state["sim"]["next_scenario"])
        self.explore_rng.bit_generator.state = state["rng"]["explore"]
        random.setstate(state["rng"]["python"])
        torch.set_rng_state(state["rng"]["torch"])
        self.features = state["features"].to(device)
        self.goal_distance = state["goal_distance"].numpy().copy()
        self.episode_return = state["episode_return"].numpy().copy()
        self.episode_length = state["episode_length"].numpy().copy()
        counters = state["counters"]
        self.epsilon = float(counters["epsilon"])
        self.env_steps, self.updates = int(counters["env_steps"]), int(counters["updates"])
        self.wall_time = float(counters["wall_time"])
        self.rows = list(state["rows"])
        self.selection = list(state["selection"])
        best = state["best_weights"]
        self.best_weights = None if best is None else {k: v.to(device) for k, v in best.items()}


def _episode_rows(
    state: TrainState, step: VectorStep, episodes: int, now: float
) -> list[dict[str, Any]]:
    """The training-log rows of the episodes that ended in ``step`` (up to ``episodes``)."""
    result, collision = step.result, step.result.info["collision"]
    rows: list[dict[str, Any]] = []
    for slot_index, env in enumerate(np.flatnonzero(step.done)):
        if len(state.rows) + len(rows) >= episodes:
            break
        rows.append(
            {
                "episode": len(state.rows) + len(rows) + 1,
                "scenario_id": int(step.finished_scenarios[slot_index]),
                "return": float(state.episode_return[env]),
                "length": int(state.episode_length[env]),
                "success": bool(result.info["success"][env]),
                "collision": bool(collision[env] != 0),
                "human_collision": bool(collision[env] == COLLISION_HUMAN),
                "wall_collision": bool(collision[env] == COLLISION_WALL),
                "timeout": bool(result.truncated[env]),
                "epsilon": float(state.epsilon),
                "env_steps": state.env_steps,
                "updates": state.updates,
                "wall_time": now,
            }
        )
    return rows


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
        variant: one of :data:`~socnav_wm.agents.features.VARIANTS`.
        params: hyper-parameters (``per_variant`` is applied here).
        env_params: training scenarios; the simulator seed is :func:`training_env_seed`.
        vae_path, lstm_path: the frozen world model (unused, may be None, for ``dueling-dqn``).
        seed: seeds the network initialisation, exploration, replay sampling and scenarios.
        checkpoint_path: where a resumable checkpoint is written every
            ``params.checkpoint_every`` episodes and at the end (None: no checkpoints).
        resume: continue from ``checkpoint_path`` if it exists (else start afresh). A resumed
            run ends with exactly the weights of an uninterrupted one.
        on_episodes: called after each vector step in which episodes finished, with their rows.
        quiet: no progress bar.

    Raises:
        NonFiniteTrainingError: a loss or a weight became NaN or infinite (one line; the
            caller writes no agent).
    """
    p = params.resolved(variant)  # checks the variant's name
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"seed: expected a non-negative integer, got {seed!r}")
    device = resolve_device(p.device)
    vae, lstm = load_world_model(variant, vae_path, lstm_path, device, env_params)
    identity = run_identity(variant, p, env_params, seed, vae_path, lstm_path)
    checkpoint_path = Path(checkpoint_path) if checkpoint_path is not None else None

    # -- seeding (cleanrl's block): Python's and torch's global generators (torch's seeds the
    # network initialisation), then one numpy generator per purpose, all derived from `seed`.
    random.seed(seed)
    torch.manual_seed(seed)
    explore_seed, replay_seed = np.random.SeedSequence(seed).spawn(2)

    # -- the pieces --------------------------------------------------------------------------
    obs_dim = observation_size(env_params.num_humans)
    features_of = variant_for(variant, vae, lstm, p, obs_dim=obs_dim, device=device)
    # Every allocation of the run together, before the first: each may fit alone, not all.
    check_fits_together(training_needs(features_of, p, env_params))
    sim = Simulator(p.num_envs, env_params)
    learner = DQNLearner(features_of.feature_dim, p, device)
    obs, _ = sim.reset(seed=training_env_seed(seed))
    state = TrainState(
        learner=learner,
        replay=ReplayBuffer(p.buffer_size, features_of.feature_dim, device, seed=replay_seed),
        accumulator=NStepAccumulator(p.num_envs, features_of.feature_dim, p.n_step, p.gamma),
        variant=features_of,
        sim=sim,
        explore_rng=np.random.default_rng(explore_seed),
        features=features_of.reset(obs),
        goal_distance=goal_distance(obs),
        episode_return=np.zeros(p.num_envs),
        episode_length=np.zeros(p.num_envs, dtype=np.int64),
        epsilon=p.epsilon_start,
    )
    if resume and checkpoint_path is not None and checkpoint_path.exists():
        try:
            state.load_state_dict(load_checkpoint(checkpoint_path, identity))
        except UnreadableCheckpoint as exc:
            # A damaged checkpoint (a full disk, a copy cut short) must not block every later
            # `dvc repro --resume`: keep it aside for inspection and train from the start.
            aside = set_aside(checkpoint_path)
            warnings.warn(f"{exc}; moved to {aside}, training from the start", stacklevel=2)

    start, elapsed_before = time.perf_counter(), state.wall_time

    def save() -> None:
        state.wall_time = elapsed_before + time.perf_counter() - start
        save_checkpoint(checkpoint_path, identity, state.state_dict())

    def select() -> None:
        """Run the current network greedily on the selection scenarios; keep it if best."""
        fresh = variant_for(variant, vae, lstm, p, obs_dim=features_of.obs_dim, device=device)
        rate = greedy_success_rate(
            learner.q_network, fresh, env_params, seed=selection_seed(seed),
            episodes=p.select_episodes,
        )  # fmt: skip
        state.selection.append({"episode": len(state.rows), "success_rate": rate})
        if best_selection_run(state.selection) is state.selection[-1]:
            state.best_weights = learner.weights()

    next_checkpoint = _next_multiple(len(state.rows), p.checkpoint_every)
    next_selection = _next_multiple(len(state.rows), p.select_every) if p.select_every else 0
    with progress(p.episodes, f"train-agent {variant}", quiet=quiet, unit="episodes") as bar:
        bar.advance(min(len(state.rows), p.episodes))
        while len(state.rows) < p.episodes:
            # -- act and step ----------------------------------------------------------------
            actions = learner.act(state.features, state.epsilon, state.explore_rng)
            step = step_and_restart(sim, features_of, actions)
            result, done = step.result, step.done

            # -- store -----------------------------------------------------------------------
            terminal = result.terminated if p.bootstrap_truncation else done
            next_distance = goal_distance(result.obs)
            shaped = progress_shaping(
                result.reward, state.goal_distance, next_distance, p.progress_reward
            )
            state.replay.add(
                *state.accumulator.push(
                    state.features, actions, shaped, step.next_features, terminal, done
                )
            )
            state.features = step.features
            state.goal_distance = next_distance
            if step.first_obs is not None:
                state.goal_distance[done] = goal_distance(step.first_obs)
            state.env_steps += p.num_envs
            state.episode_return += result.reward
            state.episode_length += 1

            # -- learn -----------------------------------------------------------------------
            if len(state.replay) >= p.learning_starts:
                losses = [
                    learner.update(state.replay.sample(p.batch_size))
                    for _ in range(p.updates_per_step)
                ]
                state.updates += len(losses)
                check_finite_updates(learner, losses, state.updates, p)

            # -- finished episodes: log rows, decay ε, select, checkpoint --------------------
            if done.any():
                now = elapsed_before + time.perf_counter() - start
                finished = _episode_rows(state, step, p.episodes, now)
                state.episode_return[done] = 0.0
                state.episode_length[done] = 0
                state.epsilon = max(
                    p.epsilon_min, state.epsilon * p.epsilon_decay ** int(done.sum())
                )
                state.rows.extend(finished)
                bar.advance(len(finished))
                if on_episodes is not None and finished:
                    on_episodes(finished)
                recent = [row["success"] for row in state.rows[-p.solved_window :]]
                bar.set_postfix(success=float(np.mean(recent)), epsilon=state.epsilon)
                n = len(state.rows)
                # Before the checkpoint, so that a checkpoint holds every run up to its episode.
                if p.select_every and (n >= next_selection or n >= p.episodes):
                    select()
                    next_selection = _next_multiple(n, p.select_every)
                if checkpoint_path is not None and n >= next_checkpoint:
                    if n < p.episodes:
                        save()
                    next_checkpoint = _next_multiple(n, p.checkpoint_every)

    if checkpoint_path is not None:
        save()  # the finished run: resuming it just returns this result
    else:
        state.wall_time = elapsed_before + time.perf_counter() - start
    selected = best_selection_run(state.selection)
    if state.best_weights is not None:  # the weights of `selected`
        learner.load_weights(state.best_weights)
    learner.q_network.eval()
    return TrainResult(
        q_network=learner.q_network,
        variant=variant,
        params=p,
        env_params=env_params,
        seed=seed,
        episodes=state.rows,
        episodes_to_solve=episodes_to_solve(
            [row["success"] for row in state.rows], p.solved_window, p.solved_success_rate
        ),
        env_steps=state.env_steps,
        updates=state.updates,
        wall_time=state.wall_time,
        vae=vae,
        lstm=lstm,
        selection=state.selection,
        selected_episode=selected["episode"] if selected is not None else None,
    )


def training_metrics(result: TrainResult, greedy: Sequence[Episode]) -> dict[str, Any]:
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
        "greedy_success_rate": success_rate(greedy),
        "greedy_collision_rate": float(np.mean([e.collision is not None for e in greedy])),
        "greedy_timeout_rate": float(np.mean([e.truncated for e in greedy])),
    }


def write_training_log(rows: Sequence[dict[str, Any]], path: str | Path) -> None:
    """The training log (one row per episode, :data:`EPISODE_COLUMNS`) as Parquet, atomically."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.table({name: [row[name] for row in rows] for name in EPISODE_COLUMNS})
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp, compression="zstd")
