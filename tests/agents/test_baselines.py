"""The ORCA and Social Force robots: unicycle conversion, empty room, a person in the way."""

from __future__ import annotations

import math
from dataclasses import fields

import numpy as np
import pytest

from socnav_wm.agents.baselines import (
    BASELINES,
    OrcaBaselineParams,
    SfmBaselineParams,
    make_baseline,
    unicycle_command,
)
from socnav_wm.env import EnvParams, Simulator
from socnav_wm.env.state import BatchState

V_MAX = 0.14
W_MAX = 0.387596899
NAMES = sorted(BASELINES)


def command(vx: float, vy: float, theta: float = 0.0, **kwargs) -> tuple[float, float]:
    """(v, ω) for one desired velocity, with the paper robot's limits unless overridden."""
    options = {"max_speed": V_MAX, "max_rotation": W_MAX, "dt": 1.0} | kwargs
    out = unicycle_command(np.array([[vx, vy]]), np.array([theta]), **options)
    assert out.shape == (1, 2)
    return float(out[0, 0]), float(out[0, 1])


# ------------------------------------------------------------------ unicycle conversion


def test_straight_ahead_goes_at_the_desired_speed_without_turning():
    assert command(0.1, 0.0) == pytest.approx((0.1, 0.0))
    # Faster than the robot can go: clipped to its speed.
    assert command(0.5, 0.0) == pytest.approx((V_MAX, 0.0))
    # Same in another heading: 0.1 m/s along θ = 2 rad.
    assert command(0.1 * math.cos(2.0), 0.1 * math.sin(2.0), theta=2.0) == pytest.approx(
        (0.1, 0.0), abs=1e-12
    )


def test_a_velocity_at_90_degrees_turns_in_place_at_full_rate():
    v, omega = command(0.0, 0.1)  # to the left of a robot facing +x
    assert v == pytest.approx(0.0, abs=1e-12)
    assert omega == pytest.approx(W_MAX)
    v, omega = command(0.0, -0.1)  # to the right
    assert v == pytest.approx(0.0, abs=1e-12)
    assert omega == pytest.approx(-W_MAX)


def test_a_velocity_behind_never_reverses():
    v, omega = command(-0.1, 0.0)
    assert v == 0.0
    assert abs(omega) == pytest.approx(W_MAX)


def test_a_small_heading_error_is_corrected_in_one_step_and_slows_by_its_cosine():
    # 0.2 rad to the left, within one step's turn (0.3876 rad): ω = 0.2, v = 0.1·cos 0.2.
    v, omega = command(0.1 * math.cos(0.2), 0.1 * math.sin(0.2))
    assert omega == pytest.approx(0.2)
    assert v == pytest.approx(0.1 * math.cos(0.2))
    # Gain and step scale the turn: ω = 0.5 · 0.2 / 2 s.
    _, omega = command(0.1 * math.cos(0.2), 0.1 * math.sin(0.2), heading_gain=0.5, dt=2.0)
    assert omega == pytest.approx(0.05)


def test_the_heading_error_takes_the_short_way_across_pi():
    # θ = 3.0, desired direction −3.0: the error is 2π − 6 ≈ +0.283 rad, not −6 rad.
    v, omega = command(0.1 * math.cos(-3.0), 0.1 * math.sin(-3.0), theta=3.0)
    assert omega == pytest.approx(2 * math.pi - 6.0)
    assert v == pytest.approx(0.1 * math.cos(2 * math.pi - 6.0))


def test_no_desired_velocity_means_no_motion():
    assert command(0.0, 0.0, theta=1.0) == (0.0, 0.0)


def test_unicycle_command_is_batched():
    desired = np.array([[0.1, 0.0], [0.0, 0.1], [0.0, 0.0]])
    theta = np.array([0.0, 0.0, 0.5])
    out = unicycle_command(desired, theta, max_speed=V_MAX, max_rotation=W_MAX, dt=1.0)
    np.testing.assert_allclose(out, [[0.1, 0.0], [0.0, W_MAX], [0.0, 0.0]], atol=1e-12)


# ------------------------------------------------------------------ helpers


