"""The robot's own motion, exact, and the no-learning predictors."""

from __future__ import annotations

import numpy as np
import pytest

from socnav_wm.env import EnvParams, Simulator
from socnav_wm.worldmodel.ego import (
    advance_pose,
    commands_of,
    ego_step,
    positions,
    predict_positions,
)

# Humans slower than the speed threshold are stopped: a scene of static humans.
STATIC = EnvParams(human_max_speed=0.01)


@pytest.mark.parametrize("action", [0, 1, 2, 3])
def test_the_ego_motion_predicts_static_scenes_to_a_micrometre(action: int) -> None:
    sim = Simulator(64, STATIC)
    obs, _ = sim.reset(seed=4)
    for _ in range(5):
        actions = np.full(64, action)
        before = positions(obs)
        result = sim.step(actions)
        active = result.info["active"] & ~result.terminated
        predicted = ego_step(before, commands_of(actions, STATIC), STATIC.dt)
        error = np.abs(predicted - positions(result.obs))[active]
        assert active.any() and error.max() <= 1e-6
        obs = result.obs


def test_advance_pose_moves_the_robot_as_the_simulator_does() -> None:
    sim = Simulator(64, STATIC)
    sim.reset(seed=5)
    rng = np.random.default_rng(0)
    for _ in range(5):
        pose = sim.state.robot_pose()
        actions = rng.integers(0, 4, size=64)
        result = sim.step(actions)
        active = result.info["active"] & ~result.terminated
        predicted = advance_pose(pose, commands_of(actions, STATIC), STATIC.dt)
        after = sim.state.robot_pose()
        turn = np.angle(np.exp(1j * (predicted[:, 2] - after[:, 2])))  # the simulator wraps θ
        assert active.any()
        assert np.abs(predicted[:, :2] - after[:, :2])[active].max() <= 1e-12
        assert np.abs(turn[active]).max() <= 1e-12


@pytest.mark.parametrize("kinematics", ["unicycle", "holonomic"])
def test_the_ego_motion_is_exact_for_continuous_commands_too(kinematics: str) -> None:
    params = STATIC.replace(kinematics=kinematics)
    sim = Simulator(64, params)
    obs, _ = sim.reset(seed=5)
    rng = np.random.default_rng(0)
    for _ in range(5):
        commands = rng.uniform(-0.3, 0.3, size=(64, 2))  # some beyond the limits: clipped
        before = positions(obs)
        pose = sim.state.robot_pose()
        result = sim.step(commands)
        active = result.info["active"] & ~result.terminated
        motion = commands_of(commands, params)
        error = np.abs(ego_step(before, motion, params.dt) - positions(result.obs))[active]
        moved = advance_pose(pose, motion, params.dt)[:, :2] - sim.state.robot_xy
        assert np.abs(moved[active]).max() <= 1e-12
        assert error.max() <= 1e-6
        obs = result.obs


def test_constant_velocity_is_exact_for_humans_walking_straight_lines() -> None:
    """Humans at constant world velocity, the robot driven by random actions through the real
    simulator (no humans in it): the predictor has zero error at every horizon."""
    params = EnvParams(num_humans=0)
    sim = Simulator(32, params)
    sim.reset(seed=6)
    rng = np.random.default_rng(1)
    steps = 12
    actions = rng.integers(0, 4, size=(steps, 32))
    poses = [(sim.state.robot_xy.copy(), sim.state.robot_theta.copy())]
    for t in range(steps):
        sim.step(actions[t])
        poses.append((sim.state.robot_xy.copy(), sim.state.robot_theta.copy()))
    start = rng.uniform(-3, 3, size=(32, 3, 2))
    velocity = rng.uniform(-0.14, 0.14, size=(32, 3, 2))
    goal = rng.uniform(-4, 4, size=(32, 2))

    def observation(t: int) -> np.ndarray:  # the robot-frame positions of paper_spec §2
        xy, theta = poses[t]
        c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
        world = np.concatenate([goal[:, None], start + t * velocity], axis=1) - xy[:, None]
        frame = np.stack([c * world[..., 0] + s * world[..., 1],
                          -s * world[..., 0] + c * world[..., 1]], axis=-1)  # fmt: skip
        obs = np.zeros((32, 2 + 7 * 3))
        obs[:, :2] = frame[:, 0]
        for h in range(3):
            obs[:, 2 + 7 * h : 4 + 7 * h] = frame[:, 1 + h]
        return obs

    predicted = predict_positions(
        "constant-velocity", observation(0), observation(1), actions[0], actions[1:].T, params
    )
    truth = np.stack([positions(observation(t)) for t in range(2, steps + 1)], axis=1)
    moving = ~sim.state.done  # an episode that ended (goal, wall) stopped moving the robot
    assert moving.sum() > 10
    assert np.abs(predicted - truth)[moving].max() < 1e-9
    static = predict_positions("static", observation(0), observation(1), actions[0],
                               actions[1:].T, params)  # fmt: skip
    assert np.abs(static - truth)[moving][:, :, 1:].max() > 0.1  # the humans do move


def test_unknown_predictor_is_one_line() -> None:
    obs = np.zeros((1, 23))
    with pytest.raises(ValueError, match="predictor: unknown 'oracle'"):
        predict_positions("oracle", obs, obs, np.zeros(1, int), np.zeros((1, 2), int), STATIC)
