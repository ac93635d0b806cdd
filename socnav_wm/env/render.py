"""RGB frames of a social-navigation scene, animated GIFs and frame grids (Pillow only).

Pillow's ``ImageDraw`` is used rather than matplotlib because rendering must be cheap: a GIF of a
200-step episode, or a grid comparing seven methods, should take a second or two, not a minute.
A 480 px frame costs well under a millisecond of drawing; the static walls are drawn once per
(size, room) and copied.

Coordinates: the image shows the square ``[−(L + w), L + w]²`` of the world, where ``L`` is the
room's inner half size and ``w`` the wall thickness, so the walls fill the outer border; a
scene with a ``view_half_size`` shows ``[−v, v]²`` instead (the crossing families, whose walls
are far away and not drawn, zoom on the crossing circle or square). World
``+x`` points right and world ``+y`` points **up** (image rows grow downwards, so ``y`` is
flipped). Angles are world-frame, counter-clockwise from ``+x``, in radians.

Anything outside the drawn square (a robot pushed through a wall by a bug, a trail point far
away) is not an error: shapes are simply clipped by the image border, so a broken episode can
still be rendered and looked at. Non-finite coordinates, which cannot be drawn, raise
:class:`ValueError`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from socnav_wm.env.episode import Episode
from socnav_wm.env.params import EnvParams
from socnav_wm.env.state import OBSTACLE_NONE, OBSTACLE_PLANT, OBSTACLE_TABLE

__all__ = [
    "BACKGROUND_COLOR",
    "GOAL_COLOR",
    "GROUP_COLOR",
    "HUMAN_COLOR",
    "PERSONAL_SPACE_COLOR",
    "PLANT_COLOR",
    "ROBOT_COLOR",
    "TABLE_COLOR",
    "TRAIL_COLOR",
    "WALL_COLOR",
    "Scene",
    "episode_frames",
    "episode_scene",
    "render_frame",
    "scene_options",
    "world_to_pixel",
]

RGB = tuple[int, int, int]

# Colours are public so tests (and figure legends) can refer to them. They are far apart in RGB
# so that GIF palette quantisation cannot merge them.
BACKGROUND_COLOR: RGB = (255, 255, 255)
WALL_COLOR: RGB = (128, 128, 128)
GOAL_COLOR: RGB = (120, 200, 120)
GOAL_MARK_COLOR: RGB = (20, 110, 20)
HUMAN_COLOR: RGB = (40, 110, 220)
HUMAN_OUTLINE_COLOR: RGB = (10, 40, 110)
PERSONAL_SPACE_COLOR: RGB = (150, 190, 245)
ROBOT_COLOR: RGB = (220, 50, 40)
ROBOT_OUTLINE_COLOR: RGB = (110, 15, 10)
TRAIL_COLOR: RGB = (245, 150, 30)
HEADING_COLOR: RGB = (0, 0, 0)
TABLE_COLOR: RGB = (160, 110, 60)
PLANT_COLOR: RGB = (60, 150, 60)
OBSTACLE_OUTLINE_COLOR: RGB = (80, 50, 20)
GROUP_COLOR: RGB = (140, 40, 170)
TEXT_COLOR: RGB = (0, 0, 0)


@dataclass(frozen=True)
class Scene:
    """Everything needed to draw one instant of an episode (world frame, metres, radians).

    Attributes:
        robot_xy: ``(2,)`` robot centre.
        robot_theta: robot heading.
        robot_radius: robot radius (0.3).
        goal_xy: ``(2,)`` goal centre.
        goal_radius: goal disc radius (0.5); the goal counts as reached when the robot centre is
            within ``robot_radius + goal_radius``. 0 (CrowdNav's goal, reached within the robot
            radius) draws a cross of the robot's size instead of a disc.
        human_xy: ``(H, 2)`` human centres (``H`` may be 0).
        human_theta: ``(H,)`` human headings.
        human_radius: human radius (0.36).
        personal_space: clearance drawn as a ring of radius ``human_radius + personal_space``.
        room_half_size: inner half size of the room, i.e. the walls' inner faces (4.8).
        wall_thickness: wall thickness (0.2).
        robot_trail: optional ``(K, 2)`` past robot positions, oldest first.
        title: short text drawn in the top-left corner (e.g. ``"step 12  sfm"``).
        obstacle_kind: optional ``(O,)`` static obstacles: ``OBSTACLE_TABLE`` (a filled
            rectangle), ``OBSTACLE_PLANT`` (a filled disc) or ``OBSTACLE_NONE`` (an empty slot,
            not drawn); given with ``obstacle_xy`` and ``obstacle_half`` or not at all.
        obstacle_xy: ``(O, 2)`` obstacle centres.
        obstacle_half: ``(O, 2)`` a table's half width (x) and depth (y); a plant's ``(r, r)``.
        human_group: optional ``(H,)`` each human's group (−1: alone); the members of a group are
            joined by thin lines drawn under the bodies.
        walls: whether to draw the walls (False for the crossing families, whose walls are far
            away); walls are drawn only in the room's own view (``view_half_size`` None), where
            they fill the border.
        view_half_size: half width of the drawn square (m); None: the room and its walls,
            ``room_half_size + wall_thickness``.
    """

    robot_xy: np.ndarray
    robot_theta: float
    robot_radius: float
    goal_xy: np.ndarray
    goal_radius: float
    human_xy: np.ndarray
    human_theta: np.ndarray
    human_radius: float
    personal_space: float
    room_half_size: float = 4.8
    wall_thickness: float = 0.2
    robot_trail: np.ndarray | None = None
    title: str = ""
    obstacle_kind: np.ndarray | None = None
    obstacle_xy: np.ndarray | None = None
    obstacle_half: np.ndarray | None = None
    human_group: np.ndarray | None = None
    walls: bool = True
    view_half_size: float | None = None

    def __post_init__(self) -> None:
        robot = np.asarray(self.robot_xy, dtype=np.float64)
        goal = np.asarray(self.goal_xy, dtype=np.float64)
        humans = np.asarray(self.human_xy, dtype=np.float64)
        human_theta = np.asarray(self.human_theta, dtype=np.float64)
        if robot.shape != (2,):
            raise ValueError(f"robot_xy must have shape (2,), got {robot.shape}")
        if goal.shape != (2,):
            raise ValueError(f"goal_xy must have shape (2,), got {goal.shape}")
        if humans.size == 0:
            humans = humans.reshape(0, 2)  # accept [] for an empty room
        if humans.ndim != 2 or humans.shape[1] != 2:
            raise ValueError(f"human_xy must have shape (H, 2), got {humans.shape}")
        human_theta = human_theta.reshape(-1) if human_theta.size == 0 else human_theta
        if human_theta.shape != (humans.shape[0],):
            raise ValueError(
                f"human_theta must have shape (H,) = ({humans.shape[0]},), got {human_theta.shape}"
            )
        trail = None
        if self.robot_trail is not None:
            trail = np.asarray(self.robot_trail, dtype=np.float64)
            if trail.size == 0:
                trail = trail.reshape(0, 2)
            if trail.ndim != 2 or trail.shape[1] != 2:
                raise ValueError(f"robot_trail must have shape (K, 2), got {trail.shape}")
        arrays = {
            "robot_xy": robot,
            "goal_xy": goal,
            "human_xy": humans,
            "human_theta": human_theta,
        }
        if trail is not None:
            arrays["robot_trail"] = trail
        obstacles = (self.obstacle_kind, self.obstacle_xy, self.obstacle_half)
        if any(o is not None for o in obstacles):
            if any(o is None for o in obstacles):
                raise ValueError(
                    "obstacle_kind, obstacle_xy and obstacle_half must be given together"
                )
            kind = np.asarray(self.obstacle_kind).reshape(-1).astype(np.int64)
            count = kind.shape[0]
            for name in ("obstacle_xy", "obstacle_half"):
                arr = np.asarray(getattr(self, name), dtype=np.float64)
                if arr.size == 0:
                    arr = arr.reshape(0, 2)
                if arr.shape != (count, 2):
                    raise ValueError(
                        f"{name} must have shape (O, 2) = ({count}, 2), got {arr.shape}"
                    )
                arrays[name] = arr
            object.__setattr__(self, "obstacle_kind", kind)
        if self.human_group is not None:
            groups = np.asarray(self.human_group).reshape(-1)
            if groups.shape != (humans.shape[0],):
                raise ValueError(
                    f"human_group must have shape (H,) = ({humans.shape[0]},), got {groups.shape}"
                )
            object.__setattr__(self, "human_group", groups.astype(np.int64))
        for name, arr in arrays.items():
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"Scene.{name} contains non-finite values")
        if not math.isfinite(self.robot_theta):
            raise ValueError(f"Scene.robot_theta must be finite, got {self.robot_theta}")
        for name in ("robot_radius", "human_radius", "room_half_size"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"Scene.{name} must be a finite number > 0, got {value}")
        if self.view_half_size is not None and not (
            math.isfinite(self.view_half_size) and self.view_half_size > 0
        ):
            raise ValueError(
                f"Scene.view_half_size must be None or a finite number > 0, "
                f"got {self.view_half_size}"
            )
        for name in ("goal_radius", "personal_space", "wall_thickness"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"Scene.{name} must be a finite number >= 0, got {value}")
        for name, arr in arrays.items():
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "robot_theta", float(self.robot_theta))


# --------------------------------------------------------------------------------------------
# Geometry
# --------------------------------------------------------------------------------------------


def _extent(scene: Scene) -> float:
    """Half width of the drawn world square, m: the room plus its walls, or the scene's view."""
    if scene.view_half_size is not None:
        return float(scene.view_half_size)
    return scene.room_half_size + scene.wall_thickness


