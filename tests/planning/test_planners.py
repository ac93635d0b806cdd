"""The planners beyond cv-mpc: oracle-mpc (the simulator cloned), wm-mpc and vae-lstm-mpc."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import torch

from socnav_wm.config import ConfigError, load_params
from socnav_wm.env.core import Simulator
from socnav_wm.env.observation import observe
from socnav_wm.env.params import EnvParams
from socnav_wm.env.state import COLLISION_NONE
from socnav_wm.evaluation.evaluate import evaluate_method
from socnav_wm.evaluation.records import BASELINE_SEED
from socnav_wm.methods import method as lookup
from socnav_wm.planning.models import ConstantVelocityModel
from socnav_wm.planning.mpc import Planner, step_gain
from socnav_wm.planning.oracle import OraclePlanner, clone_simulator
from socnav_wm.planning.params import PlanningParams
from socnav_wm.planning.vae_lstm import VaeLstmModel
from socnav_wm.worldmodel.files import save_lstm, save_vae
from socnav_wm.worldmodel.lstm import LatentLSTM
from socnav_wm.worldmodel.planning_file import ResidualTrainResult, save_residual
from socnav_wm.worldmodel.prediction import model_positions, random_policy, record
from socnav_wm.worldmodel.residual import ResidualDynamics
from socnav_wm.worldmodel.vae import VAE

ENV = EnvParams()


def states_equal(a: Simulator, b: Simulator) -> bool:
    return all(np.array_equal(getattr(a.state, k), getattr(b.state, k)) for k in vars(a.state))


def test_a_clone_steps_exactly_like_the_original() -> None:
    sim = Simulator(6, ENV)
    sim.reset(seed=11)
    rng = np.random.default_rng(0)
    for _ in range(5):
        sim.step(rng.integers(0, 4, 6))
    clone = clone_simulator(sim)
    assert states_equal(sim, clone)
    for _ in range(40):
        actions = rng.integers(0, 4, 6)
        ours, theirs = sim.step(actions), clone.step(actions)
        np.testing.assert_array_equal(ours.obs, theirs.obs)
        np.testing.assert_array_equal(ours.reward, theirs.reward)
    assert states_equal(sim, clone)


def test_clones_repeat_each_episode_in_a_row_and_can_pick_slots() -> None:
    sim = Simulator(3, ENV)
    sim.reset(seed=2)
    clone = clone_simulator(sim, repeats=4, envs=np.array([2, 0]))
    assert clone.num_envs == 8
    assert clone.state.scenario_id.tolist() == [2] * 4 + [0] * 4
    np.testing.assert_array_equal(clone.state.human_xy[4], sim.state.human_xy[0])
    with pytest.raises(ValueError, match="repeats"):
        clone_simulator(sim, repeats=0)


def test_the_oracle_draws_its_own_random_numbers() -> None:
    # SFM humans notice the robot at random, and a human at its goal draws a new one: under
    # another seed a clone's future differs from the episode's, under the same seed it does not.
    env = ENV.replace(human_policy="sfm")
    sim = Simulator(20, env)
    sim.reset(seed=5)
    same, other = clone_simulator(sim), clone_simulator(sim, seed=123)
    for _ in range(60):
        actions = np.zeros(20, dtype=np.int64)
        for s in (sim, same, other):
            s.step(actions)
    assert states_equal(sim, same)
    assert not np.array_equal(sim.state.human_xy, other.state.human_xy)


def test_a_blind_oracle_plans_as_if_the_humans_did_not_see_the_robot() -> None:
    env = ENV.replace(num_humans=6, humans_see_robot=True)
    sim = Simulator(8, env)
    sim.reset(seed=3)
    for _ in range(6):
        sim.step(np.ones(8, dtype=np.int64))
    blind_sim = clone_simulator(sim)
    blind_sim.state.human_sees_robot[:] = False
    envs = np.arange(8)
    default = OraclePlanner(PlanningParams(), env)
    blind = OraclePlanner(PlanningParams(oracle_reactions=False), env)
    np.testing.assert_array_equal(blind.scores(sim, envs), default.scores(blind_sim, envs))
    assert not np.array_equal(blind.scores(sim, envs), default.scores(sim, envs))
    assert sim.state.human_sees_robot.all()  # the episode's humans still see it


def one_human_ahead(env: EnvParams) -> Simulator:
    """A room with the robot at (−1.2, 0) facing its goal at (1.2, 0), a human standing at the
    origin on the straight path, and the two others standing in far corners."""
    sim = Simulator(1, env)
    sim.reset(seed=0)
    s = sim.state
    s.robot_xy[0], s.start_xy[0], s.robot_theta[0] = (-1.2, 0.0), (-1.2, 0.0), 0.0
    s.goal_xy[0] = (1.2, 0.0)
    s.human_xy[0] = [(0.0, 0.0), (3.5, 3.5), (-3.5, -3.5)][: env.num_humans]
    s.human_goal[0] = s.human_xy[0]
    s.human_speed[0] = 0.0
    return sim


def observation(sim: Simulator) -> np.ndarray:
    s = sim.state
    out = np.zeros((sim.num_envs, sim.obs_dim), dtype=np.float32)
    observe(
        s.robot_xy, s.robot_theta, s.robot_v, s.robot_omega, s.robot_vy, s.goal_xy, s.human_xy,
        s.human_heading, s.human_speed, sim.params.human_radius, sim.params.num_humans,
        s.obstacle_kind, s.obstacle_xy, s.obstacle_half, 0, np.arange(sim.num_envs), out,
    )  # fmt: skip
    return out


@pytest.mark.parametrize("method", ["oracle-mpc", "cv-mpc"])
def test_both_planners_go_around_a_human_on_the_straight_path(method: str) -> None:
    env = ENV.replace(human_policy="orca", human_max_speed=1e-6)  # the humans stand
    sim = one_human_ahead(env)
    policy, reads_simulator = lookup(method).policies(env, planning=PlanningParams())()
    obs = observation(sim)
    nearest, sideways = np.inf, 0.0
    while not sim.state.done[0]:
        result = sim.step(policy(sim if reads_simulator else obs))
        obs = result.obs
        nearest = min(nearest, float(np.hypot(*sim.state.robot_xy[0])))
        sideways = max(sideways, abs(float(sim.state.robot_xy[0, 1])))
    assert result.info["success"][0]
    assert nearest > env.robot_radius + env.human_radius
    assert sideways > 0.3  # it left the straight line


def brute_force_best(sim: Simulator, params: PlanningParams, env: EnvParams) -> int:
    """The first action of the best of every action sequence of ``params.horizon`` steps,
    each scored on its own clone (under the oracle's seed), the first best in table order."""
    best, best_score = -1, -np.inf
    for sequence in itertools.product(range(4), repeat=params.horizon):
        clone = clone_simulator(sim, seed=params.oracle_seed)
        score, distance = 0.0, float(np.hypot(*(clone.state.goal_xy - clone.state.robot_xy)[0]))
        for k, action in enumerate(sequence):
            result = clone.step(np.array([action]))
            new = float(np.hypot(*(clone.state.goal_xy - clone.state.robot_xy)[0]))
            centre = np.hypot(*(clone.state.human_xy[0] - clone.state.robot_xy[0]).T).min()
            collided = result.info["collision"][0] != COLLISION_NONE
            reached = bool(result.info["success"][0])
            gain = step_gain(
                params, env, np.array([distance - new]), np.array([centre]),
                np.array([collided]), np.array([reached]),
            )[0]  # fmt: skip
            score += params.discount**k * gain
            distance = new
            if clone.state.done[0]:
                break
        if score > best_score:
            best, best_score = sequence[0], score
    return best


@pytest.mark.parametrize("scenario", [0, 1, 2, 3])
def test_the_oracle_chooses_what_a_brute_force_search_chooses(scenario: int) -> None:
    params = PlanningParams(horizon=3, prefix_length=3, discomfort_cost=0.5)
    sim = Simulator(1, ENV)
    sim.reset(seed=9, scenario_ids=np.array([scenario]))
    for _ in range(3):
        sim.step(np.array([1]))
    chosen = OraclePlanner(params, ENV).act(sim)[0]
    assert chosen == brute_force_best(sim, params, ENV)


def test_the_oracle_counts_a_wall_contact_as_a_collision() -> None:
    env = ENV.replace(human_policy="orca", human_max_speed=1e-6)
    sim = one_human_ahead(env)
    half = env.wall_half_size - env.robot_radius
    sim.state.robot_xy[0] = (half - 0.1, 0.0)  # facing the wall, 0.1 m from touching it
    sim.state.goal_xy[0] = (half - 0.1, -2.0)
    params = PlanningParams(horizon=1, prefix_length=1, progress_weight=0.0, discomfort_cost=0.0)
    scores = OraclePlanner(params, env).scores(sim, np.array([0])).reshape(4, -1)[:, 0]
    assert scores[1] == -params.collision_cost  # forward hits the wall
    assert np.all(scores[[0, 2, 3]] == 0.0)


def test_oracle_evaluation_is_one_run_with_its_seed_recorded() -> None:
    params = PlanningParams(horizon=3, prefix_length=1)
    result = evaluate_method(
        "oracle-mpc", env_params=ENV, scenario_seed=3, episodes=2, planning=params
    )
    assert result.training_seeds == (BASELINE_SEED,)
    assert result.settings["planning"]["oracle_seed"] == params.oracle_seed
    assert result.settings["model_files"] == {}


def tiny_world_model(tmp_path) -> tuple[VAE, LatentLSTM]:
    torch.manual_seed(0)
    vae, lstm = VAE(23, 16, 4), LatentLSTM(4, 4, 8)
    rng = np.random.default_rng(0)
    vae.fit_normalization(rng.normal(size=(64, 23)))
    save_vae(tmp_path / "vae.pt", vae)
    save_lstm(tmp_path / "lstm.pt", lstm)
    return vae, lstm


def test_the_vae_lstm_model_imagines_what_the_predict_stage_measures(tmp_path) -> None:
    vae, lstm = tiny_world_model(tmp_path)
    recording = record(ENV, random_policy(1), 4, np.arange(5), 8)
    _, expected = model_positions(vae, lstm, recording, start=3, horizon=4, batch_size=512)
    model = VaeLstmModel(vae, lstm)
    model.reset(recording.obs[0])
    for t in range(3):
        model.observe(recording.obs[t + 1], recording.actions[t])
    rollout = model.rollout(2)  # two copies of each episode, episode-major
    for k in range(4):
        predicted = rollout.step(np.repeat(recording.actions[3 + k], 2))
        np.testing.assert_allclose(predicted[::2], expected[:, k], atol=1e-4)
        np.testing.assert_array_equal(predicted[::2], predicted[1::2])


def test_learned_planners_evaluate_from_their_files(tmp_path) -> None:
    tiny_world_model(tmp_path)
    net = ResidualDynamics(ENV.num_humans, 8, ENV.dt)
    save_residual(tmp_path / "planning.pt", ResidualTrainResult(net, [], {}), {})
    params = PlanningParams(horizon=2, prefix_length=1)
    files = {"vae": tmp_path / "vae.pt", "lstm": tmp_path / "lstm.pt"}
    result = evaluate_method(
        "vae-lstm-mpc", env_params=ENV, scenario_seed=3, episodes=2, planning=params,
        planner_files=files,
    )  # fmt: skip
    assert result.episodes.num_rows == 2
    assert result.settings["model_files"]["vae"] == str(tmp_path / "vae.pt")
    # wm-mpc with an untrained correction (zero at initialisation) is cv-mpc
    wm = evaluate_method(
        "wm-mpc", env_params=ENV, scenario_seed=3, episodes=3, planning=params,
        planner_files={"planning_model": tmp_path / "planning.pt"},
    )  # fmt: skip
    cv = evaluate_method("cv-mpc", env_params=ENV, scenario_seed=3, episodes=3, planning=params)
    assert wm.episodes["success"].to_pylist() == cv.episodes["success"].to_pylist()


def test_a_missing_or_misplaced_model_file_is_one_line(tmp_path) -> None:
    with pytest.raises(FileNotFoundError, match="train-planning-model"):
        lookup("wm-mpc").files({"planning_model": tmp_path / "nope.pt"})
    with pytest.raises(ValueError, match="reads no vae file"):
        lookup("cv-mpc").files({"vae": tmp_path / "vae.pt"})
    with pytest.raises(ValueError, match="not a planner"):
        evaluate_method(
            "orca", env_params=ENV, scenario_seed=3, episodes=1,
            planner_files={"vae": tmp_path / "vae.pt"},
        )  # fmt: skip


@pytest.mark.parametrize(
    ("override", "key"),
    [("planning.oracle_seed=-1", "planning.oracle_seed"),
     ("planning.oracle_clairvoyant=maybe", "planning.oracle_clairvoyant")],
)  # fmt: skip
def test_bad_oracle_values_name_their_key(tmp_path, override: str, key: str) -> None:
    path = tmp_path / "params.yaml"
    path.write_text("seed: 0\n")
    with pytest.raises(ConfigError, match=key):
        load_params(path, [override])


def test_the_constant_velocity_planner_is_unchanged_by_the_shared_cost() -> None:
    # Planner.scores and the oracle share step_gain: a candidate's score on a free path is the
    # discounted progress alone.
    obs = np.zeros((1, 23))
    obs[0, :2] = (3.0, 0.0)
    obs[0, 2::7], obs[0, 3::7], obs[0, 6::7] = 8.0, 8.0, ENV.human_radius
    params = PlanningParams(horizon=2, prefix_length=2, continuations=("stop",))
    planner = Planner(ConstantVelocityModel(ENV), params, ENV)
    planner.model.reset(obs)
    scores = planner.scores(obs[:, :2]).reshape(16)
    step = ENV.robot_max_speed * ENV.dt
    assert scores[5] == pytest.approx(step + params.discount * step)  # forward, forward


def test_bench_plan_reports_decisions_per_cpu_second(tmp_path) -> None:
    from socnav_wm.bench import bench_plan

    tiny_world_model(tmp_path)
    files = {"vae-lstm-mpc": {"vae": tmp_path / "vae.pt", "lstm": tmp_path / "lstm.pt"}}
    rows = bench_plan(
        ("oracle-mpc", "vae-lstm-mpc"), (1, 3), env_params=ENV,
        planning=PlanningParams(
            horizon=2, prefix_length=1, per_method={"vae-lstm-mpc": {"horizon": 3}}
        ),
        files=files, seconds=0.05,
    )  # fmt: skip
    # Each row says what its planner imagined: its per_method overrides applied.
    assert [(r["planner"], r["envs"], r["futures"], r["horizon"]) for r in rows] == [
        ("oracle-mpc", 1, 12, 2), ("oracle-mpc", 3, 12, 2),
        ("vae-lstm-mpc", 1, 12, 3), ("vae-lstm-mpc", 3, 12, 3),
    ]  # fmt: skip
    for row in rows:
        assert row["decisions_per_cpu_s"] > 0
        assert row["cpu_ms_per_decision"] == pytest.approx(1000 / row["decisions_per_cpu_s"])


def test_evaluate_refuses_model_files_for_a_method_without_them(tmp_path) -> None:
    from typer.testing import CliRunner

    from socnav_wm.cli import app

    (tmp_path / "params.yaml").write_text("seed: 0\n")
    result = CliRunner().invoke(
        app, ["evaluate", "--method", "orca", "--vae", str(tmp_path / "vae.pt"), "--no-tracking",
              "--params", str(tmp_path / "params.yaml"), "--out-dir", str(tmp_path)],
    )  # fmt: skip
    assert result.exit_code != 0
    assert "--vae: only for a planner" in result.output
