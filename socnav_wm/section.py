"""What every configuration section shares: the strict frozen base :class:`Section`, the one-line
wording of a validation error (:func:`describe_error`), and the field helpers and validators the
sections use. The lowest layer of the configuration: the simulator's ``env`` section, the agents',
the planners' and :mod:`socnav_wm.config` (which only composes the sections) all build on it,
and it imports nothing of the project.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping
from typing import Annotated, Any, ClassVar, Literal, Self

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError

__all__ = [
    "DEVICES",
    "SECTION_CONFIG",
    "SEED_LIMIT",
    "Device",
    "Section",
    "Seed",
    "as_tuple",
    "check_seed",
    "describe_error",
    "describe_errors",
    "distinct_non_negative",
    "finite",
    "non_negative",
    "one_line",
    "positive",
    "seed_field",
    "short_repr",
]

Device = Literal["auto", "cpu", "cuda"]
"""Where a network runs: ``auto`` uses CUDA when available, else the CPU."""
DEVICES: tuple[str, ...] = ("auto", "cpu", "cuda")

# Numbers are strict: YAML already types them, so `batch_size: 512.0` or `seed: true` is a slip
# worth reporting rather than silently coercing (an int is accepted where a float is expected).
# Floats must be finite (`allow_inf_nan=False` on every float field): `.inf` passes `gt=0`.
SECTION_CONFIG = ConfigDict(extra="forbid", frozen=True, strict=True, use_attribute_docstrings=True)

_NAMED = re.compile(r"^([A-Za-z_][\w.-]*): (.*)$", re.DOTALL)


def one_line(text: str) -> str:
    """``text`` with every run of whitespace (newlines included) made one space."""
    return " ".join(text.split())


def short_repr(value: Any, limit: int = 60) -> str:
    """``repr(value)`` on one line, cut to ``limit`` characters."""
    text = one_line(repr(value))
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _bound(value: Any) -> Any:
    """``0`` rather than ``0.0`` in a message about a float field's bound."""
    return int(value) if isinstance(value, float) and value.is_integer() else value


def describe_error(error: Mapping[str, Any], prefix: str = "") -> tuple[str, str]:
    """One pydantic error as ``(dotted key, "<key>: <what is wrong>")``, in the project's words.

    ``prefix`` is the dotted name of the model that was validated (``env``, ``baselines.orca``;
    empty for the top level). A ``ValueError`` raised by a model validator as ``"field: text"``
    is about that field of the model. An unknown key gives ``"<key>: unknown option"`` (the
    configuration loader words it with a suggestion instead).
    """
    parts = [prefix] if prefix else []
    parts += [str(part) for part in error["loc"]]
    key = ".".join(parts)
    kind = error["type"]
    ctx = error.get("ctx") or {}
    got = f"got {short_repr(error.get('input'))}"
    if kind == "value_error":
        text = " ".join(str(ctx.get("error", error["msg"])).split())
        match = _NAMED.match(text)
        if match:  # "field: text" from a model validator (or already "section.field: text")
            named = match.group(1)
            key = named if not key or named.startswith(f"{key}.") else f"{key}.{named}"
            text = match.group(2)
        return key, f"{key}: {text}" if key else text
    simple = {
        "greater_than": f"must be > {_bound(ctx.get('gt'))}, {got}",
        "greater_than_equal": f"must be >= {_bound(ctx.get('ge'))}, {got}",
        "less_than": f"must be < {_bound(ctx.get('lt'))}, {got}",
        "less_than_equal": f"must be <= {_bound(ctx.get('le'))}, {got}",
        "finite_number": f"must be finite, {got}",
        "int_type": f"expected an integer, {got}",
        "int_from_float": f"expected an integer, {got}",
        "int_parsing": f"expected an integer, {got}",
        "float_type": f"expected a number, {got}",
        "float_parsing": f"expected a number, {got}",
        "bool_type": f"expected true or false, {got}",
        "bool_parsing": f"expected true or false, {got}",
        "string_type": f"expected a string, {got}",
        "list_type": f"expected a list, {got}",
        "tuple_type": f"expected a list, {got}",
        "dict_type": f"expected a mapping of keys, {got}",
        "model_type": f"expected a mapping of keys, {got}",
        "model_attributes_type": f"expected a mapping of keys, {got}",
        "too_short": f"must have at least {ctx.get('min_length')} item(s), {got}",
        "extra_forbidden": "unknown option",
        "unexpected_keyword_argument": "unknown option",
        "missing": "required",
    }
    if kind == "literal_error":
        choices = ", ".join(re.findall(r"'([^']*)'", str(ctx.get("expected", ""))))
        text = f"must be one of {choices}, {got}"
    elif kind in simple:
        text = simple[kind]
    else:
        text = f"{' '.join(str(error['msg']).split())} ({got})"
    return key, f"{key}: {text}" if key else text


def describe_errors(exc: ValidationError, prefix: str = "") -> str:
    """The first error of ``exc`` in one line, plus how many more there are."""
    errors = exc.errors()
    _, message = describe_error(errors[0], prefix)
    more = len(errors) - 1
    return message + (f" (and {more} more error{'s' if more > 1 else ''})" if more else "")