def run_to_end(sim: Simulator, policy) -> dict[str, np.ndarray]:
    """Step every env to its end; outcomes per env and the closest robot-human centre distance."""
    n = sim.num_envs
    success = np.zeros(n, dtype=bool)
    collision = np.zeros(n, dtype=np.int8)
    closest = np.full(n, np.inf)
    while not sim.state.done.all():
        result = sim.step(policy.act(sim.state, sim.params))
        active = result.info["active"]
        success |= result.info["success"] & active
        collision = np.where(active, np.maximum(collision, result.info["collision"]), collision)
        if sim.state.num_humans:
            gap = np.linalg.norm(sim.state.robot_xy[:, None] - sim.state.human_xy, axis=-1)
            closest = np.where(active, np.minimum(closest, gap.min(axis=1)), closest)
    return {
        "success": success,
        "collision": collision,
        "steps": sim.state.step_count.copy(),
        "closest": closest,
    }


def place(sim: Simulator, env: int, robot, theta, goal, humans=()) -> None:
    """Robot, goal and (standing) humans of slot ``env`` where the test wants them."""
    s = sim.state
    s.robot_xy[env] = robot
    s.start_xy[env] = robot
    s.robot_theta[env] = theta
    s.goal_xy[env] = goal
    if humans:
        s.human_xy[env] = np.asarray(humans, dtype=float)
        s.human_speed[env] = 0.0
        # Goals away from the humans, so none reaches its goal and draws a new one.
        s.human_goal[env] = np.where(np.abs(s.human_xy[env]) > 0.1, -s.human_xy[env], 4.0)


# ------------------------------------------------------------------ behaviour in the simulator

EMPTY_ROOM_STARTS = [
    # robot, heading, goal: facing the goal, facing away, sideways, along a wall, corner to corner
    ((-4.0, -4.0), math.pi / 4, (4.0, 4.0)),
    ((-4.0, -4.0), -3 * math.pi / 4, (4.0, 4.0)),
    ((4.0, -4.0), 0.0, (-4.0, 4.0)),
    ((-4.4, 4.4), -math.pi / 2, (4.4, 4.4)),
    ((0.0, 0.0), math.pi, (0.0, 4.5)),
    ((3.0, 1.0), 2.0, (1.0, 1.5)),
]


@pytest.mark.parametrize("name", NAMES)
def test_both_reach_the_goal_in_an_empty_room(name):
    params = EnvParams(num_humans=0)
    sim = Simulator(len(EMPTY_ROOM_STARTS) + 24, params)
    sim.reset(seed=5)  # the last 24 slots keep the simulator's own random starts
    for env, (robot, theta, goal) in enumerate(EMPTY_ROOM_STARTS):
        place(sim, env, robot, theta, goal)
    outcome = run_to_end(sim, make_baseline(name))
    assert outcome["success"].all(), outcome["steps"]
    assert (outcome["collision"] == 0).all()
    # The longest trip (≈ 11.3 m at 0.14 m/s ≈ 81 steps, plus turning) fits well in 201 steps.
    assert outcome["steps"].max() < 130


FROZEN = {"human_max_speed": 0.01, "human_policy": "orca"}  # < 0.05 m/s: humans stand still

BLOCKED_LINES = [
    # robot, heading, goal, the person standing on the straight line between them
    ((-3.0, 0.0), 0.0, (3.0, 0.0), (0.0, 0.0)),  # exactly symmetric, head-on
    ((0.0, -3.0), math.pi / 2, (0.0, 3.0), (0.0, 0.5)),
    ((-3.0, -3.0), math.pi / 4, (3.0, 3.0), (0.0, 0.0)),  # diagonal
    ((3.5, 0.0), math.pi, (-3.5, 0.0), (1.0, 0.0)),  # the person close to the start
    ((0.0, 0.0), 0.3, (4.5, 0.0), (2.2, 0.0)),  # the goal near a wall, facing off the line
]


