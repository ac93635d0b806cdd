"""Typed, validated configuration: ``params.yaml`` is the single source of every stage's settings.

One pydantic model per section (``collect``, ``vae``, ``lstm``; ``env`` is the simulator's own
:class:`~pipeline.env.params.EnvParams` dataclass) under the top-level :class:`Params`. Every
section has defaults, so a partial ``params.yaml`` works and the shipped file only lists what a
reader should see. Attribute docstrings become the fields' descriptions (the documentation).

Every problem — a missing file, bad YAML, an unknown key, a value out of range, a malformed
``--set`` override — raises :class:`ConfigError` with a single line naming the source, the
dotted key and what is wrong, e.g.
``params.yaml: vae.batch_size: Input should be greater than 0 (got -3)``.
"""

from __future__ import annotations

import dataclasses
import difflib
import re
import typing
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from pipeline.agents.params import METHOD_NAMES, VARIANT_NAMES, AgentParams
from pipeline.env.params import EnvParams
from pipeline.io import atomic_path

Device = Literal["auto", "cpu", "cuda"]

__all__ = [
    "AgentParams",
    "BaselinesParams",
    "CollectParams",
    "ConfigError",
    "Device",
    "EvalParams",
    "ExperimentParams",
    "LstmParams",
    "Params",
    "ReportParams",
    "VaeParams",
    "flatten",
    "load_params",
    "params_dict",
    "save_resolved",
]


class ConfigError(ValueError):
    """A configuration problem, described in one line: ``<source>: <key>: <what is wrong>``."""


# ---------------------------------------------------------------------------------------------
# The models
# ---------------------------------------------------------------------------------------------

# Numbers are strict: YAML already types them, so `batch_size: 512.0` or `seed: true` is a slip
# worth reporting rather than silently coercing. Floats must be finite: `.inf` passes `gt=0`.
_SECTION_CONFIG = ConfigDict(
    extra="forbid", frozen=True, strict=True, use_attribute_docstrings=True
)


class CollectParams(BaseModel):
    """Random-policy rollouts written to ``data/rollouts/shard-*.parquet``."""

    model_config = _SECTION_CONFIG

    episodes: int = Field(4000, gt=0)
    """Number of complete episodes to record."""
    num_envs: int = Field(512, gt=0)
    """Environments stepped together in one batch (memory and speed, not the data)."""
    max_rows_per_shard: int = Field(400_000, gt=0)
    """A Parquet shard is closed once it holds this many steps (rows)."""


class VaeParams(BaseModel):
    """The VAE that compresses the 23-d observation into a latent vector."""

    model_config = _SECTION_CONFIG

    latent_dim: int = Field(16, gt=0)
    """Size of the latent vector z."""
    hidden_dim: int = Field(256, gt=0)
    """Width of the encoder and decoder hidden layers."""
    kl_weight: float = Field(1.0, ge=0, allow_inf_nan=False)
    """Weight of the KL term against the reconstruction loss (1 is the plain ELBO)."""
    learning_rate: float = Field(1e-3, gt=0, allow_inf_nan=False)
    """Adam learning rate."""
    batch_size: int = Field(512, gt=0)
    """Observations per gradient step."""
    max_epochs: int = Field(40, gt=0)
    """Upper bound on passes over the training split."""
    patience: int = Field(5, gt=0)
    """Stop after this many epochs without a better validation loss."""
    val_fraction: float = Field(0.05, gt=0, le=0.5, allow_inf_nan=False)
    """Fraction of episodes held out for validation (split by episode, never by step)."""
    device: Device = "auto"
    """`auto` uses CUDA when available, else the CPU."""


class LstmParams(BaseModel):
    """The LSTM that predicts the next latent from the latent and the action."""

    model_config = _SECTION_CONFIG

    hidden_dim: int = Field(256, gt=0)
    """Size of the LSTM hidden and cell states."""
    seq_len: int = Field(16, ge=2)
    """Length of the training windows (steps); at least 2 to have one transition."""
    learning_rate: float = Field(1e-3, gt=0, allow_inf_nan=False)
    """Adam learning rate."""
    batch_size: int = Field(256, gt=0)
    """Windows per gradient step."""
    max_epochs: int = Field(40, gt=0)
    """Upper bound on passes over the training split."""
    patience: int = Field(5, gt=0)
    """Stop after this many epochs without a better validation loss."""
    val_fraction: float = Field(0.05, gt=0, le=0.5, allow_inf_nan=False)
    """Fraction of episodes held out for validation (split by episode, never by step)."""
    device: Device = "auto"
    """`auto` uses CUDA when available, else the CPU."""


