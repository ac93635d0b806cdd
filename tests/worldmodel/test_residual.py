"""The residual constant-velocity planning model (socnav_wm/worldmodel/residual.py)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from socnav_wm.env.params import EnvParams
from socnav_wm.planning.models import ConstantVelocityModel
from socnav_wm.planning.mpc import Planner
from socnav_wm.planning.params import PlanningParams
from socnav_wm.planning.residual import ResidualPlanningModel
from socnav_wm.worldmodel import planning_file, residual, residual_training
from socnav_wm.worldmodel.ego import advance, commands_of, positions, predict_positions
from socnav_wm.worldmodel.params import PlanningModelParams
from socnav_wm.worldmodel.prediction import random_policy, record

ENV = EnvParams()


@pytest.fixture(scope="module")
def recording():
    return record(ENV, random_policy(3), seed=5, scenario_ids=np.arange(48), steps=24)


def rows_of(rec, with_poses: bool = False):
    """The recording as rollout rows (obs, action, episode id, next obs, and with
    ``with_poses`` the robot's pose after the step), real steps only."""
    obs, actions, ids, next_obs, poses = [], [], [], [], []
    for n in range(rec.obs.shape[1]):
        steps = np.flatnonzero(rec.stepped[:, n])
        obs.append(rec.obs[steps, n])
        next_obs.append(rec.obs[steps + 1, n])
        actions.append(rec.actions[steps, n])
        ids.append(np.full(len(steps), n))
        poses.append(rec.pose[steps + 1, n])
    columns = (obs, actions, ids, next_obs, poses) if with_poses else (obs, actions, ids, next_obs)
    return tuple(np.concatenate(x) for x in columns)


def perturbed(seed: int = 0) -> residual.ResidualDynamics:
    torch.manual_seed(seed)
    model = residual.ResidualDynamics(ENV.num_humans, 16, ENV.dt)
    with torch.no_grad():
        model.net[-1].weight.normal_(0.0, 0.05)
    return model


def test_ego_advance_in_torch_equals_numpy_for_every_action() -> None:
    rng = np.random.default_rng(0)
    points, velocity = rng.normal(size=(4, 4, 2)), rng.normal(scale=0.1, size=(4, 4, 2))
    motion = commands_of(np.arange(4), ENV)
    v, w = motion.v, motion.omega
    expected = advance(points, velocity, motion, ENV.dt)
    got = residual.ego_advance(*(torch.from_numpy(x) for x in (points, velocity, v, w)), ENV.dt)
    for e, g in zip(expected, got, strict=True):
        np.testing.assert_allclose(g.numpy(), e, atol=1e-12)


def test_an_untrained_model_is_constant_velocity(recording) -> None:
    model = residual.ResidualDynamics(ENV.num_humans, 16, ENV.dt)
    start = (recording.obs[2], recording.obs[3], recording.actions[2])
    future = recording.actions[3:9].T
    ours = residual.residual_positions(model, *start, future, ENV)
    cv = predict_positions("constant-velocity", *start, future, ENV)
    np.testing.assert_allclose(ours, cv, atol=1e-12)


def test_a_corrected_human_never_outruns_the_top_speed_and_the_cap_keeps_cv(recording) -> None:
    capped = residual.ResidualDynamics(ENV.num_humans, 16, ENV.dt, ENV.human_max_speed)
    start = (recording.obs[2], recording.obs[3], recording.actions[2])
    future = recording.actions[3:9].T
    cv = predict_positions("constant-velocity", *start, future, ENV)
    # Within 10 µm: the observed velocities exceed the cap by rounding only.
    np.testing.assert_allclose(residual.residual_positions(capped, *start, future, ENV), cv,
                               atol=1e-5)  # fmt: skip
    with torch.no_grad():
        capped.net[-1].bias.fill_(100.0)  # pushes every human by ~1.4 m per step
    points, velocity = residual.present_state(*start, ENV)
    v, w = (torch.zeros(len(points), dtype=torch.float64),) * 2  # the robot stands still
    p0 = torch.from_numpy(points)
    p1, _, _ = capped.double().step(p0, torch.from_numpy(velocity), v, w)
    moved = torch.linalg.vector_norm(p1[:, 1:] - p0[:, 1:], dim=-1)
    assert moved.max() <= ENV.human_max_speed * ENV.dt + 1e-9
    assert moved.max() >= ENV.human_max_speed * ENV.dt - 1e-9  # ... and is held there


def test_a_trained_correction_changes_the_humans_and_never_the_goal(recording) -> None:
    model = perturbed()
    start = (recording.obs[2], recording.obs[3], recording.actions[2])
    future = recording.actions[3:9].T
    ours = residual.residual_positions(model, *start, future, ENV)
    cv = predict_positions("constant-velocity", *start, future, ENV)
    np.testing.assert_allclose(ours[:, :, 0], cv[:, :, 0], atol=1e-12)
    assert np.abs(ours[:, :, 1:] - cv[:, :, 1:]).max() > 1e-3


def test_positions_do_not_depend_on_the_batch_size(recording) -> None:
    model = perturbed(1)
    start = (recording.obs[2], recording.obs[3], recording.actions[2])
    future = recording.actions[3:9].T
    one = residual.residual_positions(model, *start, future, ENV, batch_size=1)
    many = residual.residual_positions(model, *start, future, ENV, batch_size=512)
    np.testing.assert_allclose(one, many, rtol=0, atol=1e-12)


def test_sequences_follow_the_episodes_and_mask_their_ends(recording) -> None:
    obs, actions, ids, next_obs = rows_of(recording)
    seqs = residual_training.make_sequences(obs, actions, ids, next_obs, horizon=5, stride=3)
    assert len(seqs) > 0
    for i in range(len(seqs)):
        # Find the sample's episode and step from its present observation.
        n, t = next(
            (n, t)
            for n in range(recording.obs.shape[1])
            for t in range(1, recording.obs.shape[0])
            if np.array_equal(recording.obs[t, n], seqs.obs[i])
        )
        np.testing.assert_array_equal(seqs.previous_obs[i], recording.obs[t - 1, n])
        assert seqs.previous_action[i] == recording.actions[t - 1, n]
        for k in range(5):
            real = t + k < recording.obs.shape[0] - 1 and recording.stepped[t + k, n]
            assert seqs.mask[i, k] == real
            if real:
                np.testing.assert_array_equal(
                    seqs.targets[i, k], positions(recording.obs[t + k + 1, n])
                )
                assert seqs.actions[i, k] == recording.actions[t + k, n]
        if i >= 40:
            break


def train_and_validation(rec, horizon: int) -> list[residual_training.Sequences]:
    """Training samples from the recording's first 36 episodes, validation from the rest."""
    obs, actions, ids, next_obs = rows_of(rec)
    return [
        residual_training.make_sequences(obs[m], actions[m], ids[m], next_obs[m], horizon, stride=2)
        for m in (ids < 36, ids >= 36)
    ]


def test_zero_epochs_write_constant_velocity_itself(recording) -> None:
    seqs = train_and_validation(recording, horizon=6)
    params = PlanningModelParams(hidden_dim=16, max_epochs=0, room=False)
    result = residual_training.train_residual(*seqs, ENV, params, seed=0)
    m = result.metrics
    assert (m["best_epoch"], m["epochs"]) == (0, 0)
    assert m["val_loss"] == m["val_loss_constant_velocity"]
    v = seqs[1]
    start = (v.previous_obs, v.obs, v.previous_action)
    np.testing.assert_array_equal(
        residual.residual_positions(result.model, *start, v.actions, ENV),
        residual.residual_positions(
            residual.ResidualDynamics(3, 16, ENV.dt, ENV.human_max_speed), *start, v.actions, ENV
        ),
    )  # fmt: skip
    with pytest.raises(ValueError, match="max_epochs"):
        PlanningModelParams(max_epochs=-1)


def test_a_real_training_beats_copy_last_and_keeps_its_best_epoch(recording) -> None:
    seqs = train_and_validation(recording, horizon=6)
    result = residual_training.train_residual(
        *seqs, ENV, PlanningModelParams(hidden_dim=16, learning_rate=1e-3, batch_size=32,
        max_epochs=3, patience=2, relative_weight=0.0, room=False), seed=0,
    )  # fmt: skip
    m = result.metrics
    assert m["val_loss"] <= m["val_loss_constant_velocity"]
    assert m["val_loss"] == min(row["val_loss"] for row in result.history)
    assert all(np.isfinite(row["train_loss"]) for row in result.history[1:])
    v = seqs[1]
    ours = residual.residual_positions(
        result.model, v.previous_obs, v.obs, v.previous_action, v.actions, ENV
    )
    copy_last = np.repeat(positions(v.obs)[:, None], v.actions.shape[1], axis=1)
    error = np.linalg.norm(ours - v.targets, axis=-1)[..., 1:].mean(-1)[v.mask].mean()
    copy_error = np.linalg.norm(copy_last - v.targets, axis=-1)[..., 1:].mean(-1)[v.mask].mean()
    assert error < copy_error


def test_weighting_the_humans_near_the_robot_changes_the_training(recording) -> None:
    seqs = train_and_validation(recording, horizon=4)
    near = np.linalg.norm(positions(seqs[0].obs)[:, 1:], axis=-1) <= 1.5
    assert 0 < near.mean() < 1  # some humans start near the robot, not all

    def trained(**weight) -> list[float]:  # the training loss of each epoch
        params = PlanningModelParams(hidden_dim=8, learning_rate=1e-3, batch_size=32,
                                     max_epochs=2, patience=2, room=False, **weight)  # fmt: skip
        result = residual_training.train_residual(*seqs, ENV, params, seed=0)
        return [row["train_loss"] for row in result.history[1:]]

    plain = trained()
    assert plain == trained(near_robot_weight=0.0, near_robot_distance=0.1)
    assert plain != trained(near_robot_weight=10.0)


def assert_plans_as_cv_mpc(net: residual.ResidualDynamics, env: EnvParams, rec) -> None:
    """A planner on ``net`` scores the recording's second step as ``cv-mpc`` does."""
    planning = PlanningParams(horizon=4, prefix_length=2)
    ours = ResidualPlanningModel(net, env)
    cv = ConstantVelocityModel(env)
    for model in (ours, cv):
        model.reset(rec.obs[0])
        model.observe(rec.obs[1], rec.actions[0])
    # The residual model imagines in float32, constant velocity in float64.
    np.testing.assert_allclose(
        Planner(ours, planning, env).scores(rec.obs[1][:, :2]),
        Planner(cv, planning, env).scores(rec.obs[1][:, :2]),
        atol=1e-4,
    )


def test_a_planner_on_the_untrained_model_scores_as_cv_mpc(recording) -> None:
    assert_plans_as_cv_mpc(residual.ResidualDynamics(3, 8, ENV.dt), ENV, recording)


def test_save_and_load_round_trip_and_refuse_other_files(tmp_path) -> None:
    model = perturbed(2)
    result = planning_file.ResidualTrainResult(model=model, history=[], metrics={})
    path = tmp_path / "m.pt"
    planning_file.save_residual(path, result, {"seed": 0})
    loaded = planning_file.load_residual(path)
    for a, b in zip(model.state_dict().values(), loaded.state_dict().values(), strict=True):
        torch.testing.assert_close(a, b)
    torch.save({"format": "other"}, tmp_path / "x.pt")
    with pytest.raises(ValueError, match="x.pt: not a socnav-wm planning model"):
        planning_file.load_residual(tmp_path / "x.pt")


def test_room_features_place_a_person_in_the_room_from_the_robot_pose() -> None:
    # The robot at (1, 2) facing +y; a person 3 m to its right walks at 0.1 m/step towards +x
    # of the room. In the room it stands at (4, 2), 0.5 m before the edge of the goal area.
    pose = torch.tensor([[1.0, 2.0, np.pi / 2]], dtype=torch.float64)
    points = torch.tensor([[[0.0, 0.0], [0.0, -3.0], [5.0, 5.0], [5.0, 5.0]]], dtype=torch.float64)
    velocity = torch.tensor(
        [[[0.0, 0.0], [0.0, -0.1], [0.0, 0.0], [0.0, 0.0]]], dtype=torch.float64
    )
    f = residual.room_features(points, velocity, pose, half=4.5)[0, 0]
    # Centre seen from the person, in its heading's frame: 4 m behind, 2 m to its right.
    np.testing.assert_allclose(f.numpy(), [-4 / 4.5, -2 / 4.5, 0.5 / 4.5, 1.0, 0.0], atol=1e-12)


def test_advance_pose_is_the_simulator_unicycle_for_every_action() -> None:
    from socnav_wm.env.core import Simulator

    sim = Simulator(4, ENV)
    sim.reset(seed=3, scenario_ids=np.arange(4))
    before = np.column_stack([sim.state.robot_xy, sim.state.robot_theta])
    motion = commands_of(np.arange(4), ENV)
    v, w = motion.v, motion.omega
    sim.step(np.arange(4))
    after = residual.advance_pose(
        *(torch.from_numpy(np.asarray(x)) for x in (before, v, w)), ENV.dt
    )
    np.testing.assert_allclose(after[:, :2].numpy(), sim.state.robot_xy, atol=1e-12)
    np.testing.assert_allclose(
        np.cos(after[:, 2].numpy()), np.cos(sim.state.robot_theta), atol=1e-12
    )


def test_sequences_carry_the_pose_each_observation_was_seen_from(recording) -> None:
    obs, actions, ids, next_obs, pose_after = rows_of(recording, with_poses=True)
    seqs = residual_training.make_sequences(obs, actions, ids, next_obs, 5, 3, pose_after)
    for i in range(0, len(seqs), 7):
        n, t = next(
            (n, t)
            for n in range(recording.obs.shape[1])
            for t in range(1, recording.obs.shape[0])
            if np.array_equal(recording.obs[t, n], seqs.obs[i])
        )
        np.testing.assert_array_equal(seqs.pose[i], recording.pose[t, n])


def test_a_model_that_knows_the_room_needs_the_pose_and_learns_with_it(recording) -> None:
    obs, actions, ids, next_obs, pose_after = rows_of(recording, with_poses=True)
    train, val = ids < 36, ids >= 36
    seqs = [
        residual_training.make_sequences(
            obs[m], actions[m], ids[m], next_obs[m], 6, 2, pose_after[m]
        )
        for m in (train, val)
    ]
    result = residual_training.train_residual(
        *seqs, ENV, PlanningModelParams(hidden_dim=16, learning_rate=1e-3, batch_size=32,
        max_epochs=2, patience=2, room=True, relative_weight=0.5), seed=0,
    )  # fmt: skip
    assert result.model.room_half == ENV.spawn_half_size
    assert result.metrics["val_loss"] <= result.metrics["val_loss_constant_velocity"]
    v = seqs[1]
    start = (v.previous_obs, v.obs, v.previous_action, v.actions, ENV)
    with pytest.raises(ValueError, match="knows the room"):
        residual.residual_positions(result.model, *start)
    with_pose = residual.residual_positions(result.model, *start, pose=v.pose)
    assert np.isfinite(with_pose).all()
    planner_model = ResidualPlanningModel(result.model, ENV)
    planner_model.reset(v.obs[:2])
    with pytest.raises(ValueError, match="planning.walls"):
        planner_model.rollout(4)
    no_poses = residual_training.make_sequences(
        obs[train], actions[train], ids[train], next_obs[train], 6, 2
    )
    with pytest.raises(ValueError, match="carry no robot poses"):
        residual_training.train_residual(
            no_poses, seqs[1], ENV, PlanningModelParams(hidden_dim=8, learning_rate=1e-3,
            batch_size=32, max_epochs=1, patience=1, relative_weight=0.0, room=True), seed=0,
        )  # fmt: skip


def test_a_model_of_the_nearest_neighbours_ignores_the_order_and_the_far_humans(tmp_path) -> None:
    """neighbours=K: each human sees the K nearest others, nearest first, then the robot, so
    its correction does not depend on the others' spawn order nor on the humans beyond them;
    the file keeps K."""
    torch.manual_seed(0)
    model = residual.ResidualDynamics(6, 16, 1.0, neighbours=2)
    assert model.net[0].in_features == 1 + 4 * (2 + 1) + 2
    with torch.no_grad():
        model.net[-1].weight.normal_(0.0, 0.5)
    points = torch.randn(5, 7, 2) * 2.0  # the goal, then 6 humans
    velocity = torch.randn(5, 7, 2) * 0.1
    v, omega = torch.full((5,), 0.1), torch.zeros(5)
    out = model(points, velocity, v, omega)
    order = torch.tensor([0, 3, 1, 6, 2, 5, 4])  # the humans shuffled, the goal first
    shuffled = model(points[:, order], velocity[:, order], v, omega)
    torch.testing.assert_close(shuffled, out[:, order[1:] - 1])
    # Human 0 sees only its two nearest: moving a human beyond them changes nothing for it.
    distance = torch.linalg.vector_norm(points[:, 2:] - points[:, 1:2], dim=-1)
    far = int(distance[0].argmax()) + 2
    moved = points.clone()
    moved[0, far] += 0.5 * (points[0, far] - points[0, 1])  # further away along the same line
    torch.testing.assert_close(model(moved, velocity, v, omega)[0, 0], out[0, 0])
    path = tmp_path / "k.pt"
    result = planning_file.ResidualTrainResult(model=model, history=[], metrics={})
    planning_file.save_residual(path, result, {"seed": 0})
    assert planning_file.load_residual(path).neighbours == 2


@pytest.mark.parametrize("humans", [1, 2, 3, 7, 20])
def test_the_others_seen_from_each_human_leave_out_exactly_its_own_entry(humans) -> None:
    """_off_diagonal picks the entries a boolean mask of the diagonal keeps, in the same order,
    and the gradient flows back through it bit for bit as through the mask."""
    keep = ~torch.eye(humans, humans + 1, dtype=torch.bool)
    x = torch.randn(4, humans, humans + 1, 2, requires_grad=True)
    ours = residual._off_diagonal(x)
    theirs = x[:, keep].reshape(-1, humans, humans, 2)
    assert torch.equal(ours, theirs)
    weight = torch.randn_like(ours)
    (g_ours,) = torch.autograd.grad((ours * weight).sum(), x)
    (g_theirs,) = torch.autograd.grad((theirs * weight).sum(), x)
    assert torch.equal(g_ours, g_theirs)


def test_futures_imagined_once_and_in_chunks_are_those_imagined_one_by_one(
    recording, monkeypatch
) -> None:
    """The planner's rollouts imagine each distinct future once (futures that took the same
    actions from the same present are one), in chunks of whole episodes (about CHUNK_AGENTS
    humans): any chunking gives, bit for bit, the positions and velocities of the model run on
    every future's own row."""
    from socnav_wm.planning import residual as planning_residual

    model = ResidualPlanningModel(perturbed(3), ENV)
    model.reset(recording.obs[0])
    model.observe(recording.obs[1], recording.actions[0])
    # 7 futures per episode: the first two steps shared by some, as a planner's prefixes are.
    rng = np.random.default_rng(0)
    actions = rng.integers(0, 4, size=(5, 48 * 7))
    actions[0] = np.repeat(rng.integers(0, 4, size=48 * 7 // 4), 4)  # runs of 4 alike
    actions[1, ::7] = actions[1, 1::7]
    net, table = model.net, model.table
    start = model.rollout(7)
    points = torch.as_tensor(np.repeat(model._points, 7, axis=0), dtype=torch.float32)
    velocity = torch.as_tensor(np.repeat(model._velocity, 7, axis=0), dtype=torch.float32)
    reference = []
    with torch.no_grad():
        for k, a in enumerate(actions):
            command = table[torch.as_tensor(a)]
            points, velocity, _ = net.step(points, velocity, command[:, 0], command[:, 1], None, k)
            reference.append(
                (points.numpy().astype(np.float64), velocity.numpy().astype(np.float64))
            )
    assert start.points.shape[0] == 48  # one present per episode
    # One chunk; chunks of 35 futures' humans at most; one episode each.
    for agents, fewest in ((10**6, 1), (3 * 7 * 5, 2), (1, 48)):
        monkeypatch.setattr(planning_residual, "CHUNK_AGENTS", agents)
        rollout = model.rollout(7)
        for k, (a, (p, u)) in enumerate(zip(actions, reference, strict=True)):
            assert np.array_equal(rollout.step(a), p) and np.array_equal(rollout.velocities(), u)
            # As many futures as distinct (episode, actions so far) histories.
            histories = np.column_stack((np.arange(48 * 7) // 7, actions[: k + 1].T))
            assert rollout.points.shape[0] == len(np.unique(histories, axis=0))
            assert k > 0 or rollout.points.shape[0] < 48 * 7 / 2
            chunks = rollout._chunks()
            episodes = [len(np.unique(rollout.episode[c])) for c in chunks]
            assert sum(episodes) == 48 and len(chunks) >= fewest
            for c, n in zip(chunks, episodes, strict=True):  # whole episodes, within the size
                assert n == 1 or (c.stop - c.start) * ENV.num_humans <= agents
