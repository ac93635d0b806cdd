"""The native update (``agent.update_backend: native``): the same update as the PyTorch one up to
rounding, independent of the thread count, deterministic and resumable in training, and clear
errors when it cannot be built or used."""

import dataclasses
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from pipeline.agents import native
from pipeline.agents.dqn import DQNLearner, train_agent
from pipeline.agents.params import AgentParams
from pipeline.agents.replay import Batch
from pipeline.bench import bench_train
from pipeline.cli import app
from tests.agents.test_dqn import TINY, TINY_ENV, Interrupted, assert_same_weights, without_time


def _native_available() -> str | None:
    try:
        native.load_library()
    except native.NativeUpdateError as exc:
        return str(exc)
    return None


_UNAVAILABLE = _native_available()
needs_native = pytest.mark.skipif(_UNAVAILABLE is not None, reason=str(_UNAVAILABLE))
NATIVE = dataclasses.replace(TINY, update_backend="native")


def random_batch(n: int, dim: int, reward_scale: float = 1.0) -> Batch:
    return Batch(
        torch.randn(n, dim), torch.randint(0, 4, (n,)), reward_scale * torch.randn(n),
        torch.randn(n, dim), (torch.rand(n) < 0.2).float(), torch.full((n,), 0.95),
    )  # fmt: skip


def assert_close_to_scale(mine: torch.Tensor, theirs: torch.Tensor, tolerance: float) -> None:
    """Equal up to ``tolerance`` times the largest magnitude of ``theirs`` (rounding differs)."""
    scale = theirs.abs().max()
    torch.testing.assert_close(mine / scale, theirs / scale, rtol=0, atol=tolerance)


def twin_learners(dim: int, params: AgentParams) -> tuple[DQNLearner, DQNLearner]:
    """A PyTorch and a native learner with the same initial weights."""
    torch.manual_seed(0)
    reference = DQNLearner(dim, params, torch.device("cpu"))
    torch.manual_seed(0)
    fast = DQNLearner(
        dim, dataclasses.replace(params, update_backend="native"), torch.device("cpu")
    )
    assert torch.equal(reference.weights(), fast.weights())
    return reference, fast


@needs_native
@pytest.mark.parametrize(
    ("changes", "reward_scale"),
    [
        ({"grad_clip": 0.05}, 1.0),  # the clip bites
        ({"optimizer": "adamw", "amsgrad": True, "weight_decay": 0.01, "huber": True}, 3.0),
        ({"trunk_sizes": (48, 24, 40), "stream_size": 20, "weight_decay": 0.01}, 1.0),  # L2
        # the paper's network and batch
        (
            {
                "trunk_sizes": (512, 128),
                "stream_size": 128,
                "batch_size": 64,
                "learning_starts": 64,
            },
            1.0,
        ),
    ],
)
def test_native_update_matches_the_torch_update(changes: dict, reward_scale: float) -> None:
    params = dataclasses.replace(TINY, learning_rate=1e-3, polyak=0.9, **changes)
    dim = 11
    reference, fast = twin_learners(dim, params)
    for step in range(5):
        batch = random_batch(params.batch_size, dim, reward_scale)
        expected = reference.update(batch)
        loss = fast.update(batch)
        torch.testing.assert_close(loss, expected, rtol=1e-5, atol=1e-7)
        assert_close_to_scale(fast._grads, reference._grads, 1e-4)
        for name in ("exp_avg", "exp_avg_sq", "max_exp_avg_sq"):
            mine = fast.optimizer.state[fast._weights].get(name)
            theirs = reference.optimizer.state[reference._weights].get(name)
            assert (mine is None) == (theirs is None), name
            if mine is not None:
                assert_close_to_scale(mine, theirs, 1e-4)
        assert float(fast.optimizer.state[fast._weights]["step"]) == step + 1
    # A step moves a weight by about the learning rate: the two agree to a small part of one.
    torch.testing.assert_close(fast.weights(), reference.weights(), rtol=0, atol=1e-5)
    torch.testing.assert_close(fast._target_weights, reference._target_weights, rtol=0, atol=1e-5)
    if "grad_clip" in changes:
        assert fast._native.norm[0] > params.grad_clip  # the clipping path was taken