class ExperimentParams(BaseModel):
    """Which agents the pipeline trains: every variant × every seed (``dvc.yaml``'s matrix)."""

    model_config = _SECTION_CONFIG

    variants: list[str] = Field(default_factory=lambda: list(VARIANT_NAMES), min_length=1)
    """Agent variants to train and evaluate (pipeline/agents/params.py lists them)."""
    seeds: list[int] = Field(default_factory=lambda: [0, 1, 2], min_length=1)
    """Training seeds of every variant; results are reported over seeds and scenarios."""

    @field_validator("variants")
    @classmethod
    def _known_variants(cls, value: list[str]) -> list[str]:
        for name in value:
            if name not in VARIANT_NAMES:
                raise ValueError(f"unknown {name!r}; expected some of {', '.join(VARIANT_NAMES)}")
        if len(set(value)) != len(value):
            raise ValueError(f"a variant is listed twice in {value}")
        return value

    @field_validator("seeds")
    @classmethod
    def _distinct_seeds(cls, value: list[int]) -> list[int]:
        if any(seed < 0 for seed in value):
            raise ValueError(f"must be non-negative, got {value}")
        if len(set(value)) != len(value):
            raise ValueError(f"a seed is listed twice in {value}")
        return value


class EvalParams(BaseModel):
    """The paired test: every method runs the same scenarios ``0..episodes-1``."""

    model_config = _SECTION_CONFIG

    episodes: int = Field(500, gt=0)
    """Test scenarios per method and training seed (the paper: 500)."""
    scenario_seed: int = Field(1_000_003, ge=0)
    """Seed of the test scenarios; training scenarios use other seeds (never these)."""
    batch_size: int = Field(500, gt=0)
    """Scenarios simulated together (speed only: results do not depend on it)."""
    device: Device = "auto"
    """Where the agents' networks run."""


class BaselinesParams(BaseModel):
    """Overrides of the ORCA and Social Force robots' parameters (pipeline/agents/baselines.py
    documents each; empty: the defaults)."""

    model_config = _SECTION_CONFIG

    orca: dict[str, float | int] = Field(default_factory=dict)
    """OrcaBaselineParams fields, e.g. safety_margin: 0.2."""
    sfm: dict[str, float | int] = Field(default_factory=dict)
    """SfmBaselineParams fields, e.g. human_strength: 0.4."""

    @field_validator("orca", "sfm")
    @classmethod
    def _valid_overrides(cls, value: dict[str, Any], info: Any) -> dict[str, Any]:
        from pipeline.agents.baselines import make_baseline

        make_baseline(info.field_name, **value)  # one-line error naming a bad key or value
        return value


class ReportParams(BaseModel):
    """The report: paired tests, figures."""

    model_config = _SECTION_CONFIG

    reference: str = "dueling-dqn"
    """The method every other is compared with, scenario by scenario."""
    alpha: float = Field(0.05, gt=0, lt=1, allow_inf_nan=False)
    """Family-wise error rate of the paired tests (Holm-corrected)."""
    smoothing_window: int = Field(100, gt=0)
    """Rolling-mean window of the training curves (episodes)."""
    gif_scenarios: list[Annotated[int, Field(ge=0)]] = Field(default_factory=lambda: [0, 1, 2])
    """Test scenarios shown side by side in reports/figures/scenarios.gif (empty: no GIF)."""

    @field_validator("reference")
    @classmethod
    def _known_method(cls, value: str) -> str:
        if value not in METHOD_NAMES:
            raise ValueError(f"unknown method {value!r}; expected one of {', '.join(METHOD_NAMES)}")
        return value


_ENV_TYPES: dict[str, Any] = typing.get_type_hints(EnvParams)
_AGENT_TYPES: dict[str, Any] = typing.get_type_hints(AgentParams)


def _check_strict_types(section: str, hints: Mapping[str, Any], value: Any) -> Any:
    """Strict YAML types for a section that is a stdlib dataclass (``env``, ``agent``).

    A stdlib dataclass cannot take ``strict=True``, and in lax mode pydantic would read
    ``num_humans: true`` as 1 or ``orca_avoid_robot: "no"`` as False: check the types here so
    these sections are as strict as the others.
    """
    if not isinstance(value, Mapping):
        return value
    for name, given in value.items():
        expected = hints.get(name)
        if expected is bool and not isinstance(given, bool):
            raise ValueError(f"{section}.{name}: expected true or false, got {given!r}")
        if expected is int and (isinstance(given, bool) or not isinstance(given, int)):
            raise ValueError(f"{section}.{name}: expected an integer, got {given!r}")
        if expected is float and (isinstance(given, bool) or not isinstance(given, int | float)):
            raise ValueError(f"{section}.{name}: expected a number, got {given!r}")
        if typing.get_origin(expected) is Literal and not isinstance(given, str):
            choices = ", ".join(map(str, typing.get_args(expected)))
            raise ValueError(f"{section}.{name}: must be one of {choices}, got {given!r}")
        if typing.get_origin(expected) is tuple and not isinstance(given, list | tuple):
            raise ValueError(f"{section}.{name}: expected a list, got {given!r}")
    return value


