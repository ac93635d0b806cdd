"""Tests for socnav_wm.env.render: frame geometry and colours, GIF writing, frame grids."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from PIL import Image

from socnav_wm.env import frames as frames_module
from socnav_wm.env import render as r
from socnav_wm.env.frames import tile_frames, write_gif
from socnav_wm.env.render import Scene, render_frame


def make_scene(**overrides) -> Scene:
    kwargs = {
        "robot_xy": np.array([-2.0, 3.0]),
        "robot_theta": 0.0,
        "robot_radius": 0.3,
        "goal_xy": np.array([0.0, -3.0]),
        "goal_radius": 0.5,
        "human_xy": np.array([[2.5, -1.5], [3.0, 3.0], [-3.5, -1.0]]),
        "human_theta": np.array([0.0, math.pi / 2, -1.0]),
        "human_radius": 0.36,
        "personal_space": 0.5,
        "room_half_size": 4.8,
        "wall_thickness": 0.2,
    }
    kwargs.update(overrides)
    return Scene(**kwargs)


def near(frame: np.ndarray, row: int, col: int, color, radius: int = 2) -> bool:
    """Whether any pixel in a small window around (row, col) has exactly this colour."""
    window = frame[max(0, row - radius) : row + radius + 1, max(0, col - radius) : col + radius + 1]
    return bool(np.any(np.all(window == np.array(color, dtype=np.uint8), axis=-1)))


# With size 480 the image spans [-5, 5]^2 m at 48 px/m: col = (x + 5)·48, row = (5 − y)·48.


def test_shape_and_dtype():
    frame = render_frame(make_scene())
    assert frame.shape == (480, 480, 3)
    assert frame.dtype == np.uint8
    assert render_frame(make_scene(), size=200).shape == (200, 200, 3)


def test_robot_and_human_centres_have_their_colours():
    frame = render_frame(make_scene())
    # Robot at (-2, 3) -> col 144, row 96 (upper half: world y is up).
    assert tuple(frame[96, 144]) == r.ROBOT_COLOR
    # Human 0 at (2.5, -1.5) -> col 360, row 312 (lower right).
    assert tuple(frame[312, 360]) == r.HUMAN_COLOR
    # The mirrored positions are empty floor, so the y axis is not flipped the wrong way.
    assert tuple(frame[480 - 96, 144]) == r.BACKGROUND_COLOR
    assert tuple(frame[480 - 312, 360]) == r.BACKGROUND_COLOR


def test_world_to_pixel_mapping():
    px = r.world_to_pixel(np.array([[-2.0, 3.0], [0.0, 0.0], [-5.0, 5.0]]), 5.0, 480)
    np.testing.assert_allclose(px, [[144.0, 96.0], [240.0, 240.0], [0.0, 0.0]])


def test_walls_goal_ring_trail():
    scene = make_scene(robot_trail=np.array([[-4.0, -4.0], [-4.0, 0.0]]))
    frame = render_frame(scene)
    # Walls: 0.2 m = 9.6 px grey bands on all four sides.
    for row, col in [(3, 240), (476, 240), (240, 3), (240, 476)]:
        assert tuple(frame[row, col]) == r.WALL_COLOR
    # Room centre is empty floor.
    assert tuple(frame[240, 240]) == r.BACKGROUND_COLOR
    # Goal (0, -3) disc, 0.4 m right of its centre (off the diagonal cross): col 259, row 384.
    assert tuple(frame[384, 259]) == r.GOAL_COLOR
    # Personal-space ring of human 0: radius 0.86 m = 41.3 px right of its centre (col 360).
    assert near(frame, 312, 360 + 41, r.PERSONAL_SPACE_COLOR)
    # ... and inside the ring but outside the body there is floor.
    assert tuple(frame[312, 360 + 28]) == r.BACKGROUND_COLOR
    # Trail through (-4, -2) -> col 48, row 336.
    assert near(frame, 336, 48, r.TRAIL_COLOR)


def test_heading_lines_point_in_world_direction():
    # Robot heading +x: the stroke is to the right of the centre (col 144 + 0.8·14.4).
    frame = render_frame(make_scene(robot_theta=0.0))
    assert near(frame, 96, 144 + 11, r.HEADING_COLOR, radius=1)
    assert not near(frame, 96 - 11, 144, r.HEADING_COLOR, radius=1)
    # Heading +y (CCW quarter turn) points up in the image: smaller row.
    frame = render_frame(make_scene(robot_theta=math.pi / 2))
    assert near(frame, 96 - 11, 144, r.HEADING_COLOR, radius=1)
    assert not near(frame, 96 + 11, 144, r.HEADING_COLOR, radius=1)


def test_title_is_drawn():
    plain = render_frame(make_scene())
    titled = render_frame(make_scene(title="step 12  sfm"))
    corner = (slice(0, 20), slice(0, 100))
    assert not np.array_equal(plain[corner], titled[corner])
    # The default font is anti-aliased, so look for dark glyph pixels rather than pure black.
    assert np.any(titled[corner].max(axis=-1) < 64)
    assert not np.any(plain[corner].max(axis=-1) < 64)


def test_scene_outside_room_is_clipped_not_an_error():
    # Documented choice: positions outside the room are drawn and clipped by the image border.
    scene = make_scene(
        robot_xy=np.array([7.0, 0.0]),
        human_xy=np.array([[4.9, 4.9], [-20.0, 0.0], [0.0, 0.0]]),
        robot_trail=np.array([[0.0, 0.0], [30.0, 30.0]]),
    )
    frame = render_frame(scene)
    assert frame.shape == (480, 480, 3)
    # The robot at x = 7 lies entirely outside the image: no robot colour anywhere.
    assert not np.any(np.all(frame == np.array(r.ROBOT_COLOR, dtype=np.uint8), axis=-1))


def test_empty_room_and_no_trail():
    scene = make_scene(human_xy=np.zeros((0, 2)), human_theta=np.zeros(0), robot_trail=None)
    frame = render_frame(scene)
    assert not np.any(np.all(frame == np.array(r.HUMAN_COLOR, dtype=np.uint8), axis=-1))


@pytest.mark.parametrize(
    ("overrides", "match"),
    [
        ({"robot_xy": np.array([np.nan, 0.0])}, "robot_xy contains non-finite"),
        ({"robot_xy": np.zeros(3)}, "robot_xy must have shape"),
        ({"human_theta": np.zeros(2)}, "human_theta must have shape"),
        ({"human_xy": np.zeros((3, 3))}, "human_xy must have shape"),
        ({"robot_trail": np.zeros((4, 3))}, "robot_trail must have shape"),
        ({"robot_radius": 0.0}, "robot_radius"),
        ({"robot_theta": math.inf}, "robot_theta"),
    ],
)
def test_invalid_scene_raises(overrides, match):
    with pytest.raises(ValueError, match=match):
        make_scene(**overrides)


def test_invalid_size_raises():
    with pytest.raises(ValueError, match="size"):
        render_frame(make_scene(), size=4)


def test_rendering_is_fast():
    scene = make_scene(robot_trail=np.stack([np.linspace(-4, 0, 100), np.zeros(100)], axis=1))
    render_frame(scene)  # warm the background cache
    start = time.perf_counter()
    for _ in range(100):
        render_frame(scene)
    elapsed = time.perf_counter() - start
    # The target is a few hundred frames per second; the bound is loose for shared CI machines.
    assert elapsed < 2.0, f"100 frames took {elapsed:.2f} s"


# ---------------------------------------------------------------------------------------------
# GIFs
# ---------------------------------------------------------------------------------------------


def moving_frames(n: int, size: int = 96) -> list[np.ndarray]:
    return [
        render_frame(make_scene(robot_xy=np.array([-3.0 + i, 0.0]), title=f"step {i}"), size=size)
        for i in range(n)
    ]


def test_write_gif(tmp_path):
    frames = moving_frames(5)
    path = tmp_path / "sub" / "episode.gif"
    write_gif(frames, path, fps=10.0)
    with Image.open(path) as gif:
        assert gif.format == "GIF"
        assert gif.n_frames == 5
        assert gif.size == (96, 96)
        assert gif.info["loop"] == 0
        assert gif.info["duration"] == 100
        gif.seek(2)
        # Frame content survives palette quantisation: robot at (-1, 0) -> col 38, row 48.
        rgb = np.asarray(gif.convert("RGB"))
        assert tuple(rgb[48, 38]) == r.ROBOT_COLOR
    # Only the GIF is left in the directory: the temp file was renamed.
    assert sorted(p.name for p in path.parent.iterdir()) == ["episode.gif"]


def test_write_gif_keeps_rendered_colours_exactly(tmp_path):
    frames = moving_frames(4)
    write_gif(frames, tmp_path / "a.gif")
    with Image.open(tmp_path / "a.gif") as gif:
        for i, frame in enumerate(frames):
            gif.seek(i)
            np.testing.assert_array_equal(np.asarray(gif.convert("RGB")), frame)


def test_palette_maps_unsampled_colour_to_nearest():
    frames = [np.full((4, 4, 3), 255, np.uint8) for _ in range(10)]
    frames[0][0, 0] = (0, 0, 0)
    frames[3][1, 1] = (20, 10, 5)  # frame 3 is not among the 2 sampled frames (0 and 9)
    images = frames_module._to_palette_images(frames, max_samples=2)
    assert tuple(np.asarray(images[3].convert("RGB"))[1, 1]) == (0, 0, 0)
    assert tuple(np.asarray(images[3].convert("RGB"))[0, 0]) == (255, 255, 255)


def test_write_gif_many_colours(tmp_path):
    rng = np.random.default_rng(0)
    frames = [rng.integers(0, 256, (32, 32, 3), dtype=np.uint8) for _ in range(3)]
    write_gif(frames, tmp_path / "noise.gif")
    with Image.open(tmp_path / "noise.gif") as gif:
        assert gif.n_frames == 3


def test_write_gif_replaces_existing_file(tmp_path):
    path = tmp_path / "a.gif"
    path.write_bytes(b"old")
    write_gif(moving_frames(3), path)
    with Image.open(path) as gif:
        assert gif.n_frames == 3


def test_write_gif_bad_input_leaves_nothing(tmp_path):
    path = tmp_path / "bad.gif"
    with pytest.raises(ValueError, match="at least one frame"):
        write_gif([], path)
    with pytest.raises(ValueError, match="frame 1 has shape"):
        write_gif([np.zeros((8, 8, 3), np.uint8), np.zeros((9, 8, 3), np.uint8)], path)
    with pytest.raises(ValueError, match="dtype"):
        write_gif([np.zeros((8, 8, 3), np.float32)], path)
    with pytest.raises(ValueError, match="fps"):
        write_gif([np.zeros((8, 8, 3), np.uint8)], path, fps=0.0)
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------------------------
# Grids
# ---------------------------------------------------------------------------------------------


def test_tile_frames_layout():
    frames = [np.full((10, 12, 3), i * 40, dtype=np.uint8) for i in range(5)]
    grid = tile_frames(frames, columns=3)
    assert grid.shape == (20, 36, 3)
    assert grid.dtype == np.uint8
    assert np.all(grid[0:10, 12:24] == 40)  # frame 1: row 0, column 1
    assert np.all(grid[10:20, 12:24] == 160)  # frame 4: row 1, column 1
    assert np.all(grid[10:20, 24:36] == 255)  # unused cell: white


def test_tile_frames_caps_columns():
    frames = [np.zeros((10, 12, 3), np.uint8)] * 2
    assert tile_frames(frames, columns=7).shape == (10, 24, 3)
    assert tile_frames(frames, columns=1).shape == (20, 12, 3)


def test_tile_frames_invalid():
    with pytest.raises(ValueError, match="columns"):
        tile_frames([np.zeros((4, 4, 3), np.uint8)], columns=0)
    with pytest.raises(ValueError, match="shape"):
        tile_frames([np.zeros((4, 4, 3), np.uint8), np.zeros((4, 5, 3), np.uint8)], columns=2)


# ---------------------------------------------------------------------------------------------
# Scenario features: obstacles, groups, CrowdNav goals, crossing families
# ---------------------------------------------------------------------------------------------


def test_obstacles_have_their_colours_at_their_centres():
    from socnav_wm.env.state import OBSTACLE_NONE, OBSTACLE_PLANT, OBSTACLE_TABLE

    scene = make_scene(
        obstacle_kind=np.array([OBSTACLE_TABLE, OBSTACLE_PLANT, OBSTACLE_NONE], dtype=np.int8),
        obstacle_xy=np.array([[-2.0, -2.0], [2.0, 1.0], [0.0, 0.0]]),
        obstacle_half=np.array([[0.6, 0.4], [0.25, 0.25], [0.5, 0.5]]),
    )
    frame = render_frame(scene)
    # Table at (-2, -2) -> col 144, row 336; 0.5 m right of it is still table (half width 0.6).
    assert tuple(frame[336, 144]) == r.TABLE_COLOR
    assert tuple(frame[336, 144 + 24]) == r.TABLE_COLOR
    # ... but 0.5 m above it is floor (half depth 0.4): the rectangle is not a square.
    assert tuple(frame[336 - 24, 144]) == r.BACKGROUND_COLOR
    # Plant at (2, 1) -> col 336, row 192.
    assert tuple(frame[192, 336]) == r.PLANT_COLOR
    # The empty slot at the origin is not drawn.
    assert tuple(frame[240, 240]) == r.BACKGROUND_COLOR


def test_group_members_are_joined():
    scene = make_scene(
        human_xy=np.array([[-3.0, 0.0], [-1.0, 0.0], [3.0, 3.0]]),
        human_group=np.array([0, 0, -1]),
    )
    frame = render_frame(scene)
    # Midpoint (-2, 0) of the pair -> col 144, row 240, between the two bodies.
    assert near(frame, 240, 144, r.GROUP_COLOR, radius=1)
    # Nothing joins the lone human: the midpoint (0, 1.5) towards it is floor.
    assert tuple(frame[168, 240]) == r.BACKGROUND_COLOR
    # No groups, no lines.
    plain = render_frame(make_scene(human_group=np.array([-1, -1, -1])))
    assert not np.any(np.all(plain == np.array(r.GROUP_COLOR, dtype=np.uint8), axis=-1))


def test_goal_radius_zero_is_a_cross():
    frame = render_frame(make_scene(goal_radius=0.0))
    # Goal (0, -3) -> col 240, row 384: the cross's centre, no disc around it.
    assert tuple(frame[384, 240]) == r.GOAL_MARK_COLOR
    assert not np.any(np.all(frame == np.array(r.GOAL_COLOR, dtype=np.uint8), axis=-1))


def test_crossing_scene_has_no_walls_and_zooms():
    from socnav_wm.env.episode import Episode
    from socnav_wm.env.params import EnvParams
    from socnav_wm.env.render import episode_scene

    params = EnvParams(
        scenario="circle_crossing",
        room_size=40.0,
        crossing_radius=4.0,
        crossing_noise=0.5,
        goal_radius=0.0,
        human_radius=0.3,
    )
    episode = Episode(
        scenario_id=0,
        robot_xy=np.array([[0.0, -4.0]]),
        robot_theta=np.array([math.pi / 2]),
        goal_xy=np.array([0.0, 4.0]),
        human_xy=np.array([[[4.0, 0.0], [-4.0, 0.0], [0.0, 4.2]]]),
        human_theta=np.zeros((1, 3)),
        actions=np.zeros(0),
        rewards=np.zeros(0),
        dmin=np.zeros(0),
        success=False,
        collision=None,
        truncated=False,
    )
    frame = render_frame(episode_scene(episode, 0, params))
    # The image spans ±(4 + 0.5 + 1.5) = ±6 m at 40 px/m: no wall band, the corner is floor.
    assert tuple(frame[0, 0]) == r.BACKGROUND_COLOR
    assert tuple(frame[479, 479]) == r.BACKGROUND_COLOR
    # Human 0 at (4, 0) -> col 400, row 240; the robot at (0, -4) -> col 240, row 400.
    assert tuple(frame[240, 400]) == r.HUMAN_COLOR
    assert tuple(frame[400, 240]) == r.ROBOT_COLOR


def test_episodes_carry_their_obstacles():
    from pathlib import Path

    from socnav_wm.config import load_params
    from socnav_wm.env.core import Simulator
    from socnav_wm.env.render import episode_frames
    from socnav_wm.env.rollout import random_policy, run_episodes

    root = Path(__file__).resolve().parents[2]
    params = load_params(
        root / "params.yaml", overlays=[root / "configs" / "scenarios" / "obstacles.yaml"]
    ).env.replace(max_steps=2)
    ids = np.array([0, 3])
    episodes = run_episodes(params, random_policy(0), 0, ids)
    sim = Simulator(len(ids), params)
    sim.reset(seed=0, scenario_ids=ids)
    for e, episode in enumerate(episodes):
        np.testing.assert_array_equal(episode.obstacle_kind, sim.state.obstacle_kind[e])
        np.testing.assert_array_equal(episode.obstacle_xy, sim.state.obstacle_xy[e])
        np.testing.assert_array_equal(episode.obstacle_half, sim.state.obstacle_half[e])
    frame = episode_frames(episodes[0], params, size=96)[0]
    assert np.any(np.all(frame == np.array(r.TABLE_COLOR, dtype=np.uint8), axis=-1))
    # The paper's room has no obstacles: none recorded.
    paper = run_episodes(params.replace(tables=(0, 0), plants=(0, 0)), random_policy(0), 0, ids)
    assert paper[0].obstacle_kind is None and paper[0].obstacle_xy is None
