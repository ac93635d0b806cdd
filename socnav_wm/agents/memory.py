"""What one agent training allocates, estimated before it starts: the simulator, each
environment's share of a vector step (features, world-model rollouts, the Q-network's forward
pass), the replay buffer and the greedy selection runs. :func:`training_needs` gives them to
:func:`~socnav_wm.resources.check_fits_together`, which refuses them in one line when together
they exceed the machine's memory (each alone may fit: 10 million environments and as many
transitions once passed two separate checks and then met the OOM killer).

The per-environment share was measured (peak resident memory over three vector steps of 20,000
environments, CPU): 9.8 KiB for ``dueling-dqn`` with a 64-unit trunk, 13.5 KiB with the default
512-128 trunk, 59 KiB for ``maspm`` and 89 KiB for ``2stepahead-maspm`` with 256-unit VAE and
LSTM, 26 KiB for ``2stepahead-maspm`` with 32-unit ones. The estimate below is above each.
"""

from __future__ import annotations

from socnav_wm.agents.features import Variant
from socnav_wm.agents.params import AgentParams
from socnav_wm.agents.replay import ReplayBuffer
from socnav_wm.env.core import NUM_ACTIONS, Simulator
from socnav_wm.env.params import EnvParams
from socnav_wm.resources import Need

SAFETY = 1.25
"""The estimate's margin over what was measured (allocator slack, other PyTorch builds)."""

GREEDY_BATCH = 500
"""Scenarios a greedy run steps at once (``greedy_episodes``' batch)."""


def _lstm_steps(features: Variant, horizon: int) -> int:
    """LSTM steps of one environment's features per vector step."""
    return {
        "dueling-dqn": 0,
        "wm-dueling-dqn": 1,
        "2stepahead": horizon,
        "maspm": NUM_ACTIONS,
        "2stepahead-maspm": NUM_ACTIONS * horizon,
    }.get(features.name, NUM_ACTIONS * horizon)


def bytes_per_env(features: Variant, params: AgentParams, env_params: EnvParams) -> int:
    """One environment's share of a vector step beyond the simulator's state: observations
    sorted and encoded, the world model's rollouts and decodings, the Q-network's activations,
    the features kept and the n-step accumulator's rows."""
    obs_dim, feature_dim = features.obs_dim, features.feature_dim
    vae_hidden = features.vae.hidden_dim if features.vae is not None else 0
    decodes = 0
    if features.vae is not None and params.decode_latents:
        decodes = 1 + NUM_ACTIONS if "maspm" in features.name else 1
    floats = (
        96 * obs_dim  # the observation as tensors, sorted by distance, and its copies
        + 2 * (sum(params.trunk_sizes) + 2 * params.stream_size)  # acting: Q-network activations
        + _lstm_steps(features, params.horizon) * 8 * features.hidden_dim  # gates, h and c
        + decodes * (3 * vae_hidden + obs_dim)  # decoder layers and outputs
        + 3 * vae_hidden  # the encoder
        + 4 * feature_dim  # the features kept: current, next, the restarted ones
    )
    accumulator = params.n_step * (4 * feature_dim + 16) + 8
    return int(SAFETY * 4 * floats) + accumulator


def training_needs(features: Variant, params: AgentParams, env_params: EnvParams) -> list[Need]:
    """The allocations of one training of ``features``' variant with ``params`` (resolved for
    the variant) in ``env_params``' scenarios, each with the setting that sizes it."""
    per_env = Simulator.bytes_needed(1, env_params) + bytes_per_env(features, params, env_params)
    greedy = min(params.select_episodes, GREEDY_BATCH) if params.select_every else 0
    return [
        ("agent.num_envs", params.num_envs * per_env, f"{params.num_envs:,} environments"),
        (
            "agent.buffer_size",
            ReplayBuffer.bytes_needed(params.buffer_size, features.feature_dim),
            f"a replay buffer of {params.buffer_size:,} transitions",
        ),
        ("agent.select_episodes", greedy * per_env, f"{greedy:,} greedy selection runs"),
    ]
