"""The planning model of a holonomic robot (CrowdNav's presets): the robot translates by its
command (vx, vy) and never turns; everything else is the unicycle model's."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from socnav_wm.config import load_params
from socnav_wm.env.core import Simulator
from socnav_wm.io import ModelFileError
from socnav_wm.worldmodel import planning_file, residual, residual_training
from socnav_wm.worldmodel.ego import commands_of, predict_positions
from socnav_wm.worldmodel.params import PlanningModelParams
from socnav_wm.worldmodel.prediction import random_policy, record
from tests.worldmodel.test_residual import assert_plans_as_cv_mpc, rows_of

CROWDNAV = load_params(overlays=["configs/scenarios/crowdnav.yaml"]).env
UNICYCLE = CROWDNAV.replace(kinematics="unicycle")


@pytest.fixture(scope="module")
def recording():
    return record(CROWDNAV, random_policy(3), seed=5, scenario_ids=np.arange(48), steps=24)


def model(room: bool = False) -> residual.ResidualDynamics:
    e = CROWDNAV
    return residual.ResidualDynamics(
        e.num_humans, 8, e.dt, None, e.spawn_half_size if room else None, 4, holonomic=True
    )


def test_an_untrained_holonomic_model_is_constant_velocity(recording) -> None:
    start = (recording.obs[2], recording.obs[3], recording.actions[2])
    future = recording.actions[3:9].T
    ours = residual.residual_positions(model(), *start, future, CROWDNAV)
    cv = predict_positions("constant-velocity", *start, future, CROWDNAV)
    np.testing.assert_allclose(ours, cv, atol=1e-12)
    # The unicycle's reading of the same commands (a turn for "left") is another future.
    unicycle = residual.ResidualDynamics(CROWDNAV.num_humans, 8, CROWDNAV.dt, None, None, 4)
    theirs = residual.residual_positions(unicycle, *start, future, CROWDNAV)
    assert np.abs(theirs - cv).max() > 0.1


def test_the_holonomic_pose_moves_as_the_simulator_robot_for_every_action() -> None:
    sim = Simulator(4, CROWDNAV)
    sim.reset(seed=3, scenario_ids=np.arange(4))
    sim.state.robot_theta[:] = [0.3, -1.2, 2.0, 3.0]  # the heading turns the command
    before = sim.state.robot_pose()
    motion = commands_of(np.arange(4), CROWDNAV)
    sim.step(np.arange(4))
    after = residual.advance_pose_holonomic(
        *(torch.from_numpy(np.asarray(x, dtype=np.float64)) for x in (before, motion.v, motion.vy)),
        CROWDNAV.dt,
    )
    np.testing.assert_allclose(after[:, :2].numpy(), sim.state.robot_xy, atol=1e-12)
    np.testing.assert_allclose(after[:, 2].numpy(), before[:, 2], atol=0)


def test_the_robot_seen_by_a_holonomic_model_moves_sideways_and_never_turns() -> None:
    net = model()
    points = torch.zeros(1, 1 + CROWDNAV.num_humans, 2, dtype=torch.float64)
    points[0, 1:, 0] = torch.arange(1.0, 1.0 + CROWDNAV.num_humans)
    net = net.double()
    left = torch.tensor([0.0], dtype=torch.float64), torch.tensor([1.0], dtype=torch.float64)
    x, _, _ = net.features(points, torch.zeros_like(points), *left)
    # Each human's last features: the robot's relative velocity (its last 2 of 4), the turn, the
    # lead time. The robot moves at (0, 1)·dt: one human's frame is the robot's (standing).
    np.testing.assert_allclose(x[0, 0, -4:-2].numpy(), [0.0, CROWDNAV.dt])
    assert x[0, 0, -2].item() == 0.0  # no turn
    with torch.no_grad():
        moved, _, _ = net.step(points, torch.zeros_like(points), *left)
    np.testing.assert_allclose(moved[0, :, 1].numpy(), -CROWDNAV.dt)  # everything slid right
    np.testing.assert_allclose(moved[0, :, 0].numpy(), points[0, :, 0].numpy())


def test_a_planner_on_the_untrained_holonomic_model_scores_as_cv_mpc(recording) -> None:
    assert_plans_as_cv_mpc(model(), CROWDNAV, recording)


def test_a_holonomic_training_is_saved_as_one_and_refused_for_the_unicycle(
    recording, tmp_path
) -> None:
    obs, actions, ids, next_obs, poses = rows_of(recording, with_poses=True)
    train = np.isin(ids, np.arange(40))
    seqs = [
        residual_training.make_sequences(obs[r], actions[r], ids[r], next_obs[r], 6, 3, poses[r])
        for r in (train, ~train)
    ]
    params = PlanningModelParams(
        hidden_dim=16, learning_rate=1e-3, batch_size=32, max_epochs=2, patience=2,
        relative_weight=0.0, room=True, neighbours=4,
    )  # fmt: skip
    result = residual_training.train_residual(*seqs, CROWDNAV, params, seed=0)
    assert result.model.holonomic
    assert result.metrics["val_loss"] <= result.metrics["val_loss_constant_velocity"]
    assert all(np.isfinite(row["train_loss"]) for row in result.history[1:])
    path = tmp_path / "m.pt"
    planning_file.save_residual(path, result, {"seed": 0})
    loaded = planning_file.load_residual(path, CROWDNAV)
    assert loaded.holonomic and loaded.room_half == CROWDNAV.spawn_half_size
    v = seqs[1]
    np.testing.assert_array_equal(
        residual.residual_positions(
            loaded, v.previous_obs, v.obs, v.previous_action, v.actions, CROWDNAV, pose=v.pose
        ),
        residual.residual_positions(
            result.model, v.previous_obs, v.obs, v.previous_action, v.actions, CROWDNAV,
            pose=v.pose,
        ),
    )  # fmt: skip
    with pytest.raises(ModelFileError, match="kinematics"):
        planning_file.load_residual(path, UNICYCLE)