def world_to_pixel(xy: np.ndarray, extent: float, size: int) -> np.ndarray:
    """Map world points to continuous pixel coordinates ``(col, row)``.

    Args:
        xy: ``(..., 2)`` world points, m.
        extent: half width of the drawn square, m (the image shows ``[−extent, extent]²``).
        size: image side, px.

    Returns:
        ``(..., 2)`` float pixel coordinates; pixel ``(c, r)`` covers ``[c, c+1) × [r, r+1)``,
        so the world origin maps to the image centre and ``+y`` maps to decreasing rows.
    """
    xy = np.asarray(xy, dtype=np.float64)
    scale = size / (2.0 * extent)
    col = (xy[..., 0] + extent) * scale
    row = (extent - xy[..., 1]) * scale
    return np.stack([col, row], axis=-1)


def _circle_box(centre_px: np.ndarray, radius_px: float) -> list[float]:
    cx, cy = float(centre_px[0]), float(centre_px[1])
    return [cx - radius_px, cy - radius_px, cx + radius_px, cy + radius_px]


# --------------------------------------------------------------------------------------------
# Cached static parts
# --------------------------------------------------------------------------------------------


@lru_cache(maxsize=16)
def _background(size: int, room_half_size: float, wall_thickness: float) -> Image.Image:
    """Empty room with its walls filling the border (``wall_thickness`` 0: no walls): drawn
    once per geometry, copied for every frame."""
    image = Image.new("RGB", (size, size), BACKGROUND_COLOR)
    if wall_thickness > 0:
        draw = ImageDraw.Draw(image)
        extent = room_half_size + wall_thickness
        # Inner faces of the walls in pixels (x = -L maps to the same offset from the left edge
        # as y = +L from the top); everything outside them is wall.
        inner_lo = round(float(world_to_pixel(np.array([-room_half_size, 0.0]), extent, size)[0]))
        inner_hi = size - inner_lo
        band = [
            (0, 0, size - 1, inner_lo - 1),  # top wall (world y = +L .. +L+w)
            (0, inner_hi, size - 1, size - 1),  # bottom wall
            (0, 0, inner_lo - 1, size - 1),  # left wall
            (inner_hi, 0, size - 1, size - 1),  # right wall
        ]
        for box in band:
            if box[2] >= box[0] and box[3] >= box[1]:
                draw.rectangle(box, fill=WALL_COLOR)
    return image


