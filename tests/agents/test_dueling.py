"""The Dueling Q-network: aggregation by hand, architecture, init, hand-written backward."""

import pytest
import torch
from torch import nn

from pipeline.agents.dueling import DuelingQNetwork, dueling_q_values


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


@pytest.mark.parametrize(("trunk", "stream", "actions"), [((512, 128), 128, 4), ((7,), 5, 3)])
def test_hand_written_backward_equals_autograd(
    trunk: tuple[int, ...], stream: int, actions: int
) -> None:
    torch.manual_seed(3)
    net = DuelingQNetwork(11, actions, trunk, stream)
    features = torch.randn(32, 11)
    grad_q = torch.randn(32, actions)

    q_values, cache = net.forward_cached(features)
    (q_values * grad_q).sum().backward()  # d/dQ of this scalar is grad_q
    expected = {name: param.grad.clone() for name, param in net.named_parameters()}
    torch.testing.assert_close(q_values, net(features))

    for param in net.parameters():
        param.grad = torch.full_like(param, 123.0)  # overwritten, not accumulated into
    with torch.no_grad():
        _, cache = net.forward_cached(features)
    net.backward_cached(cache, grad_q)
    for name, param in net.named_parameters():
        torch.testing.assert_close(param.grad, expected[name], rtol=1e-5, atol=1e-6, msg=name)


def test_forward_without_cache_and_the_head_of_a_cache() -> None:
    """forward() is forward_cached() without the activations, and the first rows of a cache
    are the cache of the first rows (the DQN update runs s and s′ in one pass)."""
    torch.manual_seed(4)
    net = DuelingQNetwork(9, trunk_sizes=(16, 8), stream_size=6)
    features = torch.randn(10, 9)
    with torch.no_grad():
        q_values, cache = net.forward_cached(features)
        head_q, head_cache = net.forward_cached(features[:4])
    assert torch.equal(net(features), q_values)
    torch.testing.assert_close(q_values[:4], head_q)
    grad_q = torch.randn(4, 4)
    grads = []
    for used in (cache.head(4), head_cache):
        for param in net.parameters():
            param.grad = torch.empty_like(param)
        net.backward_cached(used, grad_q)
        grads.append([param.grad.clone() for param in net.parameters()])
    for mine, expected in zip(*grads, strict=True):
        torch.testing.assert_close(mine, expected)
