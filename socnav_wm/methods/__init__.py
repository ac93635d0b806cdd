"""The registry of methods: for every method name, its kind, what it needs, and its policy.

One entry per name of :data:`~socnav_wm.method_names.METHOD_NAMES`: the five agent variants
(kind ``agent``: a trained agent file, greedy), the ORCA and Social Force robots (``robot``: the
``baselines`` parameters) and the planners (``planner``: the ``planning`` parameters and their
model files). The evaluation, the ``render`` and ``bench plan`` commands and the examples build
every policy here; :func:`method` is the one lookup, raising a one-line ValueError that names
the choices.

A method's policy comes from :meth:`Method.policies`, a factory of fresh policies, one per
batch of episodes that start together (what :func:`socnav_wm.env.rollout.run_episodes` runs),
each with whether it reads the simulator rather than the observations. What runs a method
(torch, the robot controllers, the planners) is imported only when its policy is built.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from socnav_wm.env.params import EnvParams
from socnav_wm.layout import LAYOUT
from socnav_wm.method_names import (
    BASELINE_NAMES,
    METHOD_NAMES,
    PLANNER_NAMES,
    VARIANT_NAMES,
    check_method,
)
from socnav_wm.planning.params import PlanningParams

__all__ = ["MAKES", "METHODS", "Kind", "Method", "Policy", "PolicyFactory", "method", "names"]

Kind = Literal["agent", "robot", "planner"]

Policy = Callable[[Any], Any]
PolicyFactory = Callable[[], tuple[Policy, bool]]
"""A fresh policy for one batch of episodes that start together, and whether it reads the
simulator (its argument is then the simulator, else the observations)."""

MAKES = {
    "agent": "socnav-wm train-agent --variant {variant} --seed {seed}",
    "planning_model": "socnav-wm train-planning-model --seed {seed}",
    "vae": "socnav-wm train-vae",
    "lstm": "socnav-wm train-lstm",
    "critic": "socnav-wm train-agent --variant dueling-dqn --seed {seed}",
}
"""The command that makes the file of each role (``{variant}``, ``{seed}``: which one)."""


@dataclass(frozen=True)
class Method:
    """One method of the registry.

    Attributes:
        name: its name (one of :data:`~socnav_wm.method_names.METHOD_NAMES`).
        kind: ``agent``, ``robot`` or ``planner``.
        sections: the ``params.yaml`` sections its policy reads, besides ``env``.
        model_files: the model files it reads, by role, at their pipeline paths (an agent:
            training seed 0's file; the evaluation reads every seed's).
        builder: ``module:function``, where ``function(method, env_params, *, files,
            **inputs)`` returns the method's :data:`PolicyFactory`.
    """

    name: str
    kind: Kind
    sections: tuple[str, ...]
    model_files: Mapping[str, Path] = field(default_factory=dict)
    builder: str = ""

    @property
    def builder_module(self) -> str:
        """The module of :attr:`builder` (what building this method's policy executes)."""
        return self.builder.partition(":")[0]

    def files(self, overrides: Mapping[str, str | Path] | None = None) -> dict[str, Path]:
        """:attr:`model_files`, replaced by ``overrides`` (by role), each checked to exist.

        Raises:
            ValueError: an override of a role the method does not have.
            FileNotFoundError: a file that is not there (naming the command that makes it).
        """
        files = dict(self.model_files)
        for role, path in (overrides or {}).items():
            if role not in files:
                expected = ", ".join(files) or "none"
                raise ValueError(
                    f"{self.kind} {self.name!r} reads no {role} file (it reads: {expected})"
                )
            files[role] = Path(path)
        for role, path in files.items():
            if not path.is_file():
                make = MAKES[role].format(variant=self.name, seed=0)
                raise FileNotFoundError(f"{path}: no such {role} file (make it: {make})")
        return files

    def policies(
        self,
        env_params: EnvParams,
        *,
        files: Mapping[str, Path] | None = None,
        baseline: Mapping[str, Any] | None = None,
        planning: PlanningParams | None = None,
        device: str | None = None,
        transfer: bool = False,
    ) -> PolicyFactory:
        """The factory of this method's policies on scenarios of ``env_params``.

        Args:
            env_params: the scenarios' parameters.
            files: the model files by role (:meth:`files`); default: the pipeline's. An agent's
                is its ``agent`` file.
            baseline: a robot's parameters replacing its defaults (``baselines.<name>``).
            planning: a planner's parameters (the ``planning`` section; its ``per_method``
                entry for this planner is applied here).
            device: where an agent's network runs (``cpu``, ``cuda``, ``auto``).
            transfer: a method with model files may use files trained in another world (another
                preset's humans, obstacles or speeds: a transfer evaluation); without it they
                are refused (:func:`socnav_wm.data.compatibility.check_made_with`).

        Raises:
            ValueError: an input this kind of method does not take, or a missing one; an
                agent file of another variant or number of humans.
        """
        given = {"baseline": baseline, "planning": planning, "device": device}
        takes = {"agent": {"device"}, "robot": {"baseline"}, "planner": {"planning"}}[self.kind]
        extra = sorted(k for k, v in given.items() if v is not None and k not in takes)
        missing = sorted(k for k in takes - {"baseline"} if given[k] is None)
        if extra or missing:
            problem = f"takes no {', '.join(extra)}" if extra else f"needs {', '.join(missing)}"
            raise ValueError(f"{self.kind} {self.name!r} {problem}")
        files = self.files() if files is None else dict(files)
        module, _, function = self.builder.partition(":")
        build = getattr(importlib.import_module(module), function)
        inputs = {k: given[k] for k in takes}
        if self.model_files:  # the builders that load model files judge them
            inputs["transfer"] = transfer
        elif transfer:
            raise ValueError(f"{self.kind} {self.name!r} reads no model files: nothing to transfer")
        return build(self, env_params, files=files, **inputs)

    def configured(
        self,
        env_params: EnvParams,
        sections: Mapping[str, Any],
        files: Mapping[str, Path] | None = None,
        transfer: bool = False,
    ) -> PolicyFactory:
        """:meth:`policies` with the inputs read from the ``params.yaml`` sections of
        :attr:`sections` (``sections``: name → that section's parameters, e.g. ``{"planning":
        params.planning}``): an agent's device (``eval.device``), a robot's parameters
        (``baselines.<name>``), a planner's (``planning``)."""
        missing = [name for name in self.sections if name not in sections]
        if missing:
            raise ValueError(f"{self.kind} {self.name!r} needs the {', '.join(missing)} section")
        if self.kind == "agent":
            device = sections["eval"].device
            return self.policies(env_params, files=files, device=device, transfer=transfer)
        if self.kind == "robot":
            overrides = getattr(sections["baselines"], self.name).model_dump()
            return self.policies(env_params, files=files, baseline=overrides, transfer=transfer)
        planning = sections["planning"]
        return self.policies(env_params, files=files, planning=planning, transfer=transfer)


_BUILDERS: dict[str, str] = {
    **{name: "socnav_wm.methods.agents:build" for name in VARIANT_NAMES},
    **{name: "socnav_wm.methods.robots:build" for name in BASELINE_NAMES},
    "cv-mpc": "socnav_wm.methods.planners:constant_velocity",
    "wm-mpc": "socnav_wm.methods.wm_mpc:build",
    "vae-lstm-mpc": "socnav_wm.methods.vae_lstm_mpc:build",
    "oracle-mpc": "socnav_wm.methods.planners:oracle",
    "wm-mpc-q": "socnav_wm.methods.wm_mpc_q:build",
}
"""Each method → ``module:function``, the function that makes its policies. The module is
imported only when a policy is built, so that a stage executes (and depends on:
:mod:`socnav_wm.stages.deps` reads this table) the builders of its own methods alone."""

_MODEL_FILES: dict[str, dict[str, Path]] = {
    **{name: {"agent": LAYOUT.agent(name)} for name in VARIANT_NAMES},
    "wm-mpc": {"planning_model": LAYOUT.planning_model(0)},
    "vae-lstm-mpc": {"vae": LAYOUT.vae, "lstm": LAYOUT.lstm},
    "wm-mpc-q": {
        "planning_model": LAYOUT.planning_model(0),
        "critic": LAYOUT.agent("dueling-dqn"),
    },
}

_KIND_SECTIONS: dict[str, tuple[Kind, tuple[str, ...]]] = {
    **{name: ("agent", ("eval",)) for name in VARIANT_NAMES},
    **{name: ("robot", ("baselines",)) for name in BASELINE_NAMES},
    **{name: ("planner", ("planning",)) for name in PLANNER_NAMES},
}

METHODS: dict[str, Method] = {
    name: Method(name, *_KIND_SECTIONS[name], _MODEL_FILES.get(name, {}), _BUILDERS[name])
    for name in METHOD_NAMES
}
"""Every method by name, in :data:`~socnav_wm.method_names.METHOD_NAMES`' order."""
assert tuple(METHODS) == METHOD_NAMES


def method(name: str, label: str = "method") -> Method:
    """The method ``name``; a one-line ValueError (``{label}: unknown …``) naming the choices."""
    return METHODS[check_method(name, label=label)]


def names(kind: Kind) -> tuple[str, ...]:
    """The names of the methods of ``kind``, in registry order."""
    return tuple(name for name, entry in METHODS.items() if entry.kind == kind)
