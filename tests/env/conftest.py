"""Helpers for simulator tests: a simulator whose state a test can place by hand."""

from __future__ import annotations

import numpy as np
import pytest

from socnav_wm.env import EnvParams, Simulator


def frozen_humans_params(**overrides) -> EnvParams:
    """Humans that never move: their max speed is below the 0.05 m/s stop threshold."""
    values = {"human_max_speed": 0.01, "human_policy": "orca"}
    values.update(overrides)
    return EnvParams(**values)


def place(
    sim: Simulator,
    *,
    robot=(0.0, 0.0),
    theta=0.0,
    goal=(4.0, 4.0),
    humans=((3.0, -3.0), (-3.0, 3.0), (-3.0, -3.0)),
    env: int = 0,
) -> None:
    """Put robot, goal and humans of slot ``env`` where a test wants them (speeds zero)."""
    s = sim.state
    s.robot_xy[env] = robot
    s.start_xy[env] = robot
    s.robot_theta[env] = theta
    s.goal_xy[env] = goal
    s.human_xy[env] = np.asarray(humans, dtype=float)
    s.human_speed[env] = 0.0
    # Human goals far from the humans, so that none draws a new goal during the test.
    s.human_goal[env] = -np.asarray(humans, dtype=float)


@pytest.fixture
def frozen_sim() -> Simulator:
    sim = Simulator(1, frozen_humans_params())
    sim.reset(seed=0)
    return sim
