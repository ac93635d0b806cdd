"""The one check that a model or data file fits the scenarios it is used with.

Every file made from the simulator records the scenarios it was made with (:func:`made_with`,
the whole ``env`` section): the rollouts' shards in their Parquet metadata, the VAE, the LSTM
and the planning model in their saved dict (``env``), an agent in its ``env_params``. A file
written before it recorded them is judged by what it holds: its number of humans, or the size
of the observations it reads, and the area a planning model that knows the room draws goals in.

:func:`check_made_with` is what every loader and every reader of rollouts calls with the
params: the number of humans (hence the size of the observation) and the size of the room must
be the params'. Otherwise one line names the file and both sides::

    models/planning/seed-0.pt: trained with 5 humans in a 10.0 m room; the params have 3 humans
    in a 10.0 m room
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

from socnav_wm.data.schema import FEATURES_PER_HUMAN, GOAL_FEATURES, observation_dim
from socnav_wm.env.observation_layout import observation_size
from socnav_wm.env.params import EnvParams

__all__ = ["BEHAVIOUR_FIELDS", "check_made_with", "made_with", "observation_record"]

BEHAVIOUR_FIELDS = (
    "dt",
    "robot_max_speed",
    "robot_max_rotation",
    "human_max_speed",
    "human_policy",
    "human_speed_range",
    "humans_see_robot",
    "ignore_robot_prob",
    "tables",
    "plants",
    "groups",
    "standing_groups",
    "group_size",
)
"""The ``env`` fields that say how the world moves and what is in it (the scenario preset's
behaviour, beyond the observation's shape): a model or agent trained with other values learned
another world. Using it there is a transfer evaluation, refused unless asked for (``transfer``);
a file that does not record a field is not judged on it."""


def made_with(env_params: EnvParams) -> dict[str, Any]:
    """What a file records of the scenarios it was made with: the whole ``env`` section, as
    plain values."""
    return env_params.to_dict()


def observation_record(obs_dim: int) -> dict[str, Any]:
    """The record of an older file that tells only the size of its observations: its number
    of humans where ``obs_dim`` is one the simulator gives (2 + 7 per human), else the size."""
    humans, rest = divmod(int(obs_dim) - GOAL_FEATURES, FEATURES_PER_HUMAN)
    return {"num_humans": humans} if rest == 0 and humans >= 0 else {"obs_dim": int(obs_dim)}


def _humans(count: int) -> str:
    return f"{count} human{'' if count == 1 else 's'}"


def _check_scenario_kind(
    path: str | os.PathLike[str],
    made: Mapping[str, Any],
    env_params: EnvParams,
    verb: str,
    error: type[ValueError],
) -> None:
    """Refuse a file made for another kind of scenario: another observation layout (K humans,
    M obstacles), robot kinematics or scenario family, each named with both values."""
    humans = int(made.get("num_humans", env_params.num_humans))
    observed = made.get("observed_humans")
    size = observation_size(
        humans if observed is None else int(observed), int(made.get("observed_obstacles", 0))
    )
    ours = observation_size(env_params.num_observed_humans, env_params.observed_obstacles)
    if size != ours:
        raise error(
            f"{path}: {verb} with {size}-d observations; the params give {ours}-d observations "
            "(env.num_humans, env.observed_humans, env.observed_obstacles)"
        )
    for name in ("kinematics", "scenario"):
        theirs = made.get(name, EnvParams.model_fields[name].default)
        if theirs != getattr(env_params, name):
            raise error(
                f"{path}: {verb} with env.{name} {theirs}; the params have "
                f"{getattr(env_params, name)}"
            )


def _check_behaviour(
    path: str | os.PathLike[str],
    made: Mapping[str, Any],
    env_params: EnvParams,
    verb: str,
    error: type[ValueError],
) -> None:
    """Refuse a file made in a world that moves otherwise (:data:`BEHAVIOUR_FIELDS`), naming
    the first field that differs and both values."""
    ours = env_params.to_dict()
    for name in BEHAVIOUR_FIELDS:
        if name not in made:
            continue
        theirs = made[name]
        if isinstance(theirs, list | tuple):
            theirs = list(theirs)
        mine = list(ours[name]) if isinstance(ours[name], list | tuple) else ours[name]
        if theirs != mine:
            raise error(
                f"{path}: {verb} with env.{name} {_shown(theirs)}; the params have "
                f"{_shown(mine)} (another scenario: use it here only as a transfer, --transfer)"
            )


def _shown(value: Any) -> str:
    """A parameter value as a user writes it in params.yaml."""
    if isinstance(value, bool):
        return str(value).lower()
    if value is None:
        return "null"
    return str(value)


def check_made_with(
    path: str | os.PathLike[str],
    made: Mapping[str, Any] | None,
    env_params: EnvParams | None,
    *,
    verb: str = "trained",
    error: type[ValueError] = ValueError,
    transfer: bool = False,
) -> None:
    """Refuse the file ``path`` when what it records of its scenarios (``made``: its ``env``
    record, or for an older file what :func:`observation_record` tells, and a planning model's
    ``spawn_half_size``) differs from ``env_params`` in the number of humans, the size of the
    observation or the size of the room, the observation's layout, the kinematics or the
    scenario family and, unless ``transfer`` (an evaluation of a model of one scenario in
    another, asked for explicitly), in how the world moves (:data:`BEHAVIOUR_FIELDS`). Nothing
    is compared when either side is None, nor what the file does not record.

    Raises:
        error: ``{path}: {verb} with 5 humans in a 10.0 m room; the params have 3 humans in a
            10.0 m room``.
    """
    if made is None or env_params is None:
        return
    _check_shape(path, made, env_params, verb, error)
    if not transfer:
        _check_behaviour(path, made, env_params, verb, error)


def _check_shape(
    path: str | os.PathLike[str],
    made: Mapping[str, Any],
    env_params: EnvParams,
    verb: str,
    error: type[ValueError],
) -> None:
    """What no transfer can bridge: the humans, the observation, the room, the kinematics and
    the scenario family (:func:`check_made_with`)."""
    humans, obs_dim = made.get("num_humans"), made.get("obs_dim")
    room, spawn = made.get("room_size"), made.get("spawn_half_size")
    other_goals = room is None and spawn is not None and spawn != env_params.spawn_half_size
    differs = (
        (humans is not None and int(humans) != env_params.num_humans)
        or (obs_dim is not None and int(obs_dim) != observation_dim(env_params.num_humans))
        or (room is not None and float(room) != env_params.room_size)
        or other_goals
    )
    if not differs:
        if "observed_humans" in made or "kinematics" in made or "scenario" in made:
            _check_scenario_kind(path, made, env_params, verb, error)
        return
    ours = _humans(env_params.num_humans)
    if humans is not None:
        theirs = _humans(int(humans))
    elif obs_dim is not None:
        theirs = f"{int(obs_dim)}-d observations"
        ours += f" ({observation_dim(env_params.num_humans)}-d observations)"
    else:
        theirs = "humans not recorded"
    ours += f" in a {float(env_params.room_size)} m room"
    if room is not None:
        theirs += f" in a {float(room)} m room"
    elif other_goals:
        theirs += f", goals drawn within ±{float(spawn)} m"
        ours += f" (goals drawn within ±{env_params.spawn_half_size} m)"
    raise error(f"{path}: {verb} with {theirs}; the params have {ours}")
