"""Scenario parameters of the simulator, with the paper's values as defaults (paper_spec §1–§3).

One frozen pydantic model, validated on construction: ``gym.make("SocNav-v0", **kwargs)``,
``params.yaml``'s ``env`` section and the tests all build it, so a bad value gets the same
one-line error everywhere.

This module also holds :class:`Section`, the strict base of every configuration section (here,
in the lowest layer, so that :mod:`socnav_wm.agents.params` and :mod:`socnav_wm.agents.baselines`
can share it without importing :mod:`socnav_wm.config`), and :func:`describe_error`, the
one-line wording of a validation error that :mod:`socnav_wm.config` uses too.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from typing import Any, ClassVar, Literal, Self

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

__all__ = [
    "HUMAN_POLICIES",
    "REWARD_KINDS",
    "SECTION_CONFIG",
    "EnvParams",
    "Section",
    "describe_error",
    "describe_errors",
]

HumanPolicy = Literal["mixed", "sfm", "orca"]
RewardKind = Literal["paper", "dense"]

HUMAN_POLICIES: tuple[str, ...] = ("mixed", "sfm", "orca")
REWARD_KINDS: tuple[str, ...] = ("paper", "dense")

# Numbers are strict: YAML already types them, so `batch_size: 512.0` or `seed: true` is a slip
# worth reporting rather than silently coercing (an int is accepted where a float is expected).
# Floats must be finite (`allow_inf_nan=False` on every float field): `.inf` passes `gt=0`.
SECTION_CONFIG = ConfigDict(extra="forbid", frozen=True, strict=True, use_attribute_docstrings=True)

_NAMED = re.compile(r"^([A-Za-z_][\w.-]*): (.*)$", re.DOTALL)


def _short_repr(value: Any, limit: int = 60) -> str:
    text = " ".join(repr(value).split())
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
    got = f"got {_short_repr(error.get('input'))}"
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


def _positive(default: float) -> Any:
    return Field(default, gt=0, allow_inf_nan=False)


def _non_negative(default: float) -> Any:
    return Field(default, ge=0, allow_inf_nan=False)


def _finite(default: float) -> Any:
    return Field(default, allow_inf_nan=False)


class EnvParams(Section):
    """Every constant of the scenario. Lengths in metres, speeds in m/s, angles in radians."""

    SECTION: ClassVar[str] = "env"

    num_humans: int = Field(3, ge=0)
    """Number of people in the room."""
    room_size: float = _positive(10.0)
    """Outer side of the square room (m), centred at the origin."""
    wall_thickness: float = _non_negative(0.2)
    """Walls lie inside the room's outline; their inner faces are at ±(room_size/2 − thickness)."""
    spawn_margin: float = _non_negative(0.5)
    """Robot, humans and goals are drawn uniformly in ±(room_size/2 − spawn_margin)."""
    dt: float = _positive(1.0)
    """Simulation time step (s)."""
    max_steps: int = Field(201, gt=0)
    """Steps after which an episode is truncated (the paper's env stops when ticks > 200)."""
    robot_radius: float = _positive(0.3)
    """Radius of the robot's disc (m)."""
    robot_max_speed: float = _positive(0.14)
    """Linear speed of the `forward` action and the clip of continuous commands (m/s)."""
    robot_max_rotation: float = _positive(0.387596899)
    """Angular speed of the rotate actions and the clip of continuous commands (rad/s)."""
    goal_radius: float = _positive(0.5)
    """The goal is reached when the robot centre is within robot_radius + goal_radius."""
    min_goal_distance: float = _non_negative(0.0)
    """Minimum initial robot-goal distance (m); 0 reproduces the paper's uniform draw."""
    human_radius: float = _positive(0.36)
    """Radius of a person's disc (m)."""
    human_max_speed: float = _positive(0.14)
    """Preferred (and maximum) walking speed of the people (m/s)."""
    human_goal_radius: float = _non_negative(0.25)
    """A human draws a new goal when within human_radius + human_goal_radius of it."""
    human_speed_threshold: float = _non_negative(0.05)
    """Human speeds below this are set to 0, as in the paper's environment."""
    human_policy: HumanPolicy = "mixed"
    """`mixed` draws SFM or ORCA per human per episode (50/50); `sfm` or `orca` for all."""
    sfm_avoid_robot_prob: float = Field(0.05, ge=0, le=1, allow_inf_nan=False)
    """Probability, per human per step, that an SFM human treats the robot as an obstacle."""
    orca_avoid_robot: bool = False
    """Whether ORCA humans see the robot (as a non-reciprocating agent). The paper: no."""
    reward: RewardKind = "paper"
    """`paper`: paper_spec §3.1 (sparse, refunded on failure); `dense`: per-step penalties."""
    reach_reward: float = _finite(1.0)
    """Reward for reaching the goal."""
    failure_reward: float = _finite(-1.0)
    """Reward for a collision (with a person or a wall)."""
    alive_penalty: float = _finite(-0.0005)
    """`dense` reward: added at every step."""
    discomfort_distance: float = _non_negative(0.9999)
    """`dense` reward: people closer than this to the robot (m) cost discomfort."""
    discomfort_factor: float = _non_negative(0.01)
    """`dense` reward: weight of the discomfort penalty."""
    orca_neighbor_dist: float = _positive(1.44)
    """ORCA humans: others closer than this (m) are avoided."""
    orca_max_neighbors: int = Field(3, gt=0)
    """ORCA humans: at most this many nearest others are avoided."""
    orca_time_horizon: float = _positive(5.0)
    """ORCA humans: collisions with others are avoided over this horizon (s)."""
    orca_time_horizon_obst: float = _positive(5.0)
    """ORCA humans: collisions with walls are avoided over this horizon (s)."""
    sfm_wall_range: float = _positive(0.05)
    """r0 of the exponential wall/robot repulsion exp(−d/r0) (m)."""
    sfm_gamma: float = _positive(0.25)
    """SFM humans: γ of the anisotropic interaction with other humans."""
    sfm_n: float = _finite(1.0)
    """SFM humans: n of the interaction's angular decay."""
    sfm_n_prime: float = _finite(1.0)
    """SFM humans: n′ of the interaction's angular decay (sideways part)."""
    sfm_lambda: float = _finite(1.0)
    """SFM humans: λ weighting the direction of motion against the relative position."""
    sfm_weight: float = _finite(1.0 / math.sqrt(3.0))
    """Weight of each of the three SFM force terms (goal, obstacles, other humans)."""

    @model_validator(mode="after")
    def _fits_in_the_room(self) -> Self:
        if self.spawn_half_size <= max(self.robot_radius, self.human_radius):
            raise ValueError(
                f"room_size: a {self.room_size} m room with spawn_margin "
                f"{self.spawn_margin} leaves no room to spawn anything"
            )
        if self.spawn_half_size > self.wall_half_size:
            raise ValueError("spawn_margin: must be >= wall_thickness (spawns inside the walls)")
        if self.min_goal_distance >= 2 * math.sqrt(2) * self.spawn_half_size:
            raise ValueError(
                f"min_goal_distance: {self.min_goal_distance} m cannot fit in the spawn area"
            )
        # Every disc (robot, its goal, each human and its goal) is drawn so that it touches
        # nothing: beyond the room's area, spawning could never succeed (and would retry for
        # as long as it is let).
        per_human = math.pi * (self.human_radius**2 + self.human_goal_radius**2)
        robot = math.pi * (self.robot_radius**2 + self.goal_radius**2)
        fit = int(((2 * self.wall_half_size) ** 2 - robot) // per_human)
        if self.num_humans > fit:
            raise ValueError(
                f"num_humans: {self.num_humans} humans and their goals cannot be placed in a "
                f"{self.room_size} m room (their discs alone need more than its area; "
                f"at most {max(fit, 0)})"
            )
        return self

    @property
    def wall_half_size(self) -> float:
        """Half-side of the free square inside the walls (m): 4.8 for the paper's room."""
        return self.room_size / 2.0 - self.wall_thickness

    @property
    def spawn_half_size(self) -> float:
        """Half-side of the square where positions and goals are drawn (m): 4.5 by default."""
        return self.room_size / 2.0 - self.spawn_margin

    @property
    def success_distance(self) -> float:
        """Robot-goal centre distance under which the goal is reached (m): 0.8 by default."""
        return self.robot_radius + self.goal_radius
