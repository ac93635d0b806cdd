"""The agent file: a trained Q-network with its variant, parameters and frozen world model.

:func:`save_agent` writes one self-contained file (the Q-network, the variant's options, the
training and scenario parameters, and the VAE + LSTM weights), so an agent evaluates on its own
and can never be paired with another world model by mistake; :func:`load_agent` reads it back as
an :class:`Agent` that acts greedily.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from socnav_wm.agents.dueling import DuelingQNetwork
from socnav_wm.agents.features import VARIANTS, Variant, make_variant
from socnav_wm.agents.params import AgentParams, check_variant
from socnav_wm.data.compatibility import check_made_with
from socnav_wm.devices import resolve_device
from socnav_wm.env.episode import Episode
from socnav_wm.env.params import EnvParams
from socnav_wm.env.rollout import run_episodes
from socnav_wm.io import atomic_path, first_line, load_saved, torch_bytes
from socnav_wm.worldmodel.files import load_vae_lstm
from socnav_wm.worldmodel.lstm import LatentLSTM
from socnav_wm.worldmodel.vae import VAE

AGENT_FORMAT = "socnav-wm-agent"
AGENT_FORMAT_VERSION = 1


@dataclass
class TrainResult:
    """Outcome of :func:`socnav_wm.agents.training.train_agent`.

    Attributes:
        q_network: the trained online network (eval mode; the selected weights).
        variant: the variant's name.
        params: the resolved hyper-parameters (``agent.per_variant`` applied).
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

    q_network: torch.nn.Module
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


class AgentFileError(ValueError):
    """An agent file is missing, unreadable or not an agent (one-line message)."""


def env_params_obs_dim(env_params: EnvParams) -> int:
    """Size of the observation for these scenario parameters (2 + 7 per human)."""
    return 2 + 7 * env_params.num_humans


def variant_for(
    name: str,
    vae: VAE | None,
    lstm: LatentLSTM | None,
    params: AgentParams,
    *,
    obs_dim: int,
    device: torch.device | str,
) -> Variant:
    """The variant ``name``, with its options read from ``params``."""
    return make_variant(name, vae, lstm, params, obs_dim=obs_dim, device=device)


def load_world_model(
    variant: str,
    vae_path: str | Path | None,
    lstm_path: str | Path | None,
    device: torch.device | str,
    env_params: EnvParams | None = None,
) -> tuple[VAE | None, LatentLSTM | None]:
    """The frozen VAE and LSTM a variant needs (None, None for ``dueling-dqn``), refused in one
    line when they were trained for other scenarios than ``env_params``."""
    if not VARIANTS[check_variant(variant)].needs_world_model:
        return None, None
    if vae_path is None or lstm_path is None:
        raise ValueError(f"variant {variant!r} needs the VAE and LSTM files (got no path)")
    return load_vae_lstm(vae_path, lstm_path, device, env_params)


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

    q_network: torch.nn.Module
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
        :func:`socnav_wm.env.rollout.run_episodes` does; finished slots are simply carried along).
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


def _module_payload(model: torch.nn.Module | None) -> dict[str, Any] | None:
    if model is None:
        return None
    return {
        "hyperparameters": model.hyperparameters(),  # type: ignore[operator]
        "state_dict": {k: v.detach().cpu() for k, v in model.state_dict().items()},
    }


def save_agent(path: str | Path, result: TrainResult, extra: dict[str, Any] | None = None) -> None:
    """Write a trained agent to ``path`` atomically (see the module docstring)."""
    payload = {
        "format": AGENT_FORMAT,
        "format_version": AGENT_FORMAT_VERSION,
        "variant": result.variant,
        "params": result.params.to_dict(),
        "env_params": result.env_params.to_dict(),
        "q_network": _module_payload(result.q_network),
        "vae": _module_payload(result.vae),
        "lstm": _module_payload(result.lstm),
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
        tmp.write_bytes(torch_bytes(payload))


def load_agent(
    path: str | Path,
    device: torch.device | str = "cpu",
    env_params: EnvParams | None = None,
    *,
    transfer: bool = False,
) -> Agent:
    """Load an agent written by :func:`save_agent`, on ``device`` (``auto``/``cpu``/``cuda``).

    Raises:
        AgentFileError: one line naming the file when it is missing, unreadable, not an agent
            file, of another format version, trained for other scenarios than ``env_params``
            (another number of humans or room size; None: not checked), or when its weights
            do not fit.
    """
    path = Path(path)
    payload = load_saved(path, "agent file", AGENT_FORMAT, AGENT_FORMAT_VERSION, AgentFileError)
    made = payload.get("env_params") if isinstance(payload.get("env_params"), dict) else None
    check_made_with(path, made, env_params, error=AgentFileError, transfer=transfer)
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
    variant = variant_for(
        result.variant,
        result.vae,
        result.lstm,
        result.params,
        obs_dim=env_params_obs_dim(result.env_params),
        device=device,
    )
    return Agent(
        result.q_network.eval(), variant, result.params, result.env_params, {"seed": result.seed}
    )


def greedy_episodes(
    agent: Agent,
    env_params: EnvParams,
    *,
    seed: int,
    scenario_ids: np.ndarray | range,
    batch_size: int = 500,
) -> list[Episode]:
    """Greedy (ε = 0) episodes of scenarios ``scenario_ids`` of ``seed``, in their order.

    The one episode runner (:func:`socnav_wm.env.rollout.run_episodes`) in batches of
    ``batch_size`` scenarios, each with a fresh policy (it holds its episodes' world-model
    state); the result depends only on (agent, env_params, seed, scenario ids). The validation
    after training, the model selection and the test evaluation all run through here.
    """
    ids = np.asarray(scenario_ids, dtype=np.int64)
    episodes: list[Episode] = []
    for start in range(0, ids.size, batch_size):
        episodes += run_episodes(env_params, agent.policy(), seed, ids[start : start + batch_size])
    return episodes