class Params(BaseModel):
    """Everything ``params.yaml`` can hold; every section is optional."""

    model_config = ConfigDict(extra="forbid", frozen=True, use_attribute_docstrings=True)

    seed: int = Field(0, ge=0, strict=True)
    """Master seed: every random generator of every stage derives from it."""
    env: EnvParams = Field(default_factory=EnvParams)
    """The simulator's scenario (paper values by default); see pipeline/env/params.py."""
    collect: CollectParams = Field(default_factory=CollectParams)
    """Random-policy data collection."""
    vae: VaeParams = Field(default_factory=VaeParams)
    """VAE training."""
    lstm: LstmParams = Field(default_factory=LstmParams)
    """LSTM world-model training."""
    agent: AgentParams = Field(default_factory=AgentParams)
    """The Dueling DQN agents (all five variants); see pipeline/agents/params.py."""
    experiment: ExperimentParams = Field(default_factory=ExperimentParams)
    """Variants and training seeds of the pipeline."""
    eval: EvalParams = Field(default_factory=EvalParams)
    """The paired evaluation on test scenarios."""
    baselines: BaselinesParams = Field(default_factory=BaselinesParams)
    """ORCA and Social Force robots."""
    report: ReportParams = Field(default_factory=ReportParams)
    """Statistics and figures of the report."""

    @field_validator("agent", mode="before")
    @classmethod
    def _agent_types_are_strict(cls, value: Any) -> Any:
        return _check_strict_types("agent", _AGENT_TYPES, value)

    @field_validator("env", mode="before")
    @classmethod
    def _env_types_are_strict(cls, value: Any) -> Any:
        return _check_strict_types("env", _ENV_TYPES, value)


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
        problem = _one_line(exc.problem or exc.context or "syntax error")
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        raise ConfigError(f"{source}: not valid YAML ({where}{problem})") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{source}: not valid YAML ({_one_line(str(exc))})") from None


# ---------------------------------------------------------------------------------------------
# Loading
# ---------------------------------------------------------------------------------------------


def _section_keys() -> dict[str, set[str] | None]:
    """Top-level key -> the keys its section accepts (None for a plain top-level value)."""
    keys: dict[str, set[str] | None] = {}
    for name, field in Params.model_fields.items():
        annotation = field.annotation
        if isinstance(annotation, type) and issubclass(annotation, BaseModel):
            keys[name] = set(annotation.model_fields)
        elif dataclasses.is_dataclass(annotation):
            keys[name] = {f.name for f in dataclasses.fields(annotation)}
        else:
            keys[name] = None
    return keys


def _unknown_key(dotted: str) -> str:
    """``unknown key 'vae.bacth_size' (did you mean 'vae.batch_size'?)``."""
    sections = _section_keys()
    section, _, name = dotted.partition(".")
    if name and sections.get(section):
        candidates = [f"{section}.{key}" for key in sections[section] or ()]
    else:
        candidates = list(sections)
    close = difflib.get_close_matches(dotted, candidates, n=1, cutoff=0.75)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    return f"unknown key {dotted!r}{hint}"


def _apply_override(raw: dict[str, Any], override: str, source: str) -> str:
    """Set one ``section.key=value`` in the raw mapping; returns the dotted key."""
    key, sep, text = override.partition("=")
    key = key.strip()
    if not sep or not key or any(not part for part in key.split(".")):
        raise ConfigError(f"{source}: expected section.key=value")
    sections = _section_keys()
    parts = key.split(".")
    if len(parts) > 2 or parts[0] not in sections:
        raise ConfigError(f"{source}: {_unknown_key(key)}")
    section_keys = sections[parts[0]]
    if len(parts) == 1:
        if section_keys is not None:
            raise ConfigError(f"{source}: {key!r} is a section; use {key}.key=value")
    elif section_keys is None or parts[1] not in section_keys:
        raise ConfigError(f"{source}: {_unknown_key(key)}")

    value = _parse_yaml(text, source)
    if len(parts) == 1:
        raw[key] = value
    else:
        section = raw.setdefault(parts[0], {})
        if section is None:  # `vae:` with nothing under it
            section = raw[parts[0]] = {}
        if not isinstance(section, dict):
            raise ConfigError(f"{source}: {parts[0]}: expected a mapping, got {section!r}")
        section[parts[1]] = value
    return key