@lru_cache(maxsize=1)
def _font() -> ImageFont.ImageFont | ImageFont.FreeTypeFont:
    return ImageFont.load_default()


# --------------------------------------------------------------------------------------------
# Public API
# --------------------------------------------------------------------------------------------


def render_frame(scene: Scene, size: int = 480) -> np.ndarray:
    """Draw one scene.

    Drawing order (later on top): walls, obstacles, goal, personal-space rings, group lines,
    trail, humans, robot, title. The heading lines start at 40 % of the radius, so the disc
    centre keeps the body colour.

    Args:
        scene: what to draw.
        size: image side, px (the image is square, like the room).

    Returns:
        ``(size, size, 3)`` ``uint8`` RGB image, world ``+y`` up.
    """
    if not isinstance(size, int | np.integer) or size < 16:
        raise ValueError(f"size must be an integer >= 16 px, got {size!r}")
    size = int(size)
    extent = _extent(scene)
    scale = size / (2.0 * extent)  # px per m

    if scene.walls and scene.view_half_size is None:
        image = _background(size, float(scene.room_half_size), float(scene.wall_thickness))
    else:
        # No walls, or a view other than the room's: nothing static to cache but the floor
        # (walls are only drawn where they fill the border, i.e. in the room's own view).
        image = _background(size, 1.0, 0.0)
    image = image.copy()
    draw = ImageDraw.Draw(image)
    line_w = max(1, round(size / 240))

    if (
        scene.obstacle_kind is not None
        and scene.obstacle_xy is not None
        and scene.obstacle_half is not None
    ):
        _draw_obstacles(
            draw, scene.obstacle_kind, scene.obstacle_xy, scene.obstacle_half, extent, size
        )

    # Goal: a disc of the goal radius with a cross at its centre; a goal of radius 0 (reached
    # within the robot's radius) is a bolder cross of the robot's size.
    goal_px = world_to_pixel(scene.goal_xy, extent, size)
    gx, gy = float(goal_px[0]), float(goal_px[1])
    if scene.goal_radius > 0:
        goal_r = scene.goal_radius * scale
        draw.ellipse(_circle_box(goal_px, goal_r), fill=GOAL_COLOR)
        arm, cross_w = 0.6 * goal_r, line_w
    else:
        arm, cross_w = max(3.0, scene.robot_radius * scale), line_w + 1
    draw.line([(gx - arm, gy - arm), (gx + arm, gy + arm)], fill=GOAL_MARK_COLOR, width=cross_w)
    draw.line([(gx - arm, gy + arm), (gx + arm, gy - arm)], fill=GOAL_MARK_COLOR, width=cross_w)

    humans_px = world_to_pixel(scene.human_xy, extent, size)
    human_r = scene.human_radius * scale
    ring_r = (scene.human_radius + scene.personal_space) * scale
    # Rings first, so that no ring is drawn over another person's body.
    if scene.personal_space > 0:
        for centre in humans_px:
            draw.ellipse(_circle_box(centre, ring_r), outline=PERSONAL_SPACE_COLOR, width=line_w)

    if scene.human_group is not None:
        _draw_groups(draw, humans_px, scene.human_group, line_w)

    if scene.robot_trail is not None and len(scene.robot_trail) >= 2:
        trail_px = world_to_pixel(scene.robot_trail, extent, size)
        draw.line([tuple(p) for p in trail_px.tolist()], fill=TRAIL_COLOR, width=line_w)

    for centre, theta in zip(humans_px, scene.human_theta, strict=True):
        _draw_body(draw, centre, human_r, float(theta), HUMAN_COLOR, HUMAN_OUTLINE_COLOR, line_w)

    robot_px = world_to_pixel(scene.robot_xy, extent, size)
    robot_r = scene.robot_radius * scale
    _draw_body(draw, robot_px, robot_r, scene.robot_theta, ROBOT_COLOR, ROBOT_OUTLINE_COLOR, line_w)

    if scene.title:
        font = _font()
        left, top, right, bottom = draw.textbbox((4, 2), scene.title, font=font)
        # A white box keeps the text legible over the grey wall band.
        draw.rectangle((left - 2, top - 1, right + 2, bottom + 1), fill=BACKGROUND_COLOR)
        draw.text((4, 2), scene.title, fill=TEXT_COLOR, font=font)

    return np.asarray(image, dtype=np.uint8)


