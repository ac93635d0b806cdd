"""Every training logs its network as an MLflow 3 logged model of its run, on a real SQLite
store: listed by ``search_logged_models``, linked to the run and its final metrics, loadable
with ``models:/<id>``, and served by ``mlflow.pyfunc`` from a plain numpy array."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from socnav_wm.cli import app

mlflow = pytest.importorskip("mlflow")

# MLflow's SQLAlchemy store uses a deprecated loader option; not ours to fix.
pytestmark = pytest.mark.filterwarnings("ignore:The ``noload`` loader strategy")

TRAININGS = {  # command → (the model's name, its type, a headline metric linked to it)
    ("train-vae",): ("vae", "vae", "best_val_loss"),
    ("train-lstm",): ("lstm", "lstm", "best_val_loss"),
    ("train-planning-model", "--seed", "0"): (
        "planning-model-seed-0",
        "planning-model",
        "best_val_loss",
    ),  # noqa: E501
    ("train-agent", "--variant", "maspm"): ("maspm-seed-0", "agent", "greedy_success_rate"),
}


def _invoke(*args: str) -> None:
    result = CliRunner().invoke(app, [*args, "--quiet"])
    assert result.exit_code == 0, result.output


def _episode(agent, steps: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """One test episode's observations and the agent's greedy actions, stepped in the env."""
    env = gym.make("socnav_wm:SocNav-v0", **agent.env_params.to_dict())
    obs, _ = env.reset(seed=5, options={"scenario_id": 0})
    act = agent.policy()
    observations, actions = [], []
    for _ in range(steps):
        action = int(act(obs[None])[0])
        observations.append(obs)
        actions.append(action)
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            break
    env.close()
    return np.stack(observations).astype(np.float32), np.array(actions)


def test_each_training_logs_a_logged_model_of_its_run(workdir: Path) -> None:
    _invoke("collect", "--no-tracking")
    for command in TRAININGS:
        _invoke(*command)

    client = mlflow.MlflowClient()  # the workdir's store (MLFLOW_TRACKING_URI, no global state)
    experiment = client.get_experiment_by_name("socnav-wm")
    assert "logged model" in experiment.tags["mlflow.note.content"]
    models = mlflow.search_logged_models(
        experiment_ids=[experiment.experiment_id], output_format="list"
    )
    by_name = {model.name: model for model in models}
    assert sorted(by_name) == sorted(name for name, _, _ in TRAININGS.values())
    for name, kind, headline in TRAININGS.values():
        model = by_name[name]
        run = client.get_run(model.source_run_id)
        assert model.model_type == kind and str(model.status) == "READY"
        # Linked both ways, with the run's final metrics and its params.
        assert model.model_id in [output.model_id for output in run.outputs.model_outputs]
        linked = {metric.key: metric.value for metric in model.metrics}
        assert linked[headline] == run.data.metrics[headline], name
        assert headline in run.data.tags["headline_metrics"].split(",")
        assert headline in run.data.tags["mlflow.note.content"]
        assert model.params and model.tags["input"] and model.tags["output"]
        # Served from a plain numpy array, shaped as its signature says.
        served = mlflow.pyfunc.load_model(f"models:/{model.model_id}")
        shape = served.metadata.signature.inputs.inputs[0].shape
        rows = np.random.default_rng(0).normal(size=[3 if d == -1 else d for d in shape])
        rows = rows.astype(np.float32)
        if name == "lstm":
            rows[..., -1] = 2  # the action column
        assert served.predict(rows).shape[0] == 3, name

    # The VAE's served form is its encoder; the same weights as the pipeline's file.
    from socnav_wm.worldmodel.files import load_vae

    vae = load_vae(workdir / "models/vae.pt")
    obs = np.random.default_rng(1).normal(size=(5, vae.input_dim)).astype(np.float32)
    served = mlflow.pyfunc.load_model(f"models:/{by_name['vae'].model_id}")
    expected = vae.encode(torch.from_numpy(obs))[0].detach().numpy()
    np.testing.assert_array_equal(served.predict(obs), expected)

    # The agent's is its greedy policy: an episode's observations in, the actions it took out.
    from socnav_wm.agents.agent_file import load_agent

    agent = load_agent(workdir / "models/agents/maspm/seed-0.pt")
    observations, actions = _episode(agent)
    policy = mlflow.pyfunc.load_model(f"models:/{by_name['maspm-seed-0'].model_id}")
    np.testing.assert_array_equal(policy.predict(observations[None])[0], actions)
    module = mlflow.pytorch.load_model(f"models:/{by_name['maspm-seed-0'].model_id}")
    first = module(torch.from_numpy(observations[:2]))  # a batch of first steps
    assert first.shape == (2,) and int(first[0]) == actions[0]

    # The registry takes them as they are.
    version = mlflow.register_model(f"models:/{by_name['vae'].model_id}", "socnav-vae")
    assert version.version == 1 or version.version == "1"