def load_params(path: str | Path = "params.yaml", overrides: Sequence[str] = ()) -> Params:
    """Read, override and validate ``params.yaml``.

    ``overrides`` are ``section.key=value`` strings (``seed=3`` for a top-level key); the value
    is parsed as YAML, so ``vae.kl_weight=0.5`` is a float and ``env.human_policy=sfm`` a string.
    Sections missing from the file take their defaults. Raises :class:`ConfigError`.
    """
    source = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"{source}: file not found") from None
    except IsADirectoryError:
        raise ConfigError(f"{source}: is a directory, expected a YAML file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{source}: cannot read ({_one_line(str(exc))})") from None

    raw = _parse_yaml(text, source)
    if raw is None:  # an empty file: all defaults
        raw = {}
    if not isinstance(raw, dict):
        raise ConfigError(f"{source}: expected a mapping of sections, got {type(raw).__name__}")
    for section, content in list(raw.items()):
        if content is None and _section_keys().get(str(section)) is not None:
            raw[section] = {}  # `lstm:` left empty means "all defaults"

    # The error for a bad value names where it came from: the file or the --set that wrote it.
    origins: dict[str, str] = {}
    for override in overrides:
        label = f"--set {override}"
        origins[_apply_override(raw, override, label)] = label

    try:
        return Params.model_validate(raw)
    except ValidationError as exc:
        raise _translate(exc, source, origins) from None


def _translate(exc: ValidationError, source: str, origins: Mapping[str, str]) -> ConfigError:
    """One line out of pydantic's report: the first error, plus how many more there are."""
    errors = exc.errors()
    key, message = _describe(errors[0])
    more = len(errors) - 1
    tail = f" (and {more} more error{'s' if more > 1 else ''})" if more else ""
    # An error inside a value (``agent.trunk_sizes.1``) comes from the --set of the whole value.
    origin = next(
        (
            label
            for set_key, label in origins.items()
            if key == set_key or key.startswith(f"{set_key}.")
        ),
        source,
    )
    return ConfigError(f"{origin}: {message}{tail}")


def _describe(error: Mapping[str, Any]) -> tuple[str, str]:
    """The dotted key an error is about, and ``<key>: <what is wrong>``."""
    key = ".".join(str(part) for part in error["loc"])
    kind = error["type"]
    given = error.get("input")
    if kind in ("extra_forbidden", "unexpected_keyword_argument"):
        return key, _unknown_key(key)
    if kind == "value_error":
        # Our own checks (and EnvParams.__post_init__) already write "env.room_size: ...".
        text = _one_line(str(error.get("ctx", {}).get("error", error["msg"])))
        match = re.match(r"^([A-Za-z_][\w.]*): ", text)
        if match and (not key or match.group(1).startswith(key)):
            return match.group(1), text
        return key, f"{key}: {text}" if key else text
    if kind == "literal_error":
        choices = ", ".join(re.findall(r"'([^']*)'", error.get("ctx", {}).get("expected", "")))
        return key, f"{key}: must be one of {choices}, got {given!r}"
    if kind in ("model_type", "dataclass_type", "model_attributes_type"):
        return key, f"{key}: expected a mapping of keys, got {_short_repr(given)}"
    if kind == "missing":
        return key, f"{key}: required"
    return key, f"{key}: {_one_line(error['msg'])} (got {_short_repr(given)})"


def _short_repr(value: Any, limit: int = 60) -> str:
    text = _one_line(repr(value))
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _one_line(text: str) -> str:
    return " ".join(text.split())


# ---------------------------------------------------------------------------------------------
# Output
# ---------------------------------------------------------------------------------------------


def params_dict(params: Params) -> dict[str, Any]:
    """The resolved configuration as plain, JSON-able nested dicts (sections in model order)."""
    return params.model_dump(mode="json")


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


def save_resolved(params: Params, path: str | Path) -> None:
    """Write the resolved configuration as YAML (atomically); :func:`load_params` reads it back."""
    body = yaml.safe_dump(
        params_dict(params), sort_keys=False, default_flow_style=False, allow_unicode=True
    )
    header = (
        "# Resolved configuration (params.yaml + overrides + defaults); written by socnav-wm.\n"
    )
    with atomic_path(path) as tmp:
        tmp.write_text(header + body, encoding="utf-8")
