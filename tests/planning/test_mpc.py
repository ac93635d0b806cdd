"""The planner (socnav_wm/planning/mpc.py) and its constant-velocity model."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from socnav_wm.config import ConfigError, load_params
from socnav_wm.env.core import NUM_ACTIONS
from socnav_wm.env.params import EnvParams
from socnav_wm.evaluation.evaluate import evaluate_method
from socnav_wm.evaluation.records import BASELINE_SEED
from socnav_wm.planning.models import ConstantVelocityModel
from socnav_wm.planning.mpc import (
    FORWARD,
    LEFT,
    RIGHT,
    STOP,
    Planner,
    command_table,
    prefixes,
    towards_goal,
)
from socnav_wm.planning.params import PlanningParams
from socnav_wm.worldmodel.ego import predict_positions

ENV = EnvParams()


def observation(goal: tuple[float, float], humans: list[tuple[float, float]]) -> np.ndarray:
    """One robot-frame observation: the goal, then each human's position (other fields 0)."""
    obs = np.zeros(2 + 7 * ENV.num_humans)
    obs[:2] = goal
    for i, xy in enumerate(humans):
        obs[2 + 7 * i : 4 + 7 * i] = xy
        obs[6 + 7 * i] = ENV.human_radius
    return obs[None]


def test_prefixes_are_every_sequence_once() -> None:
    table = prefixes(3, NUM_ACTIONS)
    assert table.shape == (64, 3)
    assert len({tuple(row) for row in table}) == 64
    assert table[0].tolist() == [STOP, STOP, STOP]


def test_towards_goal_turns_then_advances() -> None:
    goals = np.array([[2.0, 0.0], [0.0, 2.0], [0.0, -2.0], [-2.0, 0.01]])
    assert towards_goal(goals, ENV).tolist() == [FORWARD, LEFT, RIGHT, LEFT]


def test_constant_velocity_model_rollout_matches_the_predictor() -> None:
    rng = np.random.default_rng(0)
    previous = rng.uniform(-4, 4, size=(5, 2 + 7 * ENV.num_humans))
    current = rng.uniform(-4, 4, size=previous.shape)
    last = rng.integers(0, 4, size=5)
    future = rng.integers(0, 4, size=(5, 6))
    model = ConstantVelocityModel(ENV)
    model.reset(previous)
    model.observe(current, last)
    rollout = model.rollout(1)
    steps = np.stack([rollout.step(future[:, k]) for k in range(6)], axis=1)
    expected = predict_positions("constant-velocity", previous, current, last, future, ENV)
    np.testing.assert_allclose(steps, expected, atol=1e-12)


def test_planner_advances_on_a_free_path_and_waits_for_a_crossing_human() -> None:
    far = [(8.0, 8.0), (-8.0, 8.0), (-8.0, -8.0)]
    blind = PlanningParams(walls=False)  # the policy of observations alone
    free = Planner(ConstantVelocityModel(ENV), blind, ENV).policy()
    assert free(observation((3.0, 0.0), far)).tolist() == [FORWARD]

    # A human ahead-left crossing the robot's path at 0.3 m/s: one step forward meets it
    # (0.63 m apart, centre to centre, under the 0.66 m of the two radii); waiting does not.
    planner = Planner(ConstantVelocityModel(ENV), blind, ENV)
    act = planner.policy()
    first = [(0.7, 0.9), *far[1:]]
    assert act(observation((3.0, 0.0), first)).tolist() == [FORWARD]  # no velocity yet
    crossing = [(0.7, 0.6), *far[1:]]
    # The robot stood still or turned in place, so the human's displacement is its own.
    planner.model.reset(observation((3.0, 0.0), first))
    planner.model.observe(observation((3.0, 0.0), crossing), np.array([STOP]))
    scores = planner.scores(np.array([[3.0, 0.0]])).reshape(64, -1)
    forward_first = scores[prefixes(3, NUM_ACTIONS)[:, 0] == FORWARD].max()
    waiting = scores[prefixes(3, NUM_ACTIONS)[:, 0] != FORWARD].max()
    assert waiting > forward_first
    assert planner.act(observation((3.0, 0.0), crossing)).tolist() != [FORWARD]


