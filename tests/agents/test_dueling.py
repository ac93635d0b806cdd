"""The Dueling Q-network: aggregation by hand, architecture, init, and a module added to it
runs and trains."""

import pytest
import torch
from torch import nn

from socnav_wm.agents.dueling import DuelingQNetwork, dueling_q_values
from socnav_wm.agents.learner import DQNLearner
from socnav_wm.agents.params import AgentParams
from socnav_wm.agents.replay import Batch


def test_dueling_aggregation_by_hand() -> None:
    value = torch.tensor([[2.0], [-1.0]])
    advantage = torch.tensor([[1.0, 2.0, 3.0, 6.0], [0.0, 0.0, 0.0, 4.0]])
    # mean(A) = 3 and 1: Q = V + A − mean(A).
    expected = torch.tensor([[0.0, 1.0, 2.0, 5.0], [-2.0, -2.0, -2.0, 2.0]])
    assert torch.equal(dueling_q_values(value, advantage), expected)


def test_q_values_average_to_the_value_stream() -> None:
    torch.manual_seed(0)
    net = DuelingQNetwork(7, trunk_sizes=(32, 16), stream_size=8)
    x = torch.randn(5, 7)
    q = net(x)
    assert q.shape == (5, 4)
    value = net.value(net.trunk(x))
    torch.testing.assert_close(q.mean(dim=1, keepdim=True), value)


def test_architecture_has_an_activation_after_every_hidden_layer() -> None:
    net = DuelingQNetwork(23)
    layers = list(net.trunk)
    # Linear(23, 512), act, Linear(512, 128), act: the paper's bare 512 → 128 → streams
    # (paper_spec §8.16) is fixed by the activation after the 128 layer.
    assert [type(m) for m in layers] == [nn.Linear, nn.LeakyReLU, nn.Linear, nn.LeakyReLU]
    assert (layers[0].in_features, layers[0].out_features) == (23, 512)
    assert (layers[2].in_features, layers[2].out_features) == (512, 128)
    assert [m.out_features for m in net.value if isinstance(m, nn.Linear)] == [128, 1]
    assert [m.out_features for m in net.advantage if isinstance(m, nn.Linear)] == [128, 4]
    assert isinstance(net.advantage[-1], nn.Linear)  # linear outputs


def test_xavier_init_with_zero_biases_and_seeded() -> None:
    torch.manual_seed(3)
    a = DuelingQNetwork(10, trunk_sizes=(64,))
    torch.manual_seed(3)
    b = DuelingQNetwork(10, trunk_sizes=(64,))
    for pa, pb in zip(a.parameters(), b.parameters(), strict=True):
        assert torch.equal(pa, pb)
    first = a.trunk[0]
    bound = nn.init.calculate_gain("leaky_relu", 0.01) * (6 / (10 + 64)) ** 0.5
    assert first.weight.abs().max() <= bound
    assert first.weight.abs().max() > 0.8 * bound  # uniform over the whole Xavier range
    assert all(torch.all(m.bias == 0) for m in a.modules() if isinstance(m, nn.Linear))


def test_needs_a_trunk_layer() -> None:
    with pytest.raises(ValueError, match="trunk_sizes"):
        DuelingQNetwork(4, trunk_sizes=())


def test_a_module_added_to_the_network_runs_and_trains() -> None:
    """Insert a LayerNorm into the trunk: the outputs change, and one update moves every one of
    the network's parameters, the LayerNorm's included (autograd, no hand-written pass)."""
    torch.manual_seed(0)
    plain = DuelingQNetwork(6, trunk_sizes=(32,), stream_size=8)
    with_norm = DuelingQNetwork(6, trunk_sizes=(32,), stream_size=8)
    with_norm.load_state_dict(plain.state_dict())
    with_norm.trunk.insert(1, nn.LayerNorm(32))
    with torch.no_grad():  # a non-trivial affine part, so that it matters in the forward pass
        with_norm.trunk[1].weight.uniform_(0.5, 1.5)
        with_norm.trunk[1].bias.uniform_(-0.5, 0.5)
    x = torch.randn(16, 6)
    assert not torch.allclose(plain(x), with_norm(x))

    params = AgentParams(batch_size=16, learning_starts=16, grad_clip=0.0, device="cpu")
    learner = DQNLearner(6, params, torch.device("cpu"), network=with_norm)
    before = {name: p.detach().clone() for name, p in learner.q_network.named_parameters()}
    assert "trunk.1.weight" in before and "trunk.1.bias" in before
    batch = Batch(
        x, torch.randint(0, 4, (16,)), torch.randn(16), torch.randn(16, 6), torch.zeros(16),
        torch.full((16,), 0.95),
    )  # fmt: skip
    learner.update(batch)
    for name, param in learner.q_network.named_parameters():
        assert not torch.equal(param, before[name]), f"{name} did not move"
