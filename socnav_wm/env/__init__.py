"""The social-navigation simulator: one batched implementation (``core.Simulator``).

Modules: ``params`` (the scenario's parameters; no numba), ``core`` (the batched simulator),
``humans``/``orca`` (the people), ``scenario``, ``reward``, ``observation``, ``state``,
``rollout`` (episodes of a policy), ``gym`` (the Gymnasium envs; ``import socnav_wm`` registers
``SocNav-v0``), ``wrappers`` and ``render`` (drawing, imported only where something is drawn).

The names below are imported lazily, so that ``from socnav_wm.env.params import EnvParams``
(what the configuration does) does not compile the simulator, and a stage depends on the
simulator's files only where it runs it (``socnav-wm deps``). Inside the package, import from
the modules themselves.
"""

from __future__ import annotations

from socnav_wm.exports import lazy_exports

_EXPORTS = {
    "ACTION_NAMES": "socnav_wm.env.core",
    "NUM_ACTIONS": "socnav_wm.env.core",
    "Simulator": "socnav_wm.env.core",
    "StepResult": "socnav_wm.env.core",
    "EnvParams": "socnav_wm.env.params",
}

__all__ = sorted(_EXPORTS)

__getattr__ = lazy_exports(__name__, _EXPORTS)