def test_a_planner_that_knows_the_walls_counts_a_wall_contact_as_a_collision() -> None:
    far = [(8.0, 8.0), (-8.0, 8.0), (-8.0, -8.0)]
    half = ENV.wall_half_size - ENV.robot_radius
    pose = np.array([[half - 0.1, 0.0, 0.0]])  # facing the wall, 0.1 m from touching it
    params = PlanningParams(horizon=1, prefix_length=1, progress_weight=0.0, discomfort_cost=0.0)
    planner = Planner(ConstantVelocityModel(ENV), params, ENV)
    planner.model.reset(observation((0.0, -2.0), far))
    scores = planner.scores(np.array([[0.0, -2.0]]), pose).reshape(4, -1)[:, 0]
    assert scores[FORWARD] == -params.collision_cost
    assert np.all(np.delete(scores, FORWARD) == 0.0)
    # Without the pose (or with walls off) the wall is invisible: forward costs nothing.
    assert np.all(planner.scores(np.array([[0.0, -2.0]])) == 0.0)


def test_the_walls_policy_reads_only_the_observation_the_pose_the_map_and_what_runs() -> None:
    far = [(8.0, 8.0), (-8.0, 8.0), (-8.0, -8.0)]
    half = ENV.wall_half_size - ENV.robot_radius
    # Facing the wall 0.1 m from touching it, the goal straight ahead beyond it: progress says
    # forward, the wall says no.
    state = SimpleNamespace(
        robot_pose=lambda: np.array([[half - 0.1, 0.0, 0.0]]),
        obstacle_kind=np.zeros((1, 0), dtype=np.int8),
        done=np.zeros(1, dtype=bool),
    )
    sim = SimpleNamespace(observation=observation((1.0, 0.0), far), state=state)
    blind = Planner(ConstantVelocityModel(ENV), PlanningParams(walls=False), ENV)
    seeing = Planner(ConstantVelocityModel(ENV), PlanningParams(), ENV)
    assert seeing.reads_simulator and not blind.reads_simulator
    assert blind.policy()(sim.observation).tolist() == [FORWARD]
    assert seeing.policy()(sim).tolist() != [FORWARD]


@pytest.mark.parametrize("method", ["cv-mpc", "wm-mpc", "vae-lstm-mpc"])
def test_only_the_running_episodes_are_planned_and_their_actions_do_not_change(method) -> None:
    """An ended episode waits for the batch's last one: planning it costs time and changes
    nothing, so the running ones' actions are those of planning every episode."""
    from socnav_wm.env.core import Simulator
    from socnav_wm.methods import method as registered

    params = PlanningParams(horizon=4, prefix_length=1)
    factory = registered(method).policies(ENV, planning=params)
    sim = Simulator(6, ENV)
    sim.reset(seed=11)
    every, _ = factory()
    some, _ = factory()
    running = np.array([True, False, True, True, False, True])
    for _ in range(4):
        full = every(SimpleNamespace(observation=sim.observation, state=_state(sim, None)))
        part = some(SimpleNamespace(observation=sim.observation, state=_state(sim, running)))
        assert np.array_equal(part[running], full[running])
        assert np.all(part[~running] == 0)
        sim.step(full)


def _state(sim, running):
    """The simulator's state as a planner reads it, with ``running`` episodes (None: all)."""
    done = np.zeros(sim.num_envs, dtype=bool) if running is None else ~running
    return SimpleNamespace(
        robot_pose=sim.state.robot_pose,
        obstacle_kind=sim.state.obstacle_kind,
        obstacle_xy=sim.state.obstacle_xy,
        obstacle_half=sim.state.obstacle_half,
        done=done,
    )


def test_cv_mpc_evaluation_runs_once_without_a_training_seed() -> None:
    params = PlanningParams(horizon=4, prefix_length=1)
    result = evaluate_method(
        "cv-mpc", env_params=ENV, scenario_seed=3, episodes=3, planning=params, batch_size=2
    )
    assert result.training_seeds == (BASELINE_SEED,)
    assert result.episodes.num_rows == 3
    assert result.settings["planning"]["horizon"] == 4
    with pytest.raises(ValueError, match="not a planner"):
        evaluate_method("orca", env_params=ENV, scenario_seed=3, episodes=1, planning=params)


