"""The scenario presets of configs/scenarios/, each on the simulator and its gymnasium env.

For every preset (a new file there is covered by the glob):

- 1,000 episodes (scenarios 0..999) start clear: nothing inside an obstacle or touching a wall,
  no two humans overlapping;
- the same episodes, run for 60 steps of random actions, keep every human out of the obstacles
  and inside the walls, never faster than its max speed, and standing-group members still;
- gymnasium's env checker passes on the single env, with either action type;
- scenario i is the same whatever the batch size.

Then two checks outside the presets: a human whose path a standing robot blocks goes round it
when the humans see the robot and walks into it when they do not (ORCA and SFM), and scenarios
that cannot be built are refused, naming the parameter at fault.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from socnav_wm.config import load_params
from socnav_wm.env.core import Simulator
from socnav_wm.env.gym import SocNavEnv
from socnav_wm.env.obstacles import nearest_points
from socnav_wm.env.params import EnvParams
from socnav_wm.env.state import COLLISION_HUMAN, OBSTACLE_NONE, BatchState

ROOT = Path(__file__).resolve().parents[2]
PRESETS = sorted((ROOT / "configs" / "scenarios").glob("*.yaml"))
EPISODES = 1000
STEPS = 60
TOLERANCE = 1e-9


@pytest.fixture(params=PRESETS, ids=lambda path: path.stem)
def params(request: pytest.FixtureRequest) -> EnvParams:
    """The env section of params.yaml with one preset laid over it."""
    return load_params(ROOT / "params.yaml", overlays=[request.param]).env


def start(params: EnvParams, num_envs: int = EPISODES, seed: int = 0) -> Simulator:
    """A simulator running scenarios 0..num_envs−1 of ``seed``."""
    sim = Simulator(num_envs, params)
    sim.reset(seed=seed, scenario_ids=np.arange(num_envs))
    return sim


def obstacle_distance(points: np.ndarray, state: BatchState) -> np.ndarray:
    """(N, K) signed distance from each of ``points`` (N, K, 2) to the nearest obstacle of its
    env (negative inside one, +inf where there is none)."""
    n, k = points.shape[:2]
    if state.obstacle_kind.shape[1] == 0:
        return np.full((n, k), np.inf)
    obstacles = (state.obstacle_kind, state.obstacle_xy, state.obstacle_half)
    per_point = [np.repeat(a, k, axis=0) for a in obstacles]
    _, distance = nearest_points(points.reshape(-1, 2), *per_point)
    return distance.min(axis=1).reshape(n, k)


def wall_gap(points: np.ndarray, radius: float, params: EnvParams) -> np.ndarray:
    """(N, K) gap between discs of ``radius`` at ``points`` (N, K, 2) and the nearest wall."""
    return params.wall_half_size - np.abs(points).max(axis=-1) - radius


def human_gaps(human_xy: np.ndarray) -> np.ndarray:
    """(N, H) centre distance from each human to the nearest other one of its env."""
    distance = np.linalg.norm(human_xy[:, :, None] - human_xy[:, None], axis=-1)
    distance[:, np.arange(human_xy.shape[1]), np.arange(human_xy.shape[1])] = np.inf
    return distance.min(axis=-1)


def standing_members(state: BatchState) -> np.ndarray:
    """(N, H) bool: the humans of a standing conversation group."""
    if state.group_standing.shape[1] == 0:
        return np.zeros(state.human_group.shape, dtype=bool)
    standing = np.take_along_axis(state.group_standing, np.maximum(state.human_group, 0), axis=1)
    return standing & (state.human_group >= 0)


def assert_everywhere(ok: np.ndarray, what: str) -> None:
    """Assert every entry of ``ok``, naming the first index where it fails."""
    bad = np.argwhere(~ok)
    assert bad.size == 0, f"{what}: {len(bad)} cases, the first at index {tuple(bad[0])}"


def test_scenarios_start_clear_of_walls_obstacles_and_each_other(params: EnvParams) -> None:
    s = start(params).state
    low = params.tables[0] + params.plants[0]
    high = params.tables[1] + params.plants[1]
    count = (s.obstacle_kind != OBSTACLE_NONE).sum(axis=1)
    assert_everywhere((low <= count) & (count <= high), f"obstacle count outside [{low}, {high}]")
    discs = {
        "robot": (s.robot_xy[:, None], params.robot_radius),
        "robot goal": (s.goal_xy[:, None], params.goal_radius),
        "human": (s.human_xy, params.human_radius),
        "human goal": (s.human_goal, params.human_goal_radius),
    }
    for name, (centres, radius) in discs.items():
        assert_everywhere(wall_gap(centres, radius, params) > 0, f"{name} touches a wall")
        assert_everywhere(obstacle_distance(centres, s) > radius, f"{name} in an obstacle")
    if params.num_humans > 1:
        assert_everywhere(human_gaps(s.human_xy) >= 2 * params.human_radius, "humans overlap")


def test_random_episodes_keep_humans_in_bounds_and_within_speed(params: EnvParams) -> None:
    sim = start(params)
    s = sim.state
    standing = standing_members(s)
    if params.standing_groups[0]:
        assert standing.any(axis=1).all(), "a scenario without its standing group"
    rng = np.random.default_rng(0)
    for step in range(STEPS):
        running = ~s.done
        before = s.human_xy.copy()
        sim.step(rng.integers(0, 4, EPISODES))
        clearance = obstacle_distance(s.human_xy, s)[running]
        assert_everywhere(
            clearance >= params.human_radius - TOLERANCE, f"step {step}: a human in an obstacle"
        )
        walls = wall_gap(s.human_xy, params.human_radius, params)[running]
        assert_everywhere(walls >= -TOLERANCE, f"step {step}: a human beyond the walls")
        moved = np.linalg.norm(s.human_xy - before, axis=-1)[running]
        fastest = s.human_max_speed[running] * params.dt + TOLERANCE
        assert_everywhere(moved <= fastest, f"step {step}: a human faster than its max speed")
        assert_everywhere(moved[standing[running]] == 0, f"step {step}: a standing human moved")


@pytest.mark.parametrize("action_type", ["discrete", "continuous"])
def test_gym_env_passes_gymnasiums_checker(params: EnvParams, action_type: str) -> None:
    check_env(SocNavEnv(action_type=action_type, **params.model_dump()), skip_render_check=True)


def test_scenario_does_not_depend_on_the_batch_size(params: EnvParams) -> None:
    small, large = start(params, 4, seed=7), start(params, 8, seed=7)
    np.testing.assert_array_equal(small.observation, large.observation[:4])
    rng = np.random.default_rng(1)
    for _ in range(30):
        actions = rng.integers(0, 4, 8)
        a, b = small.step(actions[:4]), large.step(actions)
        np.testing.assert_array_equal(a.obs, b.obs[:4])
        np.testing.assert_array_equal(a.reward, b.reward[:4])
        np.testing.assert_array_equal(small.state.human_xy, large.state.human_xy[:4])


# ------------------------------------------------------------------ a human meets the robot
PASSED_X = 0.5
BLOCKED_STEPS = 100  # SFM humans walk at ~0.08 m/s: about 45 steps to pass the robot


def walk_at_standing_robot(policy: str, sees: bool) -> tuple[int, np.ndarray, int]:
    """One human walking from (−3, 0) to (3, 0) through a robot stopped at the origin: the step
    the human got past the robot (x > 0.5) or the episode ended, the human's position then,
    and the collision code of that step."""
    sim = start(EnvParams(num_humans=1, human_policy=policy, humans_see_robot=sees), 1)
    s = sim.state
    assert s.human_sees_robot[0, 0] == sees
    s.robot_xy[0] = s.start_xy[0] = (0.0, 0.0)
    s.goal_xy[0] = (4.0, 4.0)
    s.human_xy[0, 0] = (-3.0, 0.0)
    s.human_goal[0, 0] = (3.0, 0.0)
    s.human_heading[0, 0] = (1.0, 0.0)
    s.human_speed[0, 0] = s.human_max_speed[0, 0]
    stop = np.zeros(1, dtype=np.int64)
    for _ in range(BLOCKED_STEPS):
        collision = int(sim.step(stop).info["collision"][0])
        if s.done[0] or s.human_xy[0, 0, 0] > PASSED_X:
            break
    return int(s.step_count[0]), s.human_xy[0, 0].copy(), collision


@pytest.mark.parametrize("policy", ["orca", "sfm"])
def test_a_human_who_sees_the_robot_goes_round_it(policy: str) -> None:
    step, human, collision = walk_at_standing_robot(policy, sees=True)
    assert collision != COLLISION_HUMAN, f"walked into the robot at step {step}, at {human}"
    assert human[0] > PASSED_X, f"still behind the robot after {step} steps, at {human}"


@pytest.mark.parametrize("policy", ["orca", "sfm"])
def test_a_human_who_does_not_see_the_robot_walks_into_it(policy: str) -> None:
    step, human, collision = walk_at_standing_robot(policy, sees=False)
    assert collision == COLLISION_HUMAN, f"no contact after {step} steps, at {human}"


# ------------------------------------------------------------------ impossible scenarios
def test_thirty_humans_fit_the_room_without_obstacles() -> None:
    # So that the room below is too full for its eight obstacles, not for its humans.
    assert EnvParams(num_humans=30).num_humans == 30


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"num_humans": 30, "tables": (4, 4), "plants": (4, 4)}, "num_humans: 30 humans .* cannot"),
        ({"observed_obstacles": 2}, "observed_obstacles: the scenario has no tables or plants"),
        ({"num_humans": 4, "groups": (2, 2), "group_size": (3, 3)}, "groups.*need 6 humans"),
    ],
    ids=["room-too-full", "no-obstacles-to-observe", "groups-too-large"],
)
def test_impossible_scenarios_are_refused(options: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        EnvParams(**options)
