"""Typed, validated configuration: ``params.yaml`` is the single source of every stage's settings.

One strict pydantic model per section, all subclasses of :class:`~socnav_wm.env.params.Section`
(``env`` is the simulator's :class:`~socnav_wm.env.params.EnvParams`, ``agent`` the agents'
:class:`~socnav_wm.agents.params.AgentParams`, ``baselines.orca`` / ``baselines.sfm`` the
baselines' own parameter models), under the top-level :class:`Params`. Every field has a
default, and the defaults are the shipped ``params.yaml`` (a test compares them), so a partial
file works. Attribute docstrings become the fields' descriptions (the documentation).

A run's configuration is ``params.yaml``, then each overlay (a YAML file deep-merged over it,
mapping by mapping, e.g. ``configs/paper.yaml``), then the ``--set`` overrides (any depth:
``baselines.orca.time_horizon=3``, ``agent.per_variant.maspm.gamma=0.9``).

Every problem — a missing file, bad YAML, an unknown key, a value out of range, a malformed
``--set`` override — raises :class:`ConfigError` with a single line naming the source, the
dotted key and what is wrong, e.g. ``params.yaml: vae.batch_size: must be > 0, got -3``.
"""

from __future__ import annotations

import copy
import difflib
import re
import typing
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, Self

import yaml
from pydantic import BaseModel, Field, ValidationError, model_validator

from socnav_wm.agents.baseline_params import BaselinesParams
from socnav_wm.agents.params import (
    AgentParams,
    ExperimentParams,
)
from socnav_wm.data.params import CollectParams
from socnav_wm.env.params import EnvParams
from socnav_wm.evaluation.params import EvalParams, ReportParams
from socnav_wm.io import atomic_path
from socnav_wm.planning.params import PLANNER_NAMES, PlanningParams
from socnav_wm.section import (
    Device,
    Section,
    Seed,
    describe_error,
    one_line,
    seed_field,
    short_repr,
)
from socnav_wm.studies.params import StudyParams, default_studies
from socnav_wm.worldmodel.params import (
    LstmParams,
    PlanningModelParams,
    PredictionParams,
    VaeParams,
)

__all__ = [
    "AgentParams",
    "BaselinesParams",
    "CollectParams",
    "ConfigError",
    "Device",
    "EvalParams",
    "ExperimentParams",
    "PlanningModelParams",
    "LstmParams",
    "Params",
    "ReportParams",
    "PredictionParams",
    "STAGE_SECTIONS",
    "StudyParams",
    "VaeParams",
    "flatten",
    "load_params",
    "params_dict",
    "save_resolved",
    "select_sections",
]


class ConfigError(ValueError):
    """A configuration problem, described in one line: ``<source>: <key>: <what is wrong>``."""


# ---------------------------------------------------------------------------------------------
# The models
# ---------------------------------------------------------------------------------------------

# Every section is a `Section` (socnav_wm/env/params.py): strict types (YAML already types them,
# so `batch_size: 512.0` or `seed: true` is a slip worth reporting rather than silently
# coercing), finite floats (`.inf` passes `gt=0`), frozen, unknown keys rejected.