@needs_native
def test_native_update_does_not_depend_on_the_thread_count() -> None:
    params = dataclasses.replace(NATIVE, trunk_sizes=(96, 40), stream_size=24, grad_clip=0.5)
    threads = torch.get_num_threads()
    learners = []
    for count in (1, 2):
        torch.manual_seed(0)
        learner = DQNLearner(13, params, torch.device("cpu"))
        torch.manual_seed(1)
        try:
            torch.set_num_threads(count)
            for _ in range(20):
                learner.update(random_batch(params.batch_size, 13))
        finally:
            torch.set_num_threads(threads)
        learners.append(learner)
    assert torch.equal(learners[0].weights(), learners[1].weights())
    assert torch.equal(learners[0]._target_weights, learners[1]._target_weights)


@needs_native
def test_native_training_is_deterministic_and_resumable(tmp_path: Path) -> None:
    uninterrupted = train_agent("dueling-dqn", NATIVE, TINY_ENV, None, None, seed=5)
    again = train_agent("dueling-dqn", NATIVE, TINY_ENV, None, None, seed=5)
    assert_same_weights(uninterrupted.q_network, again.q_network)
    assert without_time(again.episodes) == without_time(uninterrupted.episodes)
    torch_run = train_agent("dueling-dqn", TINY, TINY_ENV, None, None, seed=5)
    assert not torch.equal(torch_run.q_network.trunk[0].weight, again.q_network.trunk[0].weight)

    def interrupt(rows: list[dict]) -> None:
        if rows[-1]["episode"] >= 25:  # after the checkpoint at 20
            raise Interrupted

    checkpoint = tmp_path / "run.ckpt"
    with pytest.raises(Interrupted):
        train_agent("dueling-dqn", NATIVE, TINY_ENV, None, None, seed=5,
                    checkpoint_path=checkpoint, on_episodes=interrupt)  # fmt: skip
    resumed = train_agent(
        "dueling-dqn", NATIVE, TINY_ENV, None, None, seed=5, checkpoint_path=checkpoint,
        resume=True,
    )  # fmt: skip
    assert_same_weights(uninterrupted.q_network, resumed.q_network)
    assert without_time(resumed.episodes) == without_time(uninterrupted.episodes)


@needs_native
def test_bench_train_times_the_native_update() -> None:
    params = AgentParams(num_envs=8, batch_size=16, update_backend="native")
    row = bench_train("maspm", params=params, seconds=0.05)
    assert row["updates_per_s"] > 0 and row["env_steps_per_s"] > 0


def test_native_update_refuses_a_gpu_device() -> None:
    with pytest.raises(ValueError, match=r"^agent.update_backend: native runs on the CPU"):
        DQNLearner(5, NATIVE, torch.device("cuda"))


@needs_native
def test_native_update_refuses_other_dtypes() -> None:
    learner = DQNLearner(5, NATIVE, torch.device("cpu"))
    batch = random_batch(16, 5)._replace(actions=torch.zeros(16, dtype=torch.int32))
    with pytest.raises(native.NativeUpdateError, match="int64 actions, got torch.float32"):
        learner.update(batch)


@needs_native
def test_native_update_refuses_a_trunk_deeper_than_it_holds() -> None:
    deep = dataclasses.replace(NATIVE, trunk_sizes=(4,) * (native.MAX_TRUNK_LAYERS + 1))
    with pytest.raises(native.NativeUpdateError, match=r"^agent.trunk_sizes: .* at most 64"):
        DQNLearner(5, deep, torch.device("cpu"))


@pytest.mark.parametrize(
    ("compiler", "message"),
    [
        ("/nonexistent/cc", r"C compiler '/nonexistent/cc' not found"),
        ("false", r"compiling native_update.c with \S*false failed"),
    ],
)
def test_native_build_errors_are_one_line(
    compiler: str, message: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("SOCNAV_WM_CACHE_DIR", str(tmp_path))  # nothing built there yet
    monkeypatch.setenv("CC", compiler)
    native.load_library.cache_clear()
    try:
        with pytest.raises(native.NativeUpdateError, match=message) as caught:
            native.load_library()
    finally:
        native.load_library.cache_clear()
    assert "\n" not in str(caught.value)
    assert not list(tmp_path.rglob("*.so"))  # no half-written library left behind


def test_cli_reports_a_failed_build_in_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("SOCNAV_WM_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv("CC", "false")
    native.load_library.cache_clear()
    params = tmp_path / "params.yaml"
    params.write_text("agent:\n  num_envs: 4\n  batch_size: 8\n  update_backend: native\n")
    try:
        result = CliRunner().invoke(
            app, ["bench", "train", "--variant", "dueling-dqn", "--params", str(params)]
        )
    finally:
        native.load_library.cache_clear()
    assert result.exit_code == 2, result.output
    assert result.output.startswith("error: agent.update_backend: native: compiling")
    assert len(result.output.strip().splitlines()) == 1
