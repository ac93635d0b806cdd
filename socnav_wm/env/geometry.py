"""Small geometric helpers shared by the simulator's numba kernels."""

from __future__ import annotations

import math

import numba


@numba.njit(cache=True, inline="always")
def norm(x: float, y: float) -> float:
    """Length of (x, y). math.hypot guards against overflows that cannot happen with metres in a
    room, and is several times slower in the hot loops."""
    return math.sqrt(x * x + y * y)
