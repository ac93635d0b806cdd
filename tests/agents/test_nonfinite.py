"""A diverging DQN training stops with one line, exit status 2 and no files (the NaN/inf guard
of the training loop), and the learner's flat parameter layout is invisible to its users."""

from __future__ import annotations

import copy
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from socnav_wm.agents.learner import DQNLearner, flatten_parameters
from socnav_wm.agents.params import AgentParams
from socnav_wm.agents.replay import Batch
from socnav_wm.agents.training import train_agent
from socnav_wm.cli import app
from socnav_wm.env import EnvParams
from socnav_wm.worldmodel.fitting import NonFiniteTrainingError

TINY = AgentParams(
    episodes=20, num_envs=4, batch_size=16, buffer_size=500, learning_starts=32,
    updates_per_step=2, trunk_sizes=(32,), stream_size=16, select_every=0, device="cpu",
)  # fmt: skip
TINY_ENV = EnvParams(room_size=6.0, max_steps=30)


def test_a_huge_learning_rate_stops_the_training_at_the_first_bad_update() -> None:
    with pytest.raises(NonFiniteTrainingError) as caught:
        train_agent("dueling-dqn", TINY.replace(learning_rate=1e30), TINY_ENV, None, None, seed=0)
    message = str(caught.value)
    assert "\n" not in message
    assert message.startswith("agent training stopped: ")
    assert "became" in message and "at update " in message
    assert "agent.learning_rate 1e+30 too high?" in message
    # An ordinary rate trains through.
    result = train_agent("dueling-dqn", TINY, TINY_ENV, None, None, seed=0)
    assert result.updates > 0
    assert all(torch.isfinite(p).all() for p in result.q_network.parameters())


def test_train_agent_command_exits_2_with_one_line_and_writes_nothing(
    workdir: Path,
) -> None:
    out = workdir / "out"
    result = CliRunner().invoke(
        app,
        [
            "train-agent", "--variant", "dueling-dqn", "--seed", "0", "--no-tracking", "--quiet",
            "--threads", "1", "--set", "agent.learning_rate=1e30",
            "--out-dir", str(out / "models"), "--log-dir", str(out / "logs"),
            "--metrics-dir", str(out / "metrics"), "--checkpoint-dir", str(out / "checkpoints"),
        ],
    )  # fmt: skip
    assert result.exit_code == 2, result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1, result.output
    assert lines[0].startswith("error: agent training stopped: loss became ")
    assert "learning_rate 1e+30 too high?" in lines[0]
    written = [path for path in out.rglob("*") if path.is_file()] if out.exists() else []
    assert written == []


def test_flat_parameters_are_views_with_the_same_values_names_and_shapes() -> None:
    torch.manual_seed(0)
    learner = DQNLearner(5, TINY, torch.device("cpu"))
    reference = copy.deepcopy(learner.q_network)  # ordinary, separate parameters
    x = torch.randn(7, 5)
    torch.testing.assert_close(learner.q_network(x), reference(x), rtol=0, atol=0)
    flat = learner._flat
    for name, param in learner.q_network.named_parameters():
        assert param.untyped_storage().data_ptr() == flat.untyped_storage().data_ptr(), name
        assert param.grad is not None and param.grad.shape == param.shape
        assert torch.equal(param, reference.get_parameter(name))
    # The first layer widens (5 → 32): its weight lies transposed, the grad view alike.
    first = learner.q_network.trunk[0].weight
    assert first.shape == (32, 5) and first.stride() == (1, 32)
    assert first.grad.stride() == first.stride()
    # state_dict / load_state_dict round trip through the views.
    state = {k: v.clone() for k, v in learner.q_network.state_dict().items()}
    with torch.no_grad():
        flat.zero_()
    learner.q_network.load_state_dict(state)
    torch.testing.assert_close(learner.q_network(x), reference(x), rtol=0, atol=0)


def test_zero_grad_to_none_does_not_stop_the_learning() -> None:
    torch.manual_seed(0)
    learner = DQNLearner(3, TINY.replace(learning_rate=1e-2), torch.device("cpu"))
    learner.q_network.zero_grad(set_to_none=True)  # detaches the gradient views
    before = {k: v.clone() for k, v in learner.q_network.state_dict().items()}
    batch = Batch(
        torch.randn(8, 3), torch.randint(0, 4, (8,)), torch.randn(8), torch.randn(8, 3),
        torch.zeros(8), torch.full((8,), 0.9),
    )  # fmt: skip
    learner.update(batch)
    after = learner.q_network.state_dict()
    assert all(not torch.equal(before[k], after[k]) for k in before)


def test_parameters_of_mixed_dtypes_are_refused() -> None:
    net = torch.nn.Sequential(torch.nn.Linear(2, 3), torch.nn.Linear(3, 1).double())
    with pytest.raises(ValueError, match="one dtype and device"):
        flatten_parameters(net, with_grad=True)