class Params(Section):
    """Everything ``params.yaml`` can hold; every section is optional."""

    seed: Seed = seed_field(0)
    """Master seed: every random generator of every stage derives from it."""
    env: EnvParams = Field(default_factory=EnvParams)
    """The simulator's scenario (the paper's by default); see socnav_wm/env/params.py."""
    collect: CollectParams = Field(default_factory=CollectParams)
    """Random-policy data collection."""
    vae: VaeParams = Field(default_factory=VaeParams)
    """VAE training."""
    lstm: LstmParams = Field(default_factory=LstmParams)
    """LSTM world-model training."""
    agent: AgentParams = Field(default_factory=AgentParams)
    """The Dueling DQN agents (all five variants); see socnav_wm/agents/params.py."""
    experiment: ExperimentParams = Field(default_factory=ExperimentParams)
    """Variants and training seeds of the pipeline."""
    eval: EvalParams = Field(default_factory=EvalParams)
    """The paired evaluation on test scenarios."""
    baselines: BaselinesParams = Field(default_factory=BaselinesParams)
    """ORCA and Social Force robots."""
    planning: PlanningParams = Field(default_factory=PlanningParams)
    """The planners (cv-mpc); see socnav_wm/planning/params.py."""
    planning_model: PlanningModelParams = Field(default_factory=PlanningModelParams)
    """The planning world model (wm-mpc's); see socnav_wm/worldmodel/residual.py."""
    prediction: PredictionParams = Field(default_factory=PredictionParams)
    """The world models' k-step errors in metres (the ``predict`` stage)."""
    report: ReportParams = Field(default_factory=ReportParams)
    """Statistics and figures of the report."""
    studies: dict[str, StudyParams] = Field(default_factory=default_studies)
    """Named grids of agent runs (``socnav-wm sweep --study NAME``, ``dvc repro study_NAME``);
    no stage of the default pipeline reads them."""

    @model_validator(mode="after")
    def _plans_within_an_episode(self) -> Self:
        # A planner predicts `horizon` steps for every candidate at every step: beyond the
        # episode's last step there is nothing to plan for, only time to spend (a horizon of
        # 1,000,000 ran for days).
        for method in PLANNER_NAMES:
            horizon = self.planning.resolved(method).horizon
            if horizon > self.env.max_steps:
                key = "planning.horizon"
                if "horizon" in self.planning.per_method.get(method, {}):
                    key = f"planning.per_method.{method}.horizon"
                raise ValueError(
                    f"{key}: {horizon} steps ahead is longer than an episode "
                    f"(env.max_steps {self.env.max_steps}); at most {self.env.max_steps}"
                )
        return self


# ---------------------------------------------------------------------------------------------
# YAML
# ---------------------------------------------------------------------------------------------


