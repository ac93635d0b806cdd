"""wm-mpc-q: the critic's imagined observations, the planner's policy continuation and value at
the horizon, and the method end to end from its files."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from socnav_wm.agents.agent_file import load_agent, save_agent
from socnav_wm.agents.params import AgentParams
from socnav_wm.agents.training import train_agent
from socnav_wm.env.core import Simulator
from socnav_wm.env.params import EnvParams
from socnav_wm.evaluation.evaluate import evaluate_method
from socnav_wm.planning.critic import AgentCritic, ImaginedObservations
from socnav_wm.planning.models import ConstantVelocityModel
from socnav_wm.planning.mpc import FORWARD, LEFT, RIGHT, STOP, Planner
from socnav_wm.planning.params import PlanningParams
from socnav_wm.worldmodel.ego import commands_of
from socnav_wm.worldmodel.planning_file import ResidualTrainResult, save_residual
from socnav_wm.worldmodel.residual import ResidualDynamics

ENV = EnvParams()
FAR = [(8.0, 8.0), (-8.0, 8.0), (-8.0, -8.0)]


def observation(goal, humans, headings=None) -> np.ndarray:
    obs = np.zeros(2 + 7 * len(humans))
    obs[:2] = goal
    for i, xy in enumerate(humans):
        obs[2 + 7 * i : 4 + 7 * i] = xy
        obs[4 + 7 * i : 6 + 7 * i] = (0.0, 1.0) if headings is None else headings[i]
        obs[6 + 7 * i] = ENV.human_radius
    return obs[None]


def test_an_imagined_observation_is_the_simulators_for_humans_who_keep_their_velocity() -> None:
    # Three humans walking straight, far from each other and the robot, in an open room: the
    # constant-velocity future is the real one, so the imagined observation is the real one.
    env = EnvParams(room_size=40.0, human_policy="orca", human_speed_threshold=0.0)
    sim = Simulator(1, env)
    obs, _ = sim.reset(seed=0)
    s = sim.state
    s.robot_xy[:] = 0.0
    s.robot_theta[:] = 0.3
    s.goal_xy[0] = (10.0, 5.0)
    s.human_xy[0] = [(5.0, -6.0), (-6.0, 6.0), (7.0, 7.0)]
    s.human_goal[0] = [(5.0, 15.0), (14.0, 6.0), (7.0, -13.0)]
    previous = sim.step(np.array([STOP])).obs.copy()  # observed after the edit
    actions = [FORWARD, LEFT, FORWARD, RIGHT]
    now = sim.step(np.array([actions[0]])).obs
    model = ConstantVelocityModel(env)
    model.reset(previous)
    model.observe(now, np.array([actions[0]]))
    imagined = ImaginedObservations(now, 1, env)
    rollout = model.rollout(1)
    for action in actions[1:]:
        real = sim.step(np.array([action])).obs
        points = rollout.step(np.array([action]))
        seen = imagined.observe(points, rollout.velocities(), commands_of(np.array([action]), env))
        np.testing.assert_allclose(seen, real, atol=2e-4)


def test_a_standing_human_keeps_its_heading_turned_with_the_robot() -> None:
    obs = observation((3.0, 0.0), [(1.0, 2.0)], headings=[(1.0, 0.0)])  # sin 1: facing left
    imagined = ImaginedObservations(obs, 1, ENV)
    still = np.zeros((1, 2, 2))
    seen = imagined.observe(np.array([[[3.0, 0.0], [1.0, 2.0]]]), still, commands_of(
        np.array([LEFT]), ENV))  # fmt: skip
    turn = ENV.robot_max_rotation * ENV.dt
    np.testing.assert_allclose(seen[0, 4:6], [np.cos(turn), np.sin(turn)], atol=1e-6)
    assert seen[0, 8] == pytest.approx(-ENV.robot_max_rotation)  # −ω
    assert seen[0, 6] == pytest.approx(ENV.human_radius)


class FixedCritic:
    """A critic that always proposes ``action`` and values every observation at ``value``."""

    def __init__(self, action: int, value: float) -> None:
        self.action, self.value = action, value

    def imagine(self, obs, repeats):
        return ImaginedObservations(obs, repeats, ENV)

    def evaluate(self, obs):
        return np.full(len(obs), self.action), np.full(len(obs), self.value)


class RecordingModel(ConstantVelocityModel):
    """Constant velocity that records every step's actions of its rollouts."""

    steps: list[np.ndarray]

    def rollout(self, repeats, pose=None, rows=None):
        inner, steps = super().rollout(repeats, pose, rows), []
        self.steps = steps

        class Recorded:
            def step(self, actions):
                steps.append(np.array(actions))
                return inner.step(actions)

            def velocities(self):
                return inner.velocities()

        return Recorded()


