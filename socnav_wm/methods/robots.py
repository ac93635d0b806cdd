"""The ORCA and Social Force robots' policies (they read the simulator's world-frame state)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from socnav_wm.agents.baselines import make_baseline
from socnav_wm.env.params import EnvParams
from socnav_wm.methods import Method, PolicyFactory


def build(
    method: Method,
    env_params: EnvParams,
    *,
    files: Mapping[str, Path],
    baseline: Mapping[str, Any] | None,
) -> PolicyFactory:
    """Robot ``method.name`` with ``baseline`` replacing its default parameters."""
    controller = make_baseline(method.name, **dict(baseline or {}))
    return lambda: ((lambda sim: controller.act(sim.state, sim.params)), True)