class _Loader(yaml.SafeLoader):
    """SafeLoader that rejects duplicate keys and reads ``1e-3`` as a float.

    PyYAML follows YAML 1.1, where a float needs a dot: ``learning_rate: 1e-3`` would be the
    *string* "1e-3" and fail the strict float check. YAML 1.2 (and every reader's intuition)
    says float. A duplicated key silently keeps the last value in PyYAML; here it is an error.
    """

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: set[Any] = set()
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue
            key = self.construct_object(key_node, deep=True)
            try:
                duplicate = key in seen
            except TypeError:  # unhashable key: let the base class report it
                break
            if duplicate:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {key!r}", key_node.start_mark
                )
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
        |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
        |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
        |[-+]?\.(?:inf|Inf|INF)
        |\.(?:nan|NaN|NAN))$""",
        re.VERBOSE,
    ),
    list("-+0123456789."),
)


def _parse_yaml(text: str, source: str) -> Any:
    try:
        return yaml.load(text, Loader=_Loader)  # noqa: S506 - _Loader is a SafeLoader
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        problem = one_line(exc.problem or exc.context or "syntax error")
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        raise ConfigError(f"{source}: not valid YAML ({where}{problem})") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{source}: not valid YAML ({one_line(str(exc))})") from None


# ---------------------------------------------------------------------------------------------
# Loading
# ---------------------------------------------------------------------------------------------


_DICT_ORIGINS = (dict, Mapping, typing.Mapping)


def _child(node: Any, part: str) -> tuple[bool, Any]:
    """Walk one step of a dotted key from ``node`` (a model class or a type): (known, child)."""
    if isinstance(node, type) and issubclass(node, BaseModel):
        field = node.model_fields.get(part)
        return (False, None) if field is None else (True, field.annotation)
    if typing.get_origin(node) in _DICT_ORIGINS:  # a free mapping (agent.per_variant): any key
        return True, typing.get_args(node)[1] if typing.get_args(node) else Any
    if node is Any:
        return True, Any
    return False, None  # a plain value has no keys


def _is_model(node: Any) -> bool:
    return isinstance(node, type) and issubclass(node, BaseModel)


def _unknown_key(dotted: str) -> str:
    """``unknown key 'vae.bacth_size' (did you mean 'vae.batch_size'?)``."""
    parts = dotted.split(".")
    node: Any = Params
    for i, part in enumerate(parts):
        known, child = _child(node, part)
        if not known:
            hint = ""
            if _is_model(node):
                close = difflib.get_close_matches(part, list(node.model_fields), n=1, cutoff=0.75)
                if close:
                    hint = f" (did you mean {'.'.join([*parts[:i], close[0], *parts[i + 1 :]])!r}?)"
            return f"unknown key {dotted!r}{hint}"
        node = child
    return f"unknown key {dotted!r}"


def _apply_override(raw: dict[str, Any], override: str, source: str) -> str:
    """Set one ``dotted.key=value`` (any depth) in the raw mapping; returns the dotted key."""
    key, sep, text = override.partition("=")
    key = key.strip()
    if not sep or not key or any(not part for part in key.split(".")):
        raise ConfigError(f"{source}: expected section.key=value")
    parts = key.split(".")
    node: Any = Params
    for part in parts:
        known, node = _child(node, part)
        if not known:
            raise ConfigError(f"{source}: {_unknown_key(key)}")
    if _is_model(node):
        raise ConfigError(f"{source}: {key!r} is a section; use {key}.key=value")

    value = _parse_yaml(text, source)
    target = raw
    for depth, part in enumerate(parts[:-1]):
        child = target.get(part)
        if child is None:  # missing, or `vae:` with nothing under it
            child = target[part] = {}
        if not isinstance(child, dict):
            where = ".".join(parts[: depth + 1])
            raise ConfigError(f"{source}: {where}: expected a mapping, got {short_repr(child)}")
        target = child
    target[parts[-1]] = value
    return key


def _read_yaml_mapping(path: str | Path) -> dict[str, Any]:
    """The top-level mapping of a YAML file (empty for an empty file), or a ConfigError."""
    source = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"{source}: file not found") from None
    except IsADirectoryError:
        raise ConfigError(f"{source}: is a directory, expected a YAML file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{source}: cannot read ({one_line(str(exc))})") from None
    raw = _parse_yaml(text, source)
    if raw is None:  # an empty file: all defaults
        return {}
    if not isinstance(raw, dict):
        raise ConfigError(f"{source}: expected a mapping of sections, got {type(raw).__name__}")
    return raw


def _merge(base: dict[str, Any], overlay: Mapping[str, Any], prefix: str = "") -> list[str]:
    """Deep-merge ``overlay`` into ``base`` in place, mapping by mapping (anything else
    replaces); returns the dotted keys of the values it wrote. A key left empty (``lstm:``)
    changes nothing."""
    written: list[str] = []
    for key, value in overlay.items():
        dotted = f"{prefix}{key}"
        current = base.get(key)
        if value is None and (current is None or isinstance(current, dict)):
            continue
        if isinstance(value, dict) and isinstance(current, dict):
            written += _merge(current, value, f"{dotted}.")
        elif isinstance(value, dict) and current is None:
            base[key] = {}
            written += _merge(base[key], value, f"{dotted}.")
        else:
            base[key] = copy.deepcopy(value)
            written.append(dotted)
    return written


def load_params(
    path: str | Path = "params.yaml",
    overrides: Sequence[str] = (),
    overlays: Sequence[str | Path] = (),
) -> Params:
    """Read ``params.yaml``, merge the overlays, apply the overrides and validate.

    ``overlays`` are YAML files deep-merged over the file in order (mapping by mapping: an
    overlay's ``agent: {gamma: 0.9}`` changes that one key), e.g. ``configs/paper.yaml``.
    ``overrides`` then set ``dotted.key=value`` strings, at any depth (``seed=3``,
    ``baselines.orca.time_horizon=3``, ``agent.per_variant.maspm.gamma=0.9``); the value is
    parsed as YAML, so ``vae.kl_weight=0.5`` is a float and ``env.human_policy=sfm`` a string.
    Missing keys take their defaults (which equal the shipped params.yaml). Raises
    :class:`ConfigError`, naming the file, overlay or ``--set`` a bad value came from.
    """
    source = str(path)
    raw = _read_yaml_mapping(path)
    # The error for a bad value names where it came from: the file, the overlay or the --set
    # that wrote it (the last writer of the key or of a mapping above it).
    origins: list[tuple[str, str]] = []
    for overlay in overlays:
        content = _read_yaml_mapping(overlay)
        origins += [(key, str(overlay)) for key in _merge(raw, content)]
    for section, content in list(raw.items()):
        if content is None and _is_model(_child(Params, str(section))[1]):
            raw[section] = {}  # `lstm:` left empty means "all defaults"
    for override in overrides:
        label = f"--set {override}"
        origins.append((_apply_override(raw, override, label), label))

    try:
        return Params.model_validate(raw)
    except ValidationError as exc:
        raise _translate(exc, source, origins) from None


def _translate(
    exc: ValidationError, source: str, origins: Sequence[tuple[str, str]]
) -> ConfigError:
    """One line out of pydantic's report: the first error, plus how many more there are."""
    errors = exc.errors()
    key, message = _describe(errors[0])
    more = len(errors) - 1
    tail = f" (and {more} more error{'s' if more > 1 else ''})" if more else ""
    # An error inside a value (``agent.trunk_sizes.1``) comes from whoever wrote the whole value.
    origin = next(
        (
            label
            for set_key, label in reversed(origins)
            if key == set_key or key.startswith(f"{set_key}.")
        ),
        source,
    )
    return ConfigError(f"{origin}: {message}{tail}")


def _describe(error: Mapping[str, Any]) -> tuple[str, str]:
    """The dotted key an error is about, and ``<key>: <what is wrong>``."""
    if error["type"] in ("extra_forbidden", "unexpected_keyword_argument"):
        key = ".".join(str(part) for part in error["loc"])
        return key, _unknown_key(key)
    return describe_error(error)


# ---------------------------------------------------------------------------------------------
# Output
# ---------------------------------------------------------------------------------------------

STAGE_SECTIONS: dict[str, tuple[str, ...]] = {
    "collect": ("seed", "env", "collect"),
    "train_vae": ("seed", "vae"),
    "train_lstm": ("seed", "lstm"),
    "train_agent": ("env", "agent"),
    "evaluate": ("env", "eval", "experiment.seeds"),
    "evaluate_baseline": ("env", "eval", "baselines"),
    "evaluate_planner": ("env", "eval", "planning"),
    "evaluate_wm_mpc": ("env", "eval", "planning"),
    "evaluate_vae_lstm_mpc": ("env", "eval", "planning"),
    "train_planning_model": ("env", "planning_model"),
    "predict": ("env", "prediction", "planning_model.seeds"),
    "report": ("env", "eval", "report", "agent.solved_window", "agent.solved_success_rate"),
    "study_horizon": ("env", "eval", "agent", "studies.horizon"),
    "study_seeds": ("env", "eval", "agent", "studies.seeds"),
    "study_sort_humans": ("env", "eval", "agent", "studies.sort_humans"),
    "scenario_robots": ("env", "eval", "baselines"),
    "scenario_planners": ("env", "eval", "planning"),
    "scenario_collect": ("seed", "env", "collect"),
    "scenario_planning_model": ("env", "planning_model"),
    "scenario_wm_mpc": ("env", "eval", "planning"),
    "scenario_predict": ("env", "prediction", "planning"),
    "scenario_blind_oracle": ("env", "eval", "planning"),
    "scenario_transfer": ("env", "eval", "planning"),
    "scenario_vae": ("seed", "vae"),
    "scenario_lstm": ("seed", "lstm"),
    "scenario_dqn": ("env", "eval", "agent", "studies.presets"),
    "scenario_critic": ("env", "agent"),
    "scenario_wm_mpc_q": ("env", "eval", "planning"),
    "scenario_cv_model": ("env", "planning_model"),
    "scenario_cv_q": ("env", "eval", "planning"),
    "scenario_model_seeds": ("env", "planning_model"),
    "scenario_wm_mpc_q_seeds": ("env", "eval", "planning"),
    "scenarios_report": (),
}
"""Per DVC stage, the parts of params.yaml it reads: dvc.yaml's ``params:`` lists (a dotted
name is one key of a section). ``evaluate_baseline`` reads ``baselines.<its baseline>`` only:
pass ``(*STAGE_SECTIONS["evaluate_baseline"][:-1], f"baselines.{name}")`` to write just that.
Give one to :func:`save_resolved` so that a stage's output does not change with parameters
it never reads."""


def params_dict(params: Params) -> dict[str, Any]:
    """The resolved configuration as plain, JSON-able nested dicts (sections in model order)."""
    return params.model_dump(mode="json")


def select_sections(data: Mapping[str, Any], sections: Iterable[str]) -> dict[str, Any]:
    """The parts of ``data`` (a :func:`params_dict`) named by ``sections``, in ``data``'s
    order: top-level names (``env``) or dotted paths (``agent.solved_window``)."""
    wanted = [name.split(".") for name in sections]
    picked: dict[str, Any] = {}
    for parts in wanted:
        source: Any = data
        for depth, part in enumerate(parts):
            if not isinstance(source, Mapping) or part not in source:
                raise ValueError(f"unknown section {'.'.join(parts[: depth + 1])!r}")
            source = source[part]
        target = picked
        for part in parts[:-1]:
            target = target.setdefault(part, {})
        target[parts[-1]] = copy.deepcopy(source)
    return _in_order(picked, data)


def _in_order(picked: Mapping[str, Any], data: Mapping[str, Any]) -> dict[str, Any]:
    return {
        key: _in_order(picked[key], data[key])
        if isinstance(picked[key], dict) and isinstance(data[key], Mapping)
        else picked[key]
        for key in data
        if key in picked
    }


def flatten(d: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{"vae": {"kl_weight": 1.0}}`` -> ``{"vae.kl_weight": 1.0}`` (for MLflow params)."""
    flat: dict[str, Any] = {}
    for key, value in d.items():
        dotted = f"{prefix}{key}"
        if isinstance(value, Mapping) and value:
            flat.update(flatten(value, prefix=f"{dotted}."))
        else:
            flat[dotted] = value
    return flat


def save_resolved(params: Params, path: str | Path, sections: Iterable[str] | None = None) -> None:
    """Write the resolved configuration as YAML (atomically); :func:`load_params` reads it back.

    ``sections`` (e.g. ``STAGE_SECTIONS["collect"]``): write only those top-level sections or
    dotted keys, so that the file changes only with what the stage reads; None writes all.
    Reading a partial file back gives the defaults for the rest.
    """
    data = params_dict(params)
    if sections is not None:
        data = select_sections(data, sections)
    body = yaml.safe_dump(data, sort_keys=False, default_flow_style=False, allow_unicode=True)
    what = "" if sections is None else " (the sections the stage reads)"
    header = (
        f"# Resolved configuration{what}: params.yaml + overlays + overrides + defaults; "
        "written by socnav-wm.\n"
    )
    with atomic_path(path) as tmp:
        tmp.write_text(header + body, encoding="utf-8")