def test_the_policy_continuation_follows_the_critic_and_its_value_is_added_at_the_horizon():
    params = PlanningParams(horizon=4, prefix_length=1, continuations=["goal", "policy"],
                            walls=False, value_weight=0.0)  # fmt: skip
    obs = observation((3.0, 0.0), FAR)
    model = RecordingModel(ENV)
    model.reset(obs)
    planner = Planner(model, params, ENV, FixedCritic(RIGHT, 0.5))
    base = planner.scores(obs[:, :2], obs=obs)
    policy_rows = np.arange(planner.num_candidates) % 2 == 1
    for k, actions in enumerate(model.steps):
        if k >= 1:  # after the prefix, every policy future takes the critic's action
            assert (actions[policy_rows] == RIGHT).all()
            assert (actions[~policy_rows] != RIGHT).any() or k > 1
    weighted = Planner(model, params.replace(value_weight=2.0), ENV, FixedCritic(RIGHT, 0.5))
    gain = weighted.scores(obs[:, :2], obs=obs) - base
    # Nothing ends within the horizon here (the humans are far, the goal 3 m away).
    np.testing.assert_allclose(gain, 2.0 * params.discount**4 * 0.5)


def test_a_policy_continuation_without_a_critic_is_refused() -> None:
    params = PlanningParams(continuations=["goal", "policy"])
    with pytest.raises(ValueError, match="'policy' needs a critic"):
        Planner(ConstantVelocityModel(ENV), params, ENV)


TINY_AGENT = AgentParams(
    episodes=12, num_envs=4, batch_size=16, buffer_size=500, learning_starts=32,
    trunk_sizes=(16,), stream_size=8, checkpoint_every=10, select_every=0, device="cpu",
)  # fmt: skip


@pytest.fixture(scope="module")
def critic_file(tmp_path_factory) -> str:
    path = tmp_path_factory.mktemp("critic") / "dueling-dqn" / "seed-0.pt"
    save_agent(path, train_agent("dueling-dqn", TINY_AGENT, ENV, None, None, seed=0))
    return path


def test_the_agent_critic_is_its_q_networks_argmax_and_max(critic_file) -> None:
    agent = load_agent(critic_file, "cpu", ENV)
    critic = AgentCritic(agent, ENV)
    obs = np.random.default_rng(0).uniform(-3, 3, size=(5, 23)).astype(np.float32)
    actions, values = critic.evaluate(obs)
    # The agent's own input: the observation as its variant gives it (humans nearest first).
    q = agent.q_network(agent.fresh_variant().reset(obs)).detach()
    assert actions.tolist() == q.argmax(dim=1).tolist()
    np.testing.assert_allclose(values, q.max(dim=1).values.numpy(), rtol=1e-6)
    with pytest.raises(ValueError, match="observations have 37"):
        AgentCritic(agent, ENV.replace(num_humans=5))
    with pytest.raises(ValueError, match=r"not a world model's features \(maspm\)"):
        AgentCritic(SimpleNamespace(variant_name="maspm"), ENV, "maspm.pt")


def test_wm_mpc_q_evaluates_from_its_files_and_refuses_another_scenarios_agent(
    tmp_path, critic_file
) -> None:
    net = ResidualDynamics(ENV.num_humans, 8, ENV.dt)
    save_residual(tmp_path / "planning.pt", ResidualTrainResult(net, [], {}), {})
    params = PlanningParams(horizon=3, prefix_length=1)
    files = {"planning_model": tmp_path / "planning.pt", "critic": critic_file}
    result = evaluate_method(
        "wm-mpc-q", env_params=ENV, scenario_seed=3, episodes=2, planning=params,
        planner_files=files,
    )  # fmt: skip
    assert result.episodes.num_rows == 2
    assert result.settings["model_files"]["critic"] == str(critic_file)
    with pytest.raises(ValueError, match="planning.continuations: 'policy' needs a critic"):
        evaluate_method("wm-mpc", env_params=ENV, scenario_seed=3, episodes=1,
                        planning=params.replace(continuations=["policy"]),
                        planner_files={"planning_model": tmp_path / "planning.pt"})  # fmt: skip
    with pytest.raises(ValueError, match="humans"):
        evaluate_method(
            "wm-mpc-q", env_params=ENV.replace(room_size=12.0), scenario_seed=3, episodes=1,
            planning=params, planner_files=files,
        )  # fmt: skip