@pytest.mark.parametrize("name", NAMES)
def test_both_go_around_a_person_standing_on_the_straight_line(name):
    params = EnvParams(**FROZEN)
    sim = Simulator(len(BLOCKED_LINES), params)
    sim.reset(seed=0)
    far = [(-4.0, 4.0), (4.0, -4.0)]  # the other two people, out of the way
    for env, (robot, theta, goal, person) in enumerate(BLOCKED_LINES):
        place(sim, env, robot, theta, goal, humans=[person, *far])
    start_humans = sim.state.human_xy.copy()
    outcome = run_to_end(sim, make_baseline(name))
    np.testing.assert_array_equal(sim.state.human_xy, start_humans)  # nobody moved
    assert outcome["success"].all(), outcome["steps"]
    assert (outcome["collision"] == 0).all()
    # Never touched (contact at 0.3 + 0.36 m between centres), with room to spare.
    assert outcome["closest"].min() > params.robot_radius + params.human_radius + 0.05
    assert outcome["steps"].max() < 150


def slice_state(state: BatchState, env: int) -> BatchState:
    return BatchState(**{f.name: getattr(state, f.name)[env : env + 1] for f in fields(state)})


@pytest.mark.parametrize("name", NAMES)
def test_batched_commands_equal_per_env_commands(name):
    params = EnvParams()
    sim = Simulator(12, params)
    sim.reset(seed=2)
    policy = make_baseline(name)
    for _ in range(15):  # mid-episode: robots and humans moving, some near each other
        sim.step(policy.act(sim.state, params))
    before = sim.state.copy()
    batched = policy.act(sim.state, params)
    assert batched.shape == (12, 2)
    assert batched.dtype == np.float64
    for env in range(12):
        single = policy.act(slice_state(sim.state, env), params)
        np.testing.assert_allclose(single[0], batched[env], rtol=1e-12, atol=1e-15)
    # Stateless and read-only: the same state gives the same commands, and is left untouched.
    np.testing.assert_array_equal(policy.act(sim.state, params), batched)
    for f in fields(before):
        np.testing.assert_array_equal(getattr(sim.state, f.name), getattr(before, f.name))


@pytest.mark.parametrize("name", NAMES)
def test_commands_stay_within_the_robot_limits_in_crowded_scenarios(name):
    params = EnvParams()
    sim = Simulator(32, params)
    sim.reset(seed=9)
    policy = make_baseline(name)
    while not sim.state.done.all():
        commands = policy.act(sim.state, params)
        assert np.all(np.isfinite(commands))
        assert np.all((commands[:, 0] >= 0.0) & (commands[:, 0] <= params.robot_max_speed))
        assert np.all(np.abs(commands[:, 1]) <= params.robot_max_rotation + 1e-12)
        sim.step(commands)


# ------------------------------------------------------------------ registry and parameters


def test_registry_builds_each_baseline_with_overrides():
    assert set(BASELINES) == {"orca", "sfm"}
    orca = make_baseline("orca", safety_margin=0.05, time_horizon=3.0)
    assert orca.name == "orca"
    assert orca.config == OrcaBaselineParams(safety_margin=0.05, time_horizon=3.0)
    sfm = make_baseline("sfm")
    assert sfm.name == "sfm"
    assert sfm.config == SfmBaselineParams()


def test_unknown_baseline_or_option_is_a_one_line_error():
    with pytest.raises(ValueError, match="unknown baseline 'rvo'; expected one of orca, sfm"):
        make_baseline("rvo")
    with pytest.raises(ValueError, match=r"baselines\.sfm: unknown option\(s\) tau"):
        make_baseline("sfm", tau=0.5)


@pytest.mark.parametrize(
    ("name", "option", "value", "message"),
    [
        ("orca", "time_horizon", 0.0, "must be > 0"),
        ("orca", "safety_margin", -0.1, "must be >= 0"),
        ("orca", "max_neighbors", 2.5, "expected an integer"),
        ("orca", "symmetry_bias", 2.0, "within ±π/2"),
        ("sfm", "relaxation_time", -1.0, "must be > 0"),
        ("sfm", "anisotropy", 1.5, r"must be in \[0, 1\]"),
        ("sfm", "human_range", "far", "expected a number"),
        ("sfm", "wall_strength", math.nan, "must be finite"),
    ],
)
def test_bad_parameters_are_named(name, option, value, message):
    with pytest.raises(ValueError, match=rf"baselines\.{name}\.{option}: .*{message}"):
        make_baseline(name, **{option: value})
