"""The agents' policies: a trained agent file, greedy."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from socnav_wm.agents.agent_file import load_agent
from socnav_wm.env.params import EnvParams
from socnav_wm.methods import Method, PolicyFactory


def build(
    method: Method,
    env_params: EnvParams,
    *,
    files: Mapping[str, Path],
    device: str,
    transfer: bool,
) -> PolicyFactory:
    """Agent ``files["agent"]`` (of variant ``method.name``), on ``device``; refused in one line
    when the file holds another variant or was trained for other scenarios (another number of
    humans or room size; another world, unless ``transfer``)."""
    path = files["agent"]
    agent = load_agent(path, device, env_params, transfer=transfer)
    if agent.variant_name != method.name:
        raise ValueError(f"{path}: an agent of variant {agent.variant_name!r}, not {method.name!r}")
    return lambda: (agent.policy(), False)
