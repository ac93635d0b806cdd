"""The rollout schema: columns, types and metadata as documented."""

import pyarrow as pa

from socnav_wm.data.schema import (
    COLLISION_HUMAN,
    COLLISION_NONE,
    COLLISION_WALL,
    COLUMN_NAMES,
    SCHEMA_VERSION,
    observation_dim,
    rollout_schema,
    schema_num_humans,
    schema_version,
)


def test_paper_schema_has_23_d_observations_and_documented_types() -> None:
    schema = rollout_schema(3)
    assert tuple(schema.names) == COLUMN_NAMES
    assert observation_dim(3) == 23
    assert schema.field("obs").type == pa.list_(pa.float32(), 23)
    assert schema.field("next_obs").type == pa.list_(pa.float32(), 23)
    assert schema.field("human_xy").type == pa.list_(pa.float32(), 6)
    assert schema.field("episode_id").type == pa.int64()
    assert schema.field("t").type == pa.int32()
    assert schema.field("action").type == pa.int8()
    assert schema.field("collision").type == pa.int8()
    for name in ("is_first", "is_last", "is_terminal", "truncated", "success"):
        assert schema.field(name).type == pa.bool_()
    for name in ("reward", "dmin", "robot_x", "robot_y", "robot_theta"):
        assert schema.field(name).type == pa.float32()
    assert not any(field.nullable for field in schema)


def test_metadata_carries_version_and_num_humans() -> None:
    schema = rollout_schema(5)
    assert schema_version(schema) == SCHEMA_VERSION == 1
    assert schema_num_humans(schema) == 5
    assert schema.field("human_xy").type.list_size == 10
    assert schema.field("obs").type.list_size == 2 + 7 * 5


def test_missing_metadata_reads_as_none() -> None:
    bare = pa.schema([pa.field("t", pa.int32())])
    assert schema_version(bare) is None
    assert schema_num_humans(bare) is None


def test_collision_codes() -> None:
    assert (COLLISION_NONE, COLLISION_HUMAN, COLLISION_WALL) == (0, 1, 2)
