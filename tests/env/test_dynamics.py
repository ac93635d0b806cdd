"""Robot kinematics, termination order and action handling, on hand-placed scenes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from socnav_wm.env import EnvParams, Simulator
from socnav_wm.env.state import COLLISION_HUMAN, COLLISION_NONE, COLLISION_WALL
from tests.env.conftest import frozen_humans_params, place

STOP, FORWARD, LEFT, RIGHT = 0, 1, 2, 3


def test_forward_moves_0_14_m_along_the_heading(frozen_sim: Simulator) -> None:
    place(frozen_sim, robot=(1.0, 2.0), theta=math.pi / 2)
    frozen_sim.step(np.array([FORWARD]))
    np.testing.assert_allclose(frozen_sim.state.robot_xy[0], [1.0, 2.14], atol=1e-12)
    assert frozen_sim.state.robot_theta[0] == pytest.approx(math.pi / 2)


def test_rotations_turn_by_0_3876_rad_without_moving(frozen_sim: Simulator) -> None:
    place(frozen_sim, robot=(1.0, 2.0), theta=0.0)
    frozen_sim.step(np.array([LEFT]))
    assert frozen_sim.state.robot_theta[0] == pytest.approx(0.387596899)
    frozen_sim.step(np.array([RIGHT]))
    frozen_sim.step(np.array([RIGHT]))
    assert frozen_sim.state.robot_theta[0] == pytest.approx(-0.387596899)
    np.testing.assert_allclose(frozen_sim.state.robot_xy[0], [1.0, 2.0])


def test_stop_keeps_the_pose(frozen_sim: Simulator) -> None:
    place(frozen_sim, robot=(-1.0, 0.5), theta=1.0)
    frozen_sim.step(np.array([STOP]))
    np.testing.assert_allclose(frozen_sim.state.robot_xy[0], [-1.0, 0.5])
    assert frozen_sim.state.robot_theta[0] == 1.0


def test_heading_wraps_to_minus_pi_pi(frozen_sim: Simulator) -> None:
    place(frozen_sim, theta=math.pi - 0.1)
    frozen_sim.step(np.array([LEFT]))
    expected = math.pi - 0.1 + 0.387596899 - 2 * math.pi
    assert frozen_sim.state.robot_theta[0] == pytest.approx(expected)


def test_turn_happens_before_the_advance() -> None:
    # A continuous command (v, ω): the paper's robot turns first, then moves along the new heading.
    sim = Simulator(1, frozen_humans_params())
    sim.reset(seed=0)
    place(sim, robot=(0.0, 0.0), theta=0.0)
    sim.step(np.array([[0.14, 0.3]]))
    np.testing.assert_allclose(sim.state.robot_xy[0], [0.14 * math.cos(0.3), 0.14 * math.sin(0.3)])


def test_continuous_commands_are_clipped_to_the_robot_limits(frozen_sim: Simulator) -> None:
    place(frozen_sim, robot=(0.0, 0.0), theta=0.0)
    frozen_sim.step(np.array([[5.0, -9.0]]))
    assert frozen_sim.state.robot_v[0] == pytest.approx(0.14)
    assert frozen_sim.state.robot_omega[0] == pytest.approx(-0.387596899)


@pytest.mark.parametrize(
    ("actions", "message"),
    [
        (np.array([4]), "action: must be in 0..3, got 4"),
        (np.array([-1]), "action: must be in 0..3, got -1"),
        (np.array([1, 2]), "expected 1 integer actions"),
        (np.array([[np.nan, 0.0]]), "must be finite"),
    ],
)
def test_bad_actions_are_rejected_with_a_clear_message(
    frozen_sim: Simulator, actions: np.ndarray, message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        frozen_sim.step(actions)


def test_goal_is_reached_within_0_8_m(frozen_sim: Simulator) -> None:
    place(frozen_sim, robot=(0.0, 0.0), theta=0.0, goal=(0.93, 0.0))
    first = frozen_sim.step(np.array([FORWARD]))  # 0.79 m from the goal centre
    assert first.terminated[0] and first.info["success"][0]
    assert first.info["collision"][0] == COLLISION_NONE


def test_goal_is_not_reached_at_0_8_m_or_more(frozen_sim: Simulator) -> None:
    place(frozen_sim, robot=(0.0, 0.0), theta=0.0, goal=(0.95, 0.0))
    result = frozen_sim.step(np.array([FORWARD]))  # 0.81 m away
    assert not result.terminated[0]


def test_touching_a_human_is_a_human_collision(frozen_sim: Simulator) -> None:
    # Centres 0.65 m apart after the move: the robot (0.3) and the human (0.36) overlap.
    place(frozen_sim, robot=(0.0, 0.0), humans=((0.79, 0.0), (-3, 3), (-3, -3)))
    result = frozen_sim.step(np.array([FORWARD]))
    assert result.terminated[0]
    assert result.info["collision"][0] == COLLISION_HUMAN
    assert not result.info["success"][0]


def test_touching_a_wall_is_a_wall_collision(frozen_sim: Simulator) -> None:
    # Inner wall face at x = 4.8; the robot's edge reaches it when its centre is at 4.5.
    place(frozen_sim, robot=(4.40, 0.0), theta=0.0)
    result = frozen_sim.step(np.array([FORWARD]))
    assert result.terminated[0]
    assert result.info["collision"][0] == COLLISION_WALL


def test_goal_has_priority_over_collision(frozen_sim: Simulator) -> None:
    place(frozen_sim, robot=(0.0, 0.0), goal=(0.5, 0.5), humans=((0.6, 0.0), (-3, 3), (-3, -3)))
    result = frozen_sim.step(np.array([STOP]))
    assert result.info["success"][0]
    assert result.info["collision"][0] == COLLISION_NONE


def test_episode_is_truncated_at_step_201() -> None:
    sim = Simulator(1, frozen_humans_params())
    sim.reset(seed=0)
    place(sim)
    for step in range(1, 202):
        result = sim.step(np.array([STOP]))
        if step < 201:
            assert not result.truncated[0], step
    assert result.truncated[0] and not result.terminated[0]
    assert sim.state.step_count[0] == 201


def test_finished_slots_ignore_actions_until_reset(frozen_sim: Simulator) -> None:
    place(frozen_sim, robot=(4.40, 0.0), theta=0.0)
    frozen_sim.step(np.array([FORWARD]))
    pose = frozen_sim.state.robot_xy[0].copy()
    result = frozen_sim.step(np.array([FORWARD]))
    np.testing.assert_array_equal(frozen_sim.state.robot_xy[0], pose)
    assert result.reward[0] == 0.0 and not result.info["active"][0]
    frozen_sim.reset_envs(np.array([0]))
    assert not frozen_sim.state.done[0]


def test_single_env_and_batch_share_dynamics() -> None:
    """A batch of one and slot 3 of a batch of 5 follow identical trajectories."""
    params = EnvParams()
    single = Simulator(1, params)
    batch = Simulator(5, params)
    single.reset(seed=7, scenario_ids=np.array([3]))
    batch.reset(seed=7)
    rng = np.random.default_rng(1)
    for _ in range(40):
        actions = rng.integers(0, 4, size=5)
        a = single.step(actions[3:4])
        b = batch.step(actions)
        if a.terminated[0] or a.truncated[0]:
            break
        np.testing.assert_array_equal(a.obs[0], b.obs[3])
        np.testing.assert_array_equal(a.reward[0], b.reward[3])
