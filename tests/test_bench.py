"""The training benchmark's rows (the simulator and collection benchmarks run through the CLI
in tests/test_cli.py)."""

from __future__ import annotations

import pytest

from socnav_wm.agents.params import AgentParams
from socnav_wm.bench import bench_train


def test_bench_train_reports_both_rates() -> None:
    params = AgentParams(num_envs=8, batch_size=16)
    row = bench_train("2stepahead-maspm", params=params, seconds=0.05)
    assert (row["feature_dim"], row["num_envs"], row["batch_size"]) == (
        5 * 23,
        8,
        16,
    )  # z and 4 predictions, decoded
    assert row["env_steps_per_cpu_s"] > 0 and row["updates_per_cpu_s"] > 0


def test_bench_contention_measures_the_stage_alone_and_beside_busy_processes() -> None:
    from socnav_wm.bench import bench_contention

    tiny = ("collect.episodes=16", "collect.num_envs=8", "vae.max_epochs=1", "vae.hidden_dim=16",
            "vae.device=cpu")  # fmt: skip
    (row,) = bench_contention((1,), hogs=1, settings=tiny)
    assert row["stage"] == "train-vae" and row["threads"] == 1 and row["hogs"] == 1
    assert row["cpu_s_alone"] > 0 and row["cpu_s_shared"] > 0
    assert row["ratio"] == row["cpu_s_shared"] / row["cpu_s_alone"]


def test_bench_contention_runs_each_torch_stage_on_inputs_it_makes_first() -> None:
    from socnav_wm.bench import bench_contention

    tiny = ("collect.episodes=16", "collect.num_envs=8", "vae.max_epochs=1", "vae.hidden_dim=16",
            "vae.device=cpu", "lstm.max_epochs=1", "lstm.hidden_dim=16", "lstm.seq_len=4",
            "lstm.batch_size=16", "agent.episodes=4", "agent.num_envs=4", "agent.batch_size=8",
            "agent.buffer_size=64", "agent.learning_starts=16", "agent.eval_episodes=2",
            "agent.select_every=0", "agent.device=cpu", "planning_model.max_epochs=1",
            "planning_model.hidden_dim=4", "planning_model.val_fraction=0.2")  # fmt: skip
    (row,) = bench_contention((1,), hogs=1, settings=tiny, stages=("train-agent",))
    assert row["stage"] == "train-agent"  # on the VAE and LSTM it trained first
    assert row["cpu_s_alone"] > 0 and row["cpu_s_shared"] > 0
    with pytest.raises(ValueError, match="--stage: unknown 'evaluate'"):
        bench_contention((1,), hogs=1, stages=("evaluate",))