@pytest.mark.parametrize(
    ("override", "key"),
    [
        ("planning.horizon=0", "planning.horizon"),
        ("planning.prefix_length=6", "planning.prefix_length"),
        ("planning.continuations=[goal, goal]", "planning.continuations"),
        ("planning.discount=1.5", "planning.discount"),
        ("planning.per_method.mpc={horizon: 3}", "planning.per_method: unknown planner 'mpc'"),
        ("planning.per_method.cv-mpc.horizon=0", "planning.per_method.cv-mpc.horizon"),
        ("planning.per_method.cv-mpc.horizn=3", "planning.per_method.cv-mpc.horizn"),
    ],
)
def test_bad_planning_values_name_their_key(tmp_path, override: str, key: str) -> None:
    path = tmp_path / "params.yaml"
    path.write_text("seed: 0\n")
    with pytest.raises(ConfigError, match=key):
        load_params(path, [override])


def test_a_planner_uses_its_per_method_overrides_and_only_it(tmp_path) -> None:
    path = tmp_path / "params.yaml"
    path.write_text("seed: 0\n")
    shipped = load_params(path).planning
    assert shipped.resolved("cv-mpc") == shipped.replace(per_method={})
    assert shipped.resolved("vae-lstm-mpc").horizon == shipped.per_method["vae-lstm-mpc"]["horizon"]
    params = load_params(path, ["planning.per_method.cv-mpc.horizon=3"]).planning
    assert params.resolved("cv-mpc").horizon == 3
    assert params.resolved("oracle-mpc").horizon == params.horizon == 12
    with pytest.raises(ValueError, match="unknown planner 'orca'"):
        params.resolved("orca")


@pytest.mark.parametrize("kinematics", ["unicycle", "holonomic"])
def test_a_lattice_has_every_speed_and_heading_and_stops_first(kinematics: str) -> None:
    env = EnvParams(kinematics=kinematics, robot_max_speed=1.0)
    params = PlanningParams(
        actions="lattice", lattice_speeds=2, lattice_headings=8, prefix_length=1
    )
    table = command_table(params, env)
    assert table.shape == (params.num_actions, 2) == (24, 2)
    assert np.array_equal(table[0], [0.0, 0.0])
    if kinematics == "holonomic":  # eight directions at 0.5 and 1 m/s
        speeds = np.round(np.hypot(table[:, 0], table[:, 1]), 9)
        assert sorted(set(speeds)) == [0.0, 0.5, 1.0]
        assert np.count_nonzero(speeds == 1.0) == 8
    else:  # three speeds, eight turn rates within the robot's limit
        assert sorted(set(np.round(table[:, 0], 9))) == [0.0, 0.5, 1.0]
        assert np.abs(table[:, 1]).max() == pytest.approx(env.robot_max_rotation)
    assert command_table(PlanningParams(), env) is None


def test_planners_on_a_lattice_send_continuous_commands_and_reach_goals() -> None:
    env = load_params(overlays=["configs/scenarios/crowdnav.yaml"]).env
    params = PlanningParams(actions="lattice", prefix_length=1, horizon=8)
    for method in ("cv-mpc", "oracle-mpc"):
        result = evaluate_method(
            method, env_params=env, scenario_seed=3, episodes=4, planning=params, batch_size=4
        )
        assert result.episodes["success"].to_numpy().mean() >= 0.5, method


def test_only_constant_velocity_and_the_oracle_plan_over_a_lattice() -> None:
    with pytest.raises(ValueError, match="prefix_length: 24 actions over 3 steps make 13,824"):
        PlanningParams(actions="lattice")
    from socnav_wm.methods import METHODS
    from socnav_wm.methods.planners import planner_policies

    lattice = PlanningParams(actions="lattice", prefix_length=1)
    for method in ("wm-mpc", "vae-lstm-mpc"):
        with pytest.raises(ValueError, match=f"planning.actions: {method}'s model imagines"):
            planner_policies(METHODS[method], ENV, lattice, lambda: None)
