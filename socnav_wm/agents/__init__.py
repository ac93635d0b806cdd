"""The Dueling DQN agents: the Q-network, what each variant feeds it, replay and training.

Modules: ``params`` (hyper-parameters and variant names; no torch), ``dueling`` (the network),
``features`` (the five variants), ``replay`` (uniform replay buffer and n-step returns),
``learner`` (the autograd DQN update), ``training`` (the training loop and its state),
``checkpoint`` (resumable checkpoints), ``agent_file`` (saving, loading and running trained
agents), ``baselines`` (the ORCA and Social Force robots). The training benchmark is
``socnav_wm.bench.bench_train``.

The names below are imported lazily, so ``from socnav_wm.agents.params import AgentParams`` (what
the configuration does) does not pay for importing torch.
"""

from __future__ import annotations

from socnav_wm.exports import lazy_exports

_EXPORTS = {
    "AgentParams": "socnav_wm.agents.params",
    "VARIANT_NAMES": "socnav_wm.agents.params",
    "Agent": "socnav_wm.agents.agent_file",
    "TrainResult": "socnav_wm.agents.agent_file",
    "greedy_episodes": "socnav_wm.agents.agent_file",
    "load_agent": "socnav_wm.agents.agent_file",
    "save_agent": "socnav_wm.agents.agent_file",
    "train_agent": "socnav_wm.agents.training",
    "VARIANTS": "socnav_wm.agents.features",
    "make_variant": "socnav_wm.agents.features",
}

__all__ = sorted(_EXPORTS)

__getattr__ = lazy_exports(__name__, _EXPORTS)