def _draw_obstacles(
    draw: ImageDraw.ImageDraw,
    kinds: np.ndarray,
    centres: np.ndarray,
    halves: np.ndarray,
    extent: float,
    size: int,
) -> None:
    """Tables as filled axis-aligned rectangles, plants as filled discs; empty slots skipped."""
    scale = size / (2.0 * extent)
    for kind, centre, half in zip(kinds, centres, halves, strict=True):
        if kind == OBSTACLE_NONE:
            continue
        cx, cy = world_to_pixel(centre, extent, size).tolist()
        hx, hy = float(half[0]) * scale, float(half[1]) * scale
        box = [cx - hx, cy - hy, cx + hx, cy + hy]
        if kind == OBSTACLE_TABLE:
            draw.rectangle(box, fill=TABLE_COLOR, outline=OBSTACLE_OUTLINE_COLOR, width=1)
        elif kind == OBSTACLE_PLANT:
            draw.ellipse(box, fill=PLANT_COLOR, outline=OBSTACLE_OUTLINE_COLOR, width=1)


def _draw_groups(
    draw: ImageDraw.ImageDraw, humans_px: np.ndarray, groups: np.ndarray, line_w: int
) -> None:
    """Thin lines joining the members of each group: a closed polygon around the group's centre
    (members in angular order, so a standing circle is drawn as its outline), one segment for
    two."""
    for g in np.unique(groups[groups >= 0]):
        members = humans_px[groups == g]
        if len(members) < 2:
            continue
        offset = members - members.mean(axis=0)
        members = members[np.argsort(np.arctan2(offset[:, 1], offset[:, 0]))]
        points = [tuple(p) for p in members.tolist()]
        if len(points) > 2:
            points.append(points[0])
        # Twice the usual stroke: members stand 0.05–0.3 m apart, so only the gaps between
        # their bodies show the line.
        draw.line(points, fill=GROUP_COLOR, width=2 * line_w)


