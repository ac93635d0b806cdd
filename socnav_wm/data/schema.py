"""The rollout table: one row per environment step, defined once as a pyarrow schema.

Every shard written by :class:`socnav_wm.data.shards.ShardWriter` carries this schema, and every
reader checks it. The schema version, the number of humans and the scenarios the rollouts were
collected in (the ``env`` section, as JSON; shards written before it was recorded have none)
travel in the Parquet schema metadata, so a shard can be checked on its own, without side
files.

Columns (one row per step; lengths in metres, angles in radians, world frame unless noted):

| column | type | meaning |
|---|---|---|
| ``episode_id`` | int64 | episode number, unique within a dataset |
| ``t`` | int32 | step index within the episode, 0-based |
| ``obs`` | float32[obs_dim] | robot-frame observation *before* the step (paper_spec §2) |
| ``action`` | int8 | 0 stop, 1 forward, 2 rotate-left (CCW), 3 rotate-right (CW) |
| ``reward`` | float32 | reward of the step |
| ``next_obs`` | float32[obs_dim] | observation *after* the step (terminal one on the last row) |
| ``is_first`` | bool | ``t == 0`` |
| ``is_last`` | bool | last transition of the episode (terminal or truncated) |
| ``is_terminal`` | bool | goal reached or collision; *not* set on truncation (time limit) |
| ``truncated`` | bool | the episode was cut by the time limit at this step |
| ``success`` | bool | the goal was reached at this step |
| ``collision`` | int8 | 0 none, 1 human, 2 wall (see the ``COLLISION_*`` constants) |
| ``dmin`` | float32 | approximate robot–human surface distance over the step (m) |
| ``robot_x``, ``robot_y`` | float32 | robot position after the step (m) |
| ``robot_theta`` | float32 | robot heading after the step (rad, wrapped to (−π, π]) |
| ``human_xy`` | float32[2·num_humans] | human positions after the step, ``x0, y0, x1, y1, …`` (m) |
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import pyarrow as pa

SCHEMA_VERSION = 1
"""Bumped whenever a column is added, removed, renamed or changes meaning."""

METADATA_SCHEMA_VERSION = b"socnav_wm.schema_version"
METADATA_NUM_HUMANS = b"socnav_wm.num_humans"
METADATA_OBS_DIM = b"socnav_wm.obs_dim"
METADATA_ENV = b"socnav_wm.env"

# Discrete actions, in the paper's order (ARCHITECTURE.md "Names").
ACTION_STOP = 0
ACTION_FORWARD = 1
ACTION_ROTATE_LEFT = 2
ACTION_ROTATE_RIGHT = 3
NUM_ACTIONS = 4
ACTION_NAMES: tuple[str, ...] = ("stop", "forward", "rotate-left", "rotate-right")

# Values of the ``collision`` column.
COLLISION_NONE = 0
COLLISION_HUMAN = 1
COLLISION_WALL = 2

GOAL_FEATURES = 2
"""Goal x, y in the robot frame."""
FEATURES_PER_HUMAN = 7
"""x, y, sin, cos, radius, relative speed, −ω per human (paper_spec §2)."""

COLUMN_NAMES: tuple[str, ...] = (
    "episode_id",
    "t",
    "obs",
    "action",
    "reward",
    "next_obs",
    "is_first",
    "is_last",
    "is_terminal",
    "truncated",
    "success",
    "collision",
    "dmin",
    "robot_x",
    "robot_y",
    "robot_theta",
    "human_xy",
)


def observation_dim(num_humans: int) -> int:
    """Length of the flat observation vector: 2 goal features + 7 per human (23 for 3 humans)."""
    return GOAL_FEATURES + FEATURES_PER_HUMAN * num_humans


def rollout_schema(num_humans: int, env: Mapping[str, Any] | None = None) -> pa.Schema:
    """The Arrow schema of a rollout shard for ``num_humans`` people.

    The observation width is :func:`observation_dim` (23 for the paper's 3 humans). The schema
    metadata holds ``SCHEMA_VERSION``, ``num_humans``, the observation width and, when given,
    ``env``: the scenarios' parameters (:func:`socnav_wm.data.compatibility.made_with`).
    """
    if num_humans < 1:
        raise ValueError(f"num_humans must be >= 1, got {num_humans}")
    obs_dim = observation_dim(num_humans)
    obs_type = pa.list_(pa.float32(), obs_dim)
    # Every column is required: a null in a rollout is always a collector bug.
    fields = [
        pa.field("episode_id", pa.int64(), nullable=False),
        pa.field("t", pa.int32(), nullable=False),
        pa.field("obs", obs_type, nullable=False),
        pa.field("action", pa.int8(), nullable=False),
        pa.field("reward", pa.float32(), nullable=False),
        pa.field("next_obs", obs_type, nullable=False),
        pa.field("is_first", pa.bool_(), nullable=False),
        pa.field("is_last", pa.bool_(), nullable=False),
        pa.field("is_terminal", pa.bool_(), nullable=False),
        pa.field("truncated", pa.bool_(), nullable=False),
        pa.field("success", pa.bool_(), nullable=False),
        pa.field("collision", pa.int8(), nullable=False),
        pa.field("dmin", pa.float32(), nullable=False),
        pa.field("robot_x", pa.float32(), nullable=False),
        pa.field("robot_y", pa.float32(), nullable=False),
        pa.field("robot_theta", pa.float32(), nullable=False),
        pa.field("human_xy", pa.list_(pa.float32(), 2 * num_humans), nullable=False),
    ]
    assert tuple(f.name for f in fields) == COLUMN_NAMES
    metadata = {
        METADATA_SCHEMA_VERSION: str(SCHEMA_VERSION).encode(),
        METADATA_NUM_HUMANS: str(num_humans).encode(),
        METADATA_OBS_DIM: str(obs_dim).encode(),
    }
    if env is not None:
        metadata[METADATA_ENV] = json.dumps(dict(env), sort_keys=True).encode()
    return pa.schema(fields, metadata=metadata)


def schema_version(schema: pa.Schema) -> int | None:
    """The rollout schema version stored in ``schema``'s metadata, or None when absent/garbled."""
    raw = (schema.metadata or {}).get(METADATA_SCHEMA_VERSION)
    try:
        return int(raw) if raw is not None else None
    except ValueError:
        return None


def schema_num_humans(schema: pa.Schema) -> int | None:
    """The number of humans stored in ``schema``'s metadata, or None when absent/garbled."""
    raw = (schema.metadata or {}).get(METADATA_NUM_HUMANS)
    try:
        return int(raw) if raw is not None else None
    except ValueError:
        return None


def schema_env(schema: pa.Schema) -> dict[str, Any] | None:
    """The scenarios' parameters stored in ``schema``'s metadata, or None when absent/garbled."""
    raw = (schema.metadata or {}).get(METADATA_ENV)
    try:
        env = json.loads(raw) if raw is not None else None
    except ValueError:
        return None
    return env if isinstance(env, dict) else None
