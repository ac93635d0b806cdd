"""The paper's reward, the dense reward, dmin and the 23-d observation, against hand computations.

Humans are frozen (max speed below the 0.05 m/s stop threshold), so every distance below can be
worked out on paper.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from socnav_wm.env import Simulator
from socnav_wm.env.observation import observe
from socnav_wm.env.observation_layout import observation_names, observation_size
from tests.env.conftest import frozen_humans_params, place

STOP, FORWARD = 0, 1
F, D = 0.01, 0.9999


def _sim(reward: str = "paper") -> Simulator:
    sim = Simulator(1, frozen_humans_params(reward=reward))
    sim.reset(seed=0)
    return sim


def test_dmin_while_standing_is_the_surface_distance() -> None:
    sim = _sim()
    place(sim, robot=(0.0, 0.0), humans=((1.5, 0.0), (-3, 3), (-3, -3)))
    result = sim.step(np.array([STOP]))
    assert result.info["dmin"][0] == pytest.approx(1.5 - 0.36 - 0.3)


def test_dmin_when_moving_uses_the_relative_velocity_segment() -> None:
    sim = _sim()
    place(sim, robot=(0.0, 0.0), theta=0.0, humans=((1.5, 0.3), (-3, 3), (-3, -3)))
    result = sim.step(np.array([FORWARD]))
    # After the move the human is at p = (1.36, 0.3) from the robot; the robot's velocity
    # (0.14, 0) makes the relative segment p → p + (−0.14, 0) = (1.22, 0.3), whose nearest
    # point to the robot is its end.
    expected = math.sqrt(1.22**2 + 0.3**2) - 0.66
    assert result.info["dmin"][0] == pytest.approx(expected)


def test_paper_reward_success_pays_one_plus_the_alive_accumulator() -> None:
    sim = _sim()
    place(
        sim, robot=(0.0, 0.0), theta=0.0, goal=(0.93, 0.0), humans=((1.5, 0.0), (-3, 3), (-3, -3))
    )
    discomfort = F * ((1.5 - 0.66) - D)  # −0.001599 per uncomfortable step
    first = sim.step(np.array([STOP]))
    second = sim.step(np.array([STOP]))
    assert first.reward[0] == pytest.approx(discomfort)
    assert second.reward[0] == pytest.approx(discomfort)
    last = sim.step(np.array([FORWARD]))
    assert last.info["success"][0]
    assert last.reward[0] == pytest.approx(1.0 - 2 * 0.0005)
    episode_return = first.reward[0] + second.reward[0] + last.reward[0]
    assert episode_return == pytest.approx(0.999 + 2 * -0.001599)


def test_paper_reward_failure_refunds_discomfort_so_the_return_is_minus_one() -> None:
    sim = _sim()
    place(sim, robot=(4.4, 0.0), theta=0.0, humans=((4.4, 1.2), (-3, 3), (-3, -3)))
    discomfort = F * ((1.2 - 0.66) - D)  # −0.004599
    rewards = [sim.step(np.array([STOP])).reward[0] for _ in range(2)]
    crash = sim.step(np.array([FORWARD]))  # into the wall at x = 4.8
    assert rewards == pytest.approx([discomfort, discomfort])
    assert crash.info["collision"][0] == 2
    assert crash.reward[0] == pytest.approx(-1.0 - 2 * discomfort)
    assert sum(rewards) + crash.reward[0] == pytest.approx(-1.0)


def test_paper_reward_is_zero_when_comfortable() -> None:
    sim = _sim()
    place(sim, robot=(0.0, 0.0), humans=((3.0, 0.0), (-3, 3), (-3, -3)))
    assert sim.step(np.array([STOP])).reward[0] == 0.0


def test_paper_reward_timeout_is_a_failure() -> None:
    sim = _sim()
    place(sim, robot=(0.0, 0.0), humans=((3.0, 0.0), (-3, 3), (-3, -3)))
    total = sum(sim.step(np.array([STOP])).reward[0] for _ in range(201))
    assert total == pytest.approx(-1.0)


def test_dense_reward_pays_per_step_penalties_and_plus_minus_one() -> None:
    sim = _sim("dense")
    place(
        sim, robot=(0.0, 0.0), theta=0.0, goal=(0.93, 0.0), humans=((1.5, 0.0), (-3, 3), (-3, -3))
    )
    step = sim.step(np.array([STOP]))
    assert step.reward[0] == pytest.approx(F * (0.84 - D) - 0.0005)
    assert sim.step(np.array([FORWARD])).reward[0] == pytest.approx(1.0)
    sim = _sim("dense")
    place(sim, robot=(0.0, 0.0), humans=((3.0, 0.0), (-3, 3), (-3, -3)))
    assert sim.step(np.array([STOP])).reward[0] == pytest.approx(-0.0005)
    place(sim, robot=(4.45, 0.0), theta=0.0)
    assert sim.step(np.array([FORWARD])).reward[0] == pytest.approx(-1.0)


def test_observation_layout_in_the_robot_frame() -> None:
    sim = _sim()
    s = sim.state
    place(
        sim,
        robot=(1.0, 1.0),
        theta=math.pi / 2,
        goal=(1.0, 3.0),
        humans=((0.0, 1.0), (1.0, 2.0), (3.0, 1.0)),
    )
    s.robot_v[0] = 0.14
    s.robot_omega[0] = 0.2
    s.human_speed[0] = [0.1, 0.0, 0.0]
    s.human_heading[0] = [[-1.0, 0.0], [0.0, 1.0], [1.0, 0.0]]  # headings π, π/2, 0
    out = np.zeros((1, 23), dtype=np.float32)
    observe(
        s.robot_xy, s.robot_theta, s.robot_v, s.robot_omega, s.robot_vy, s.goal_xy, s.human_xy,
        s.human_heading, s.human_speed, 0.36, 3, s.obstacle_kind, s.obstacle_xy,
        s.obstacle_half, 0, np.array([0]), out,
    )  # fmt: skip
    rel_speed = math.sqrt(0.1**2 + 0.14**2)  # human (−0.1, 0) minus robot (0, 0.14)
    expected = [
        2.0, 0.0,  # goal: 2 m straight ahead
        0.0, 1.0, 1.0, 0.0, 0.36, rel_speed, -0.2,  # human 0: 1 m to the left, facing left
        1.0, 0.0, 0.0, 1.0, 0.36, 0.14, -0.2,  # human 1: 1 m ahead, same heading, standing
        0.0, -2.0, -1.0, 0.0, 0.36, 0.14, -0.2,  # human 2: 2 m to the right, facing right
    ]  # fmt: skip
    np.testing.assert_allclose(out[0], expected, atol=1e-6)


def test_observation_names_match_the_size() -> None:
    assert observation_size(3) == 23
    names = observation_names(3)
    assert len(names) == 23 and names[:3] == ["goal_x", "goal_y", "human0_x"]
    assert names[-1] == "human2_neg_omega"
