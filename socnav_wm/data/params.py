"""The parameters of the random-policy rollouts (``params.yaml``'s ``collect`` section)."""

from __future__ import annotations

from typing import ClassVar

from pydantic import Field

from socnav_wm.section import Section

__all__ = ["CollectParams"]


class CollectParams(Section):
    """Random-policy rollouts written to ``data/rollouts/shard-*.parquet``."""

    SECTION: ClassVar[str] = "collect"

    episodes: int = Field(6000, gt=0)
    """Number of complete episodes to record."""
    num_envs: int = Field(512, gt=0)
    """Environments stepped together in one batch (memory and speed, not the data)."""
    max_rows_per_shard: int = Field(400_000, gt=0)
    """A Parquet shard is closed once it holds this many steps (rows)."""