def _draw_body(
    draw: ImageDraw.ImageDraw,
    centre: np.ndarray,
    radius: float,
    theta: float,
    fill: RGB,
    outline: RGB,
    line_w: int,
) -> None:
    """A filled disc with a heading stroke from 40 % of the radius to the rim (y flipped)."""
    draw.ellipse(_circle_box(centre, radius), fill=fill, outline=outline, width=1)
    cx, cy = float(centre[0]), float(centre[1])
    dx, dy = math.cos(theta), -math.sin(theta)  # image rows grow downwards
    draw.line(
        [(cx + 0.4 * radius * dx, cy + 0.4 * radius * dy), (cx + radius * dx, cy + radius * dy)],
        fill=HEADING_COLOR,
        width=line_w,
    )


def episode_frames(
    episode: Episode, params: EnvParams, *, label: str = "", size: int = 480
) -> list[np.ndarray]:
    """RGB frames (size, size, 3) of every state of an episode, with its trail and a caption."""
    outcome = (
        "success"
        if episode.success
        else f"{episode.collision} collision"
        if episode.collision
        else "timeout"
    )
    frames = []
    for t in range(episode.num_steps + 1):
        status = outcome if t == episode.num_steps else ""
        title = f"{label} scenario {episode.scenario_id}  step {t}  {status}".strip()
        scene = episode_scene(episode, t, params, title)
        frames.append(render_frame(scene, size=size))
    return frames


def episode_scene(episode: Episode, t: int, params: EnvParams, title: str = "") -> Scene:
    """The :class:`Scene` of state ``t`` of a recorded episode, with the trail so far, its
    obstacles and groups (:func:`scene_options`)."""
    return Scene(
        robot_xy=episode.robot_xy[t],
        robot_theta=float(episode.robot_theta[t]),
        goal_xy=episode.goal_xy,
        human_xy=episode.human_xy[t],
        human_theta=episode.human_theta[t],
        robot_trail=episode.robot_xy[: t + 1],
        title=title,
        obstacle_kind=episode.obstacle_kind,
        obstacle_xy=episode.obstacle_xy,
        obstacle_half=episode.obstacle_half,
        human_group=episode.human_group,
        **scene_options(params),
    )


def scene_options(params: EnvParams) -> dict[str, Any]:
    """What a :class:`Scene` takes from the scenario's parameters: radii and the room; the
    crossing families are drawn without walls, zoomed on the crossing (``crossing_radius +
    crossing_noise + 1.5`` m each side of the centre)."""
    crossing = params.scenario != "room"
    return {
        "robot_radius": params.robot_radius,
        "goal_radius": params.goal_radius,
        "human_radius": params.human_radius,
        "personal_space": 0.5,
        "room_half_size": params.wall_half_size,
        "wall_thickness": params.wall_thickness,
        "walls": not crossing,
        "view_half_size": (
            params.crossing_radius + params.crossing_noise + 1.5 if crossing else None
        ),
    }
