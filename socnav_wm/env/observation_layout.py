"""The observation's layout (its fields, its size, their names), apart from the numba kernel
that fills it (:mod:`socnav_wm.env.observation`), so that a reader of files can check a size
without importing the simulator."""

from __future__ import annotations

GOAL_FIELDS = ("goal_x", "goal_y")
HUMAN_FIELDS = ("x", "y", "sin_rel_heading", "cos_rel_heading", "radius", "rel_speed", "neg_omega")
OBSTACLE_FIELDS = ("x", "y", "size", "present")


def observation_size(num_humans: int, num_obstacles: int = 0) -> int:
    """The observation's length for ``num_humans`` human slots (K) and ``num_obstacles`` (M)."""
    return len(GOAL_FIELDS) + len(HUMAN_FIELDS) * num_humans + len(OBSTACLE_FIELDS) * num_obstacles


def observation_names(num_humans: int, num_obstacles: int = 0) -> list[str]:
    """Names of the observation's entries, in order (``human0_x``, …, ``obstacle0_x``, …)."""
    return (
        list(GOAL_FIELDS)
        + [f"human{i}_{name}" for i in range(num_humans) for name in HUMAN_FIELDS]
        + [f"obstacle{i}_{name}" for i in range(num_obstacles) for name in OBSTACLE_FIELDS]
    )


FEATURES_PER_HUMAN = len(HUMAN_FIELDS)
FEATURES_PER_OBSTACLE = len(OBSTACLE_FIELDS)
