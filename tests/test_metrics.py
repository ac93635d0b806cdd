"""Tests for socnav_wm.metrics: every metric on small hand-made trajectories, numbers by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from socnav_wm import metrics as m
from socnav_wm.metrics import MetricParams, Trajectory, episode_metrics


def make_traj(
    robot_xy,
    human_xy=None,
    goal_xy=(2.0, 0.0),
    dmin=None,
    rewards=None,
    success=False,
    collision=None,
    truncated=False,
) -> Trajectory:
    robot_xy = np.asarray(robot_xy, dtype=float)
    t = robot_xy.shape[0] - 1
    if human_xy is None:
        human_xy = np.full((t + 1, 1, 2), 4.0)  # one human far away in a corner
    return Trajectory(
        robot_xy=robot_xy,
        human_xy=np.asarray(human_xy, dtype=float),
        goal_xy=np.asarray(goal_xy, dtype=float),
        dmin=np.full(t, 5.0) if dmin is None else np.asarray(dmin, dtype=float),
        rewards=np.zeros(t) if rewards is None else np.asarray(rewards, dtype=float),
        success=success,
        collision=collision,
        truncated=truncated,
    )


@pytest.fixture
def walk_then_stop() -> Trajectory:
    """Robot moves +x by 0.14 m for 3 steps, then stands still for 2 (T = 5).

    Human 0 stands at (1.5, 0): centre distances 1.50, 1.36, 1.22, 1.08, 1.08, 1.08, so surface
    distances (minus 0.36 + 0.3 = 0.66) are 0.84, 0.70, 0.56, 0.42, 0.42, 0.42.
    Human 1 stands at (-3, -3), always > 4 m away.
    """
    xs = [0.0, 0.14, 0.28, 0.42, 0.42, 0.42]
    robot = np.array([[x, 0.0] for x in xs])
    humans = np.array([[[1.5, 0.0], [-3.0, -3.0]]] * 6)
    return make_traj(
        robot,
        humans,
        goal_xy=(3.0, 0.0),
        dmin=[1.2, 0.95, 0.5, 0.9999, 1.5],
        rewards=[-0.1, -0.1, -0.1, -0.1, 0.5],
        truncated=True,
    )


# ---------------------------------------------------------------------------------------------
# Paper metrics on the walk-then-stop episode
# ---------------------------------------------------------------------------------------------


def test_discomfort_counts_strictly_below_threshold(walk_then_stop):
    # 0.95 and 0.5 are below 0.9999; 0.9999 itself is not.
    assert m.discomfort(walk_then_stop) == 2.0


def test_distance_travelled_and_path_length(walk_then_stop):
    assert m.distance_travelled(walk_then_stop) == pytest.approx(0.42)
    assert m.path_length(walk_then_stop) == m.distance_travelled(walk_then_stop)


def test_simulation_time_uses_dt(walk_then_stop):
    assert m.simulation_time(walk_then_stop) == 5.0
    assert m.simulation_time(walk_then_stop, MetricParams(dt=0.5)) == 2.5


def test_idle_time(walk_then_stop):
    # Two steps with zero displacement; the 0.14 m steps are not idle.
    assert m.idle_time(walk_then_stop) == 2.0
    assert m.idle_time(walk_then_stop, MetricParams(dt=0.5)) == 1.0
    # With a threshold above 0.14 m every step is idle.
    assert m.idle_time(walk_then_stop, MetricParams(idle_threshold=0.15)) == 5.0


def test_reward_success_flags(walk_then_stop):
    assert m.reward(walk_then_stop) == pytest.approx(0.1)
    assert m.success(walk_then_stop) == 0.0
    assert m.max_steps(walk_then_stop) == 1.0
    assert m.human_collision(walk_then_stop) == 0.0
    assert m.wall_collision(walk_then_stop) == 0.0


def test_personal_space_compliance(walk_then_stop):
    # Post-step surface distances to human 0: 0.70, 0.56, 0.42, 0.42, 0.42 -> 2 of 5 exceed 0.5.
    assert m.personal_space_compliance(walk_then_stop) == pytest.approx(0.4)
    # Personal space 0.6 m: only 0.70 passes -> 1/5.
    assert m.personal_space_compliance(
        walk_then_stop, MetricParams(personal_space=0.6)
    ) == pytest.approx(0.2)


def test_personal_space_compliance_code(walk_then_stop):
    # Centre distances 1.36 .. 1.08 are all < 2.02 -> never compliant.
    assert m.personal_space_compliance_code(walk_then_stop) == 0.0
    # With a 1.2 m radius: 1.36 and 1.22 pass -> 2/5.
    assert m.personal_space_compliance_code(
        walk_then_stop, MetricParams(code_psc_radius=1.2)
    ) == pytest.approx(0.4)


def test_minimum_distance_and_failure_metrics(walk_then_stop):
    assert m.minimum_distance_to_human(walk_then_stop) == pytest.approx(0.42)
    assert math.isnan(m.time_to_reach_goal(walk_then_stop))
    assert m.spl(walk_then_stop) == 0.0


def test_episode_metrics_keys_and_values(walk_then_stop):
    out = episode_metrics(walk_then_stop)
    assert tuple(out) == m.ALL_METRICS
    assert all(isinstance(v, float) for v in out.values())
    assert out["discomfort"] == 2.0
    assert out["distance_travelled"] == pytest.approx(0.42)
    assert out["personal_space_compliance"] == pytest.approx(0.4)
    assert out["max_steps"] == 1.0


def test_personal_space_boundary_is_strict():
    # Human centre exactly 0.66 + 0.5 = 1.16 m away: not "more than" 0.5 m -> not compliant.
    robot = [[0.0, 0.0], [0.0, 0.0]]
    humans = [[[1.16, 0.0]], [[1.16, 0.0]]]
    traj = make_traj(robot, humans)
    assert m.personal_space_compliance(traj) == 0.0
    # The code variant's boundary is inclusive: exactly 2.02 m is compliant.
    traj = make_traj(robot, [[[2.02, 0.0]], [[2.02, 0.0]]])
    assert m.personal_space_compliance_code(traj) == 1.0


def test_personal_space_excludes_reset_state():
    # Human touching the robot at reset (t = 0) but gone after step 1: compliance 1.
    robot = [[0.0, 0.0], [0.0, 0.0]]
    humans = [[[0.7, 0.0]], [[3.0, 0.0]]]
    traj = make_traj(robot, humans)
    assert m.personal_space_compliance(traj) == 1.0
    # ... while the minimum distance does include t = 0: 0.7 - 0.66 = 0.04.
    assert m.minimum_distance_to_human(traj) == pytest.approx(0.04)


# ---------------------------------------------------------------------------------------------
# Successful episodes, SPL, time to goal
# ---------------------------------------------------------------------------------------------


def test_spl_straight_path_is_one():
    # Goal at 1.8 m: shortest path l = 1.8 - 0.8 = 1.0; robot moves straight 1.0 m.
    traj = make_traj([[0, 0], [0.5, 0], [1.0, 0]], goal_xy=(1.8, 0.0), success=True)
    assert m.spl(traj) == pytest.approx(1.0)
    assert m.time_to_reach_goal(traj) == 2.0
    assert m.time_to_reach_goal(traj, MetricParams(dt=0.25)) == 0.5


def test_spl_detour():
    # Path (0,0) -> (0.3,0.4) -> (1.1,0.4): 0.5 + 0.8 = 1.3 m; l = 1.0 -> SPL = 1/1.3.
    traj = make_traj([[0, 0], [0.3, 0.4], [1.1, 0.4]], goal_xy=(1.8, 0.0), success=True)
    assert m.distance_travelled(traj) == pytest.approx(1.3)
    assert m.spl(traj) == pytest.approx(1.0 / 1.3)


def test_spl_shorter_than_straight_line_is_capped():
    # Robot reaches goal region after 0.9 m although l = 1.0 (e.g. goal radius slack) -> 1.
    traj = make_traj([[0, 0], [0.9, 0]], goal_xy=(1.8, 0.0), success=True)
    assert m.spl(traj) == pytest.approx(1.0)


def test_spl_starting_inside_goal():
    # Start 0.5 m from the goal: l = 0. No motion -> 1; any motion -> 0 (by the formula).
    still = make_traj([[0, 0], [0, 0]], goal_xy=(0.5, 0.0), success=True)
    assert m.spl(still) == 1.0
    moved = make_traj([[0, 0], [0.1, 0]], goal_xy=(0.5, 0.0), success=True)
    assert m.spl(moved) == 0.0


# ---------------------------------------------------------------------------------------------
# Edge cases
# ---------------------------------------------------------------------------------------------


def test_zero_length_movement():
    traj = make_traj([[1.0, 1.0]] * 5)
    assert m.distance_travelled(traj) == 0.0
    assert m.idle_time(traj) == 4.0
    assert m.simulation_time(traj) == 4.0


def test_collision_at_step_one():
    # Robot (0,0) -> (0.14,0); human static at (0.7,0): surface distance after the step
    # 0.56 - 0.66 = -0.10 (overlap).
    traj = make_traj(
        [[0, 0], [0.14, 0]],
        [[[0.7, 0.0]], [[0.7, 0.0]]],
        dmin=[-0.1],
        rewards=[-1.0],
        collision="human",
    )
    out = episode_metrics(traj)
    assert out["human_collision"] == 1.0
    assert out["wall_collision"] == 0.0
    assert out["success"] == 0.0
    assert out["max_steps"] == 0.0
    assert out["simulation_time"] == 1.0
    assert out["discomfort"] == 1.0
    assert out["reward"] == -1.0
    assert out["idle_time"] == 0.0
    assert out["personal_space_compliance"] == 0.0
    assert out["minimum_distance_to_human"] == pytest.approx(-0.10)
    assert out["distance_travelled"] == pytest.approx(0.14)
    assert math.isnan(out["time_to_reach_goal"])
    assert out["spl"] == 0.0


def test_wall_collision_is_not_a_human_collision():
    traj = make_traj([[4.3, 0], [4.44, 0]], collision="wall")
    assert m.wall_collision(traj) == 1.0
    assert m.human_collision(traj) == 0.0


def test_no_humans():
    traj = make_traj([[0, 0], [0.1, 0]], human_xy=np.zeros((2, 0, 2)), dmin=[math.inf])
    assert m.personal_space_compliance(traj) == 1.0
    assert m.personal_space_compliance_code(traj) == 1.0
    assert m.minimum_distance_to_human(traj) == math.inf
    assert m.discomfort(traj) == 0.0


def test_trajectory_is_an_immutable_copy():
    robot = np.array([[0.0, 0.0], [0.1, 0.0]])
    traj = make_traj(robot)
    robot[1, 0] = 100.0
    assert m.distance_travelled(traj) == pytest.approx(0.1)
    with pytest.raises(ValueError):
        traj.robot_xy[0, 0] = 1.0  # read-only


# ---------------------------------------------------------------------------------------------
# Registry
# ---------------------------------------------------------------------------------------------


def test_metric_name_tuples():
    assert m.PAPER_METRICS == (
        "discomfort",
        "distance_travelled",
        "simulation_time",
        "human_collision",
        "max_steps",
        "reward",
        "success",
        "idle_time",
        "personal_space_compliance",
    )
    assert len(m.EXTRA_METRICS) == 8
    assert not set(m.PAPER_METRICS) & set(m.EXTRA_METRICS)


def test_directions_and_units_cover_all_metrics():
    names = set(m.PAPER_METRICS) | set(m.EXTRA_METRICS)
    assert set(m.METRIC_DIRECTIONS) == names
    assert set(m.METRIC_UNITS) == names
    assert set(m.METRIC_FUNCTIONS) == names
    assert set(m.METRIC_DIRECTIONS.values()) <= {"max", "min"}
    assert all(isinstance(u, str) and u for u in m.METRIC_UNITS.values())
    assert m.METRIC_DIRECTIONS["success"] == "max"
    assert m.METRIC_DIRECTIONS["human_collision"] == "min"
    assert m.METRIC_DIRECTIONS["personal_space_compliance"] == "max"


# ---------------------------------------------------------------------------------------------
# Validation
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"robot_xy": [[0, 0]]}, "at least one step"),
        ({"robot_xy": [0, 0, 1]}, "robot_xy must have shape"),
        ({"human_xy": np.zeros((2, 1, 2))}, "human_xy must have shape"),
        ({"human_xy": np.zeros((3, 2))}, "human_xy must have shape"),
        ({"goal_xy": [1.0, 2.0, 3.0]}, "goal_xy must have shape"),
        ({"dmin": [1.0]}, "dmin must have shape"),
        ({"rewards": [0.0, 0.0, 0.0]}, "rewards must have shape"),
        ({"robot_xy": [[0, 0], [np.nan, 0], [0, 0]]}, "robot_xy contains non-finite"),
        ({"dmin": [np.nan, 1.0]}, "dmin contains NaN"),
        ({"rewards": [np.inf, 1.0]}, "rewards contains non-finite"),
        ({"robot_xy": [["a", "b"], [0, 0], [0, 0]]}, "robot_xy is not a numeric array"),
        ({"collision": "table"}, "collision must be one of"),
        ({"success": True, "collision": "human"}, "both a success and a human collision"),
    ],
)
def test_invalid_trajectory_raises(kwargs, match):
    base = {
        "robot_xy": np.zeros((3, 2)),
        "human_xy": np.full((3, 1, 2), 4.0),
        "goal_xy": np.zeros(2),
        "dmin": np.ones(2),
        "rewards": np.zeros(2),
        "success": False,
        "collision": None,
        "truncated": False,
    }
    base.update(kwargs)
    with pytest.raises(ValueError, match=match):
        Trajectory(**base)


@pytest.mark.parametrize(
    "kwargs", [{"dt": 0.0}, {"robot_radius": -1.0}, {"idle_threshold": math.nan}]
)
def test_invalid_params_raise(kwargs):
    with pytest.raises(ValueError, match="MetricParams"):
        MetricParams(**kwargs)


def test_episode_metrics_rejects_non_trajectory():
    with pytest.raises(TypeError, match="Trajectory"):
        episode_metrics({"robot_xy": np.zeros((2, 2))})  # type: ignore[arg-type]


# ---------------------------------------------------------------------------------------------
# Properties
# ---------------------------------------------------------------------------------------------

_coords = st.floats(-4.8, 4.8, allow_nan=False)


@settings(max_examples=50, deadline=None)
@given(
    robot=arrays(np.float64, st.tuples(st.integers(2, 8), st.just(2)), elements=_coords),
    success=st.booleans(),
)
def test_metric_ranges(robot, success):
    t = robot.shape[0] - 1
    humans = np.broadcast_to(np.array([[1.0, -2.0], [-3.0, 3.0]]), (t + 1, 2, 2))
    traj = make_traj(robot, humans, goal_xy=robot[-1], success=success)
    out = episode_metrics(traj)
    assert out["path_length"] == out["distance_travelled"] >= 0.0
    assert 0.0 <= out["idle_time"] <= out["simulation_time"] == t
    assert 0.0 <= out["spl"] <= 1.0
    for name in ("personal_space_compliance", "personal_space_compliance_code"):
        assert 0.0 <= out[name] <= 1.0
    # The paper's 0.5 m surface clearance (1.16 m centre) is laxer than the code's 2.02 m centre.
    assert out["personal_space_compliance"] >= out["personal_space_compliance_code"]


def test_group_crossings_count_the_steps_through_a_group_and_not_around_it():
    # Two members of group 0 at (0, ±0.5) (1 m apart), a lone human at (0, 3) and (0, 2.5).
    humans = np.array([[[0.0, 0.5], [0.0, -0.5], [0.0, 3.0]]] * 3)
    through = np.array([[-1.0, 0.0], [1.0, 0.0], [2.0, 0.0]])  # between the members
    around = np.array([[-1.0, 1.5], [1.0, 1.5], [2.0, 1.5]])  # between a member and the loner

    def trajectory(robot, groups):
        return m.Trajectory(
            robot_xy=robot, human_xy=humans, goal_xy=np.array([5.0, 0.0]), dmin=np.ones(2),
            rewards=np.zeros(2), success=False, collision=None, truncated=True,
            human_group=groups,
        )  # fmt: skip

    assert m.group_crossings(trajectory(through, np.array([0, 0, -1]))) == 1.0
    assert m.group_crossings(trajectory(around, np.array([0, 0, -1]))) == 0.0
    assert m.group_crossings(trajectory(through, np.array([-1, -1, -1]))) == 0.0
    assert m.group_crossings(trajectory(through, None)) == 0.0
    with pytest.raises(ValueError, match="human_group must have shape"):
        trajectory(through, np.array([0, 0]))
