"""The examples run as shipped (tiny budgets)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def load(name: str):
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_sb3_dqn_trains_and_tests_on_the_registered_env(capsys) -> None:
    rates = load("sb3_dqn").main(["--timesteps", "300", "--test-episodes", "3"])
    assert set(rates) == {"success", "human_collision", "wall_collision", "timeout"}
    assert sum(rates.values()) == pytest.approx(1.0)
    assert "on 3 test scenarios" in capsys.readouterr().out


# ---------------------------------------------------------------- the three uses of the README
@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory):
    """The tiny configuration and a folder for what its stages write."""
    from socnav_wm.config import load_params
    from tests.conftest import ROOT, TINY_OVERLAY

    return load_params(ROOT / "params.yaml", overlays=[TINY_OVERLAY]), tmp_path_factory.mktemp(
        "examples"
    )


def test_gym_env_runs_the_single_and_the_vector_env(capsys) -> None:
    result = load("gym_env").main(["--episodes", "3", "--num-envs", "8", "--steps", "30"])
    outcomes = ("success", "human_collision", "wall_collision", "timeout")
    assert sum(result[k] for k in outcomes) == 3
    assert result["vector_episodes_ended"] >= 0
    assert "gym.make_vec: 8 rooms x 30 random steps" in capsys.readouterr().out


def test_run_agent_loads_a_trained_agent_and_matches_the_evaluation(tiny, capsys) -> None:
    """An agent trained by the train_agent stage (tiny budget), run step by step in the gym
    env by the example: the same outcomes, scenario by scenario, as the evaluation's runner."""
    import torch

    from socnav_wm.agents.agent_file import greedy_episodes, load_agent
    from socnav_wm.stages import train_agent

    params, folder = tiny
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        train_agent.run(
            params, variant="dueling-dqn", seed=0, vae=folder / "vae.pt", lstm=folder / "lstm.pt",
            out_dir=folder / "agents",
            log_dir=folder / "training", metrics_dir=folder / "metrics",
            checkpoint_dir=folder / "checkpoints", tracking=False,
        )  # fmt: skip
        path = folder / "agents" / "dueling-dqn" / "seed-0.pt"
        outcomes = load("run_agent").main([str(path), "--episodes", "4", "--scenario-seed", "5"])
        agent = load_agent(path)
        expected = [
            "success" if e.success else f"{e.collision}_collision" if e.collision else "timeout"
            for e in greedy_episodes(agent, agent.env_params, seed=5, scenario_ids=range(4))
        ]
    finally:
        torch.set_num_threads(before)
    assert outcomes == expected
    assert "dueling-dqn" in capsys.readouterr().out


def test_plan_with_constant_velocity_and_with_a_trained_planning_model(tiny, capsys) -> None:
    """The planner on constant velocity, then on a planning model trained by the
    train_planning_model stage on rollouts of the collect stage (tiny budgets)."""
    from socnav_wm.stages import collect, train_planning_model

    params, folder = tiny
    small = ["--episodes", "3", "--horizon", "4", "--prefix-length", "1", "--scenario-seed", "5"]
    counts = load("plan").main(small)
    assert sum(counts.values()) == 3
    rollouts = folder / "rollouts"
    collect.run(params, out=rollouts, metrics=folder / "collect.json", tracking=False)
    train_planning_model.run(
        params, seed=0, rollouts=rollouts, out_dir=folder / "planning",
        metrics_dir=folder / "planning-metrics", tracking=False,
    )  # fmt: skip
    model = folder / "planning" / "seed-0.pt"
    assert sum(load("plan").main([*small, "--model", str(model)]).values()) == 3
    out = capsys.readouterr().out
    assert "ConstantVelocityModel" in out and "ResidualPlanningModel" in out


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ([], "give an agent file, e.g. models/agents/maspm/seed-0.pt"),
        (["no/such.pt"], "no/such.pt: no such agent file"),
    ],
)
def test_run_agent_without_an_agent_file_says_so_in_one_line(args, message, capsys) -> None:
    with pytest.raises(SystemExit) as ended:
        load("run_agent").main(args)
    assert ended.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and message in lines[0]
