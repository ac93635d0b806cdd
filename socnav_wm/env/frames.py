"""Frames to files: animated GIFs (one palette for all frames) and grids of frames."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

import numpy as np
from PIL import Image

from socnav_wm.env.render import BACKGROUND_COLOR
from socnav_wm.io import atomic_path


def _check_frames(frames: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Validate a non-empty sequence of equal-shape ``(h, w, 3)`` uint8 frames."""
    frames = [np.asarray(f) for f in frames]
    if not frames:
        raise ValueError("need at least one frame")
    first = frames[0].shape
    if len(first) != 3 or first[2] != 3:
        raise ValueError(f"frames must have shape (h, w, 3), got {first}")
    for i, frame in enumerate(frames):
        if frame.shape != first:
            raise ValueError(f"frame {i} has shape {frame.shape}, expected {first} like frame 0")
        if frame.dtype != np.uint8:
            raise ValueError(f"frame {i} has dtype {frame.dtype}, expected uint8")
    return frames


def write_gif(frames: Sequence[np.ndarray], path: str | os.PathLike[str], fps: float = 8.0) -> None:
    """Write frames as an animated GIF that loops forever, atomically.

    Written through :func:`socnav_wm.io.atomic_path` (temporary file beside the target, then
    ``os.replace``), so readers never see a half-written file.

    Args:
        frames: equal-shape ``(h, w, 3)`` ``uint8`` RGB frames.
        path: destination file.
        fps: frames per second. GIF delays are stored in 1/100 s, so the delay is rounded.

    Note:
        Pillow folds a frame that is pixel-identical to the previous one into it (adding its
        delay), so the file can hold fewer frames than given while playing for the same time.
        Frames from :func:`render_frame` with a step counter in the title always differ.
    """
    frames = _check_frames(frames)
    if not (math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be a finite number > 0, got {fps}")
    duration_ms = max(10, round(1000.0 / fps / 10.0) * 10)
    images = _to_palette_images(frames)
    with atomic_path(path) as tmp:
        images[0].save(
            tmp,
            format="GIF",
            save_all=True,
            append_images=images[1:],
            duration=duration_ms,
            loop=0,  # 0 = loop forever
        )


def _rgb_codes(rgb: np.ndarray) -> np.ndarray:
    """``(..., 3)`` uint8 colours as ``(...)`` uint32 codes ``0xRRGGBB``."""
    rgb = rgb.astype(np.uint32)
    return (rgb[..., 0] << 16) | (rgb[..., 1] << 8) | rgb[..., 2]


def _to_palette_images(frames: list[np.ndarray], max_samples: int = 8) -> list[Image.Image]:
    """Convert RGB frames to palette ("P") images sharing one palette of at most 256 colours.

    Letting Pillow quantise every frame adaptively costs ~10 ms per 480 px frame and dominates
    GIF writing. Rendered frames use a handful of flat colours (plus the title's anti-aliasing
    greys), so one palette taken from a few evenly spaced frames fits them all: when that
    sample has at most 256 colours they are kept exactly and mapped with a lookup, not with
    Pillow's approximate palette matching (which shifts colours by a few levels). Colours
    missing from the sample go to the nearest palette entry; samples with more than 256
    colours (photos, heat maps) fall back to a median-cut palette. No dithering anywhere, so
    flat areas stay flat.
    """
    idx = np.unique(np.linspace(0, len(frames) - 1, min(max_samples, len(frames))).astype(int))
    mosaic = np.concatenate([frames[i] for i in idx], axis=0)
    colors = Image.fromarray(mosaic).getcolors(maxcolors=256)
    if colors is None:
        palette = Image.fromarray(mosaic).quantize(colors=256, method=Image.Quantize.MEDIANCUT)
        return [
            Image.fromarray(f).quantize(palette=palette, dither=Image.Dither.NONE) for f in frames
        ]

    palette_rgb = np.array(sorted(rgb for _, rgb in colors), dtype=np.uint8)  # (P, 3)
    palette_codes = _rgb_codes(palette_rgb)  # sorted, because the colours are sorted
    flat_palette = palette_rgb.reshape(-1).tolist()
    images = []
    for frame in frames:
        codes = _rgb_codes(frame)
        index = np.minimum(np.searchsorted(palette_codes, codes), len(palette_codes) - 1)
        missing = palette_codes[index] != codes
        if np.any(missing):
            # Rare: a colour absent from the sampled frames. Nearest palette colour, per
            # distinct missing colour (not per pixel) to keep it cheap.
            miss_codes, inverse = np.unique(codes[missing], return_inverse=True)
            miss_rgb = np.stack(
                [(miss_codes >> 16) & 255, (miss_codes >> 8) & 255, miss_codes & 255], axis=1
            ).astype(np.int32)
            dist = ((miss_rgb[:, None, :] - palette_rgb[None, :, :].astype(np.int32)) ** 2).sum(-1)
            index[missing] = np.argmin(dist, axis=1)[inverse]
        image = Image.fromarray(index.astype(np.uint8), mode="P")
        image.putpalette(flat_palette)
        images.append(image)
    return images


def tile_frames(frames: Sequence[np.ndarray], columns: int) -> np.ndarray:
    """Arrange equal-size frames in a grid, row by row (e.g. one method per cell).

    Args:
        frames: ``N`` equal-shape ``(h, w, 3)`` ``uint8`` frames.
        columns: cells per row (≥ 1); capped at ``N`` so a short list gives one tight row.

    Returns:
        ``(rows·h, cols·w, 3)`` ``uint8`` with ``cols = min(columns, N)`` and
        ``rows = ceil(N / cols)``; cells after the last frame are background white.
    """
    frames = _check_frames(frames)
    if not isinstance(columns, int | np.integer) or columns < 1:
        raise ValueError(f"columns must be an integer >= 1, got {columns!r}")
    n = len(frames)
    cols = min(int(columns), n)
    rows = -(-n // cols)
    h, w, _ = frames[0].shape
    grid = np.empty((rows * h, cols * w, 3), dtype=np.uint8)
    grid[...] = BACKGROUND_COLOR
    for i, frame in enumerate(frames):
        r, c = divmod(i, cols)
        grid[r * h : (r + 1) * h, c * w : (c + 1) * w] = frame
    return grid
