"""The Dueling DQN agents: the Q-network, what each variant feeds it, replay and training.

Modules: ``params`` (hyper-parameters and variant names; no torch), ``dueling`` (the network),
``features`` (the five variants), ``replay`` (uniform replay buffer and n-step returns),
``learner`` (the autograd DQN update), ``training`` (the training loop and its state),
``checkpoint`` (resumable checkpoints), ``agent_file`` (saving, loading and running trained
agents), ``baselines`` (the ORCA and Social Force robots). The training benchmark is
``pipeline.bench.bench_train``.

The names below are imported lazily, so ``from pipeline.agents.params import AgentParams`` (what
the configuration does) does not pay for importing torch.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "AgentParams": "pipeline.agents.params",
    "VARIANT_NAMES": "pipeline.agents.params",
    "Agent": "pipeline.agents.agent_file",
    "TrainResult": "pipeline.agents.training",
    "greedy_episodes": "pipeline.agents.agent_file",
    "load_agent": "pipeline.agents.agent_file",
    "save_agent": "pipeline.agents.agent_file",
    "train_agent": "pipeline.agents.training",
    "VARIANTS": "pipeline.agents.features",
    "make_variant": "pipeline.agents.features",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'pipeline.agents' has no attribute {name!r}")
