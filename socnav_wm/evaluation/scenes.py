"""Animated test scenarios: every method's episode of a scenario side by side, drawn with the
simulator's renderer (the report's ``scenarios.gif``). Apart from the figures so that only the
stages that draw depend on the renderer."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from socnav_wm.env.episode import Episode
from socnav_wm.env.frames import tile_frames, write_gif
from socnav_wm.env.params import EnvParams
from socnav_wm.env.render import episode_scene, render_frame


def _outcome_text(episode: Episode) -> str:
    if episode.success:
        return "success"
    if episode.collision:
        return f"{episode.collision} hit"
    return "timeout"


def scenario_frames(
    episodes: Mapping[str, Episode],
    params: EnvParams,
    *,
    size: int = 200,
    columns: int = 4,
    max_frames: int = 60,
    hold: int = 6,
) -> list[np.ndarray]:
    """Frames of one scenario played by several methods at once, tiled in a grid.

    Every cell shows one method's episode at the same time step; a method whose episode has
    ended keeps showing its last state with its outcome. Long episodes are subsampled (every
    ``stride``-th step, the last one always kept) to at most about ``max_frames`` frames.

    Args:
        episodes: method → its episode of the scenario (the same scenario id for all).
        params: the scenario parameters (room, radii).
        size: cell side, px.
        columns: cells per row.
        max_frames: frames before the final hold.
        hold: extra copies of the final frame, so the outcome stays on screen.

    Returns:
        ``(rows·size, cols·size, 3)`` uint8 frames.
    """
    if not episodes:
        raise ValueError("need at least one method's episode")
    longest = max(e.num_steps for e in episodes.values())
    stride = max(1, math.ceil((longest + 1) / max_frames))
    times = list(range(0, longest + 1, stride))
    if times[-1] != longest:
        times.append(longest)
    frames = []
    for t in times:
        cells = []
        for method, episode in episodes.items():
            step = min(t, episode.num_steps)
            status = f" {_outcome_text(episode)}" if step == episode.num_steps else ""
            title = f"{method} s{episode.scenario_id} t{step}{status}"
            cells.append(render_frame(episode_scene(episode, step, params, title), size=size))
        frames.append(tile_frames(cells, columns))
    return frames + [frames[-1]] * hold


def scenarios_gif(
    scenarios: Sequence[Mapping[str, Episode]],
    params: EnvParams,
    path: str | Path,
    *,
    size: int = 200,
    columns: int = 4,
    max_frames: int = 60,
    fps: float = 8.0,
) -> None:
    """An animated GIF of test scenarios, one after the other, every method side by side.

    Args:
        scenarios: per scenario, method → its episode of that scenario.
        params: the scenario parameters.
        path: the GIF to write (atomically).
        size, columns, max_frames: see :func:`scenario_frames`.
        fps: frames per second.
    """
    frames: list[np.ndarray] = []
    for episodes in scenarios:
        frames += scenario_frames(
            episodes, params, size=size, columns=columns, max_frames=max_frames
        )
    if not frames:
        raise ValueError("no scenario to draw")
    # Every scenario has the same set of methods, so the tiles have the same shape.
    write_gif(frames, path, fps=fps)