class Section(BaseModel):
    """A strict, frozen configuration section with one-line errors named by dotted key.

    ``SECTION`` is the section's dotted name in ``params.yaml`` (``env``, ``agent``,
    ``baselines.orca``): building one in Python with a bad value raises a ``ValueError`` whose
    single line starts with ``<SECTION>.<field>:``.
    """

    model_config = SECTION_CONFIG

    SECTION: ClassVar[str] = ""

    def __init__(self, /, **values: Any) -> None:
        try:
            super().__init__(**values)
        except ValidationError as exc:
            raise ValueError(describe_errors(exc, type(self).SECTION)) from None

    # Validation inside another model (``Params``, ``model_validate``) must not go through this
    # __init__: pydantic would call it and get one flattened ValueError instead of the errors
    # with their locations. Marking it as pydantic's own __init__ keeps the plain path there.
    __init__.__pydantic_base_init__ = True  # type: ignore[attr-defined]

    def replace(self, **changes: Any) -> Self:
        """A copy with ``changes`` applied, validated like a new instance."""
        current = {name: getattr(self, name) for name in type(self).model_fields}
        return type(self)(**{**current, **changes})

    def __hash__(self) -> int:  # a dict field (agent.per_variant) is not hashable: hash the JSON
        return hash(json.dumps(self.to_dict(), sort_keys=True))

    def to_dict(self) -> dict[str, Any]:
        """The values as a plain, JSON-able dict (lists, not tuples)."""
        return self.model_dump(mode="json")

    # -- per-name overrides (agent.per_variant, planning.per_method) ------------------------------

    def _check_overrides(self, field: str, names: tuple[str, ...], kind: str) -> None:
        """Check the overrides in ``field`` (a dict: name → changes of the other fields): every
        name is one of ``names`` (each a ``kind``, e.g. ``variant``), and the section with each
        name's changes applied is valid.

        Raises:
            ValueError: one line naming ``field.name`` (and the key) at fault.
        """
        shared = {name: getattr(self, name) for name in type(self).model_fields}
        shared[field] = {}
        for name, changes in getattr(self, field).items():
            if name not in names:
                raise ValueError(
                    f"{field}: unknown {kind} {name!r}; expected some of {', '.join(names)}"
                )
            if field in changes:
                raise ValueError(f"{field}.{name}.{field}: cannot be nested")
            try:
                type(self).model_validate({**shared, **changes})
            except ValidationError as exc:
                _, message = describe_error(exc.errors()[0], f"{field}.{name}")
                raise ValueError(message) from None

    def _overridden(self, field: str, name: str) -> Self:
        """``self`` with ``field[name]``'s changes applied and ``field`` emptied (``self`` itself
        when ``field`` is empty)."""
        overrides = getattr(self, field)
        if not overrides:
            return self
        return self.replace(**overrides.get(name, {}), **{field: {}})

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> Self:
        """Build from a mapping, naming any unknown key in the error."""
        unknown = sorted(set(values) - set(cls.model_fields))
        if unknown:
            raise ValueError(f"{cls.SECTION}: unknown option(s) {', '.join(map(str, unknown))}")
        return cls(**values)


def finite(default: float, **bounds: float) -> Any:
    """A float field with ``default`` that must be finite (and within ``bounds``: gt, ge, le…)."""
    return Field(default, allow_inf_nan=False, **bounds)


def positive(default: float) -> Any:
    """A finite float field with ``default`` that must be > 0."""
    return finite(default, gt=0)


def non_negative(default: float) -> Any:
    """A finite float field with ``default`` that must be >= 0."""
    return finite(default, ge=0)


def as_tuple(value: Any) -> Any:
    """A YAML list as a tuple (a ``BeforeValidator``), so that the frozen section stays hashable."""
    return tuple(value) if isinstance(value, list) else value


SEED_LIMIT = 2**63
"""Seeds are below 2**63: the simulator's compiled kernels take a seed as a 64-bit signed
integer (a larger one fails to compile, a wider one would be reduced)."""


def check_seed(value: int, name: str = "seed") -> int:
    """``value`` if it is a seed the kernels take (0 ≤ value < 2**63), else a ValueError naming
    ``name`` in one line."""
    if not 0 <= value < SEED_LIMIT:
        raise ValueError(f"{name}: must be in 0..2**63 - 1, got {value}")
    return value


def _seed(value: int) -> int:
    if value >= SEED_LIMIT:
        raise ValueError(f"must be < 2**63 (the simulator's seeds are 63-bit), got {value}")
    return value


def seed_field(default: int) -> Any:
    """A seed field with ``default``: an integer in 0..2**63 - 1."""
    return Field(default, ge=0)


Seed = Annotated[int, AfterValidator(_seed)]
"""A seed's type (with :func:`seed_field`): below 2**63."""


def distinct_non_negative(value: list[int]) -> list[int]:
    """``value`` (seeds) if none is negative or 2**63 or more and none is listed twice, else a
    ValueError."""
    if any(seed < 0 for seed in value):
        raise ValueError(f"must be non-negative, got {value}")
    if any(seed >= SEED_LIMIT for seed in value):
        raise ValueError(f"must be < 2**63 (the simulator's seeds are 63-bit), got {value}")
    if len(set(value)) != len(value):
        raise ValueError(f"a seed is listed twice in {value}")
    return value
