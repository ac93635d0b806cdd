"""Evaluation: aggregation on known data, files that round-trip, paired scenarios, complete
trajectories (metrics recomputed from them), agents evaluated from agent files."""

from __future__ import annotations

import json
import math

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

from socnav_wm.env.core import discrete_commands
from socnav_wm.evaluation.evaluate import evaluate_method, write_evaluation
from socnav_wm.evaluation.intervals import mean_ci_crossed
from socnav_wm.evaluation.records import (
    BASELINE_SEED,
    METADATA_KEY,
    OUTCOMES,
    episode_from_trajectories,
    evaluation_metadata,
    per_seed_means,
    read_evaluation,
    recompute_metrics,
    summarise,
)
from socnav_wm.metrics import ALL_METRICS, PAPER_METRICS
from tests.evaluation.conftest import (
    EPISODES,
    SCENARIO_SEED,
    TEST_ENV,
    save_tiny_agent,
    write_evaluation_files,
)


def assert_tables_equal(a: pa.Table, b: pa.Table) -> None:
    """Same schema (metadata aside) and values, NaN equal to NaN (``Table.equals`` says no)."""
    assert a.schema.remove_metadata() == b.schema.remove_metadata()
    np.testing.assert_equal(a.to_pydict(), b.to_pydict())


def test_method_names_match_the_rest_of_the_project():
    from socnav_wm.agents.baselines import BASELINES
    from socnav_wm.method_names import (
        BASELINE_NAMES,
        METHOD_NAMES,
        PAPER_METHOD_NAMES,
        PLANNER_NAMES,
        VARIANT_NAMES,
    )
    from socnav_wm.methods import METHODS, names

    assert PAPER_METHOD_NAMES == VARIANT_NAMES + BASELINE_NAMES
    assert METHOD_NAMES == PAPER_METHOD_NAMES + PLANNER_NAMES == tuple(METHODS)
    assert names("planner") == PLANNER_NAMES
    assert names("agent") == VARIANT_NAMES
    assert names("robot") == BASELINE_NAMES
    assert set(BASELINE_NAMES) == set(BASELINES)


# ------------------------------------------------------------------ aggregation


def _hand_table() -> pa.Table:
    """Two seeds × three scenarios with values chosen by hand."""
    columns = {
        "method": ["m"] * 6,
        "training_seed": [0, 0, 0, 1, 1, 1],
        "scenario_id": [0, 1, 2, 0, 1, 2],
    }
    for metric in ALL_METRICS:
        columns[metric] = [0.0] * 6
    columns["success"] = [1.0, 1.0, 0.0, 1.0, 0.0, 0.0]  # seed 0: 2/3, seed 1: 1/3
    columns["reward"] = [1.0, 2.0, 3.0, 5.0, 6.0, 7.0]  # seed 0: 2, seed 1: 6
    columns["time_to_reach_goal"] = [10.0, 20.0, math.nan, 30.0, math.nan, math.nan]
    return pa.table(columns)


def test_summarise_means_intervals_and_nan_on_known_data():
    table = _hand_table()
    summary = summarise(table)
    assert set(summary) == set(ALL_METRICS)
    assert summary["success"]["mean"] == pytest.approx(0.5)
    assert summary["reward"]["mean"] == pytest.approx(4.0)
    assert summary["reward"]["n"] == 6
    # NaN (failures) are left out: mean of 10, 20, 30 over n = 3.
    assert summary["time_to_reach_goal"]["mean"] == pytest.approx(20.0)
    assert summary["time_to_reach_goal"]["n"] == 3
    # The interval is the crossed bootstrap over seeds and scenarios, reproducibly.
    expected = mean_ci_crossed(
        np.array([1.0, 2.0, 3.0, 5.0, 6.0, 7.0]),
        np.array([0, 1, 2] * 2),
        np.array([0] * 3 + [1] * 3),
    )
    assert (summary["reward"]["low"], summary["reward"]["high"]) == (expected.low, expected.high)
    assert summary["reward"]["low"] < 4.0 < summary["reward"]["high"]
    # A constant metric has a zero-width interval.
    assert summary["discomfort"] == {"mean": 0.0, "low": 0.0, "high": 0.0, "n": 6}


def test_per_seed_means_by_hand():
    means = per_seed_means(_hand_table(), ("success", "reward", "time_to_reach_goal"))
    assert means[0] == pytest.approx({"success": 2 / 3, "reward": 2.0, "time_to_reach_goal": 15.0})
    assert means[1] == pytest.approx({"success": 1 / 3, "reward": 6.0, "time_to_reach_goal": 30.0})


def test_summarise_refuses_mixed_methods():
    table = _hand_table()
    mixed = table.set_column(0, "method", pa.array(["a", "a", "a", "b", "b", "b"]))
    with pytest.raises(ValueError, match="one method"):
        summarise(mixed)


# ------------------------------------------------------------------ baselines, files


def test_evaluation_metadata_names_a_foreign_or_older_file(tmp_path):
    table = pa.table({"x": [1.0]})
    cases = [
        (None, "not a socnav-wm evaluation file (no run metadata)"),
        ({"format": "other"}, "not a socnav-wm evaluation file"),
        (
            {"format": "socnav-wm-eval", "format_version": 0},
            "evaluation file format version 0, this code reads version 1",
        ),
    ]
    for number, (header, problem) in enumerate(cases):
        path = tmp_path / f"{number}.parquet"
        metadata = None if header is None else {METADATA_KEY: json.dumps(header).encode()}
        pq.write_table(table.replace_schema_metadata(metadata), path)
        with pytest.raises(ValueError) as error:
            evaluation_metadata(path)
        assert str(error.value) == f"{path}: {problem}"


@pytest.mark.parametrize("method", ["orca", "sfm"])
def test_baseline_evaluation_writes_files_that_round_trip(baseline_results, tmp_path, method):
    result = baseline_results[method]
    episodes, trajectories, metrics = write_evaluation_files(
        result, tmp_path / "data" / "eval", tmp_path / "metrics" / "eval"
    )

    table, metadata = read_evaluation(episodes)
    assert_tables_equal(table, result.episodes)
    assert_tables_equal(pq.read_table(trajectories), result.trajectories)
    assert evaluation_metadata(trajectories) == metadata
    assert metadata["method"] == method
    assert metadata["scenario_seed"] == SCENARIO_SEED
    assert metadata["num_scenarios"] == EPISODES
    assert metadata["training_seeds"] == [BASELINE_SEED]
    assert metadata["env_params"] == TEST_ENV.to_dict()
    # No temporary files left behind.
    assert sorted(p.name for p in episodes.parent.iterdir()) == sorted(
        [episodes.name, trajectories.name]
    )

    # One row per scenario, every metric, the baseline marker.
    assert table.num_rows == EPISODES
    assert sorted(table["scenario_id"].to_pylist()) == list(range(EPISODES))
    assert set(table["training_seed"].to_pylist()) == {BASELINE_SEED}
    assert set(ALL_METRICS) <= set(table.column_names)
    assert set(table["outcome"].to_pylist()) <= set(OUTCOMES)

    # The JSON holds the means and intervals of the table.
    content = json.loads(metrics.read_text())
    assert content["method"] == method and content["episodes"] == EPISODES
    for metric in PAPER_METRICS:
        entry = content["metrics"][metric]
        assert entry["mean"] == pytest.approx(float(np.mean(table[metric].to_numpy())))
        assert entry["low"] <= entry["mean"] <= entry["high"]
        assert entry["n"] == EPISODES
    assert "per_seed" not in content


@pytest.mark.parametrize("method", ["orca", "sfm"])
def test_baseline_trajectories_hold_continuous_commands(baseline_results, method):
    trajectories = baseline_results[method].trajectories
    steps = trajectories.filter(pc.greater(trajectories["t"], 0))
    first = trajectories.filter(pc.equal(trajectories["t"], 0))
    assert set(steps["action"].to_pylist()) == {-1}
    v, omega = steps["v"].to_numpy(), steps["omega"].to_numpy()
    assert np.all(np.abs(v) <= TEST_ENV.robot_max_speed + 1e-12)
    assert np.all(np.abs(omega) <= TEST_ENV.robot_max_rotation + 1e-12)
    assert np.any(v > 0) and np.any(omega != 0)
    # The step that led to state 0 does not exist.
    for column in ("action", "v", "omega", "reward", "dmin"):
        assert first[column].null_count == first.num_rows
    # Rows per episode = steps + 1; the outcome sits on the last row only.
    table = baseline_results[method].episodes
    assert trajectories.num_rows == int(np.sum(table["num_steps"].to_numpy())) + EPISODES
    assert trajectories["outcome"].null_count == trajectories.num_rows - EPISODES


def test_outcome_columns_agree_with_the_metrics(baseline_results):
    for result in baseline_results.values():
        for row in result.episodes.to_pylist():
            flags = {
                "success": row["success"],
                "human_collision": row["human_collision"],
                "wall_collision": row["wall_collision"],
                "timeout": row["max_steps"],
            }
            assert flags[row["outcome"]] == 1.0
            assert sum(flags.values()) == 1.0
            assert row["simulation_time"] == row["num_steps"] * TEST_ENV.dt


def test_same_scenario_starts_identically_for_two_methods(baseline_results):
    """The comparison is paired: scenario i is the same room for every method."""
    starts = {}
    for method, result in baseline_results.items():
        table = result.trajectories.filter(pc.equal(result.trajectories["t"], 0))
        starts[method] = table.sort_by("scenario_id").select(
            ["scenario_id", "robot_x", "robot_y", "robot_theta", "goal_x", "goal_y", "human_xy"]
        )
    assert starts["orca"].num_rows == EPISODES
    assert starts["orca"].equals(starts["sfm"])
    # ...and different scenarios are different rooms.
    robot_x = starts["orca"]["robot_x"].to_numpy()
    assert len(set(robot_x.tolist())) == EPISODES
    # The two controllers did behave differently afterwards.
    assert (
        not baseline_results["orca"]
        .episodes["num_steps"]
        .equals(baseline_results["sfm"].episodes["num_steps"])
    )


def test_metrics_recomputed_from_trajectories_match_the_episode_rows(baseline_results):
    for method, result in baseline_results.items():
        for row in result.episodes.to_pylist():
            again = recompute_metrics(
                result.trajectories, method, row["training_seed"], row["scenario_id"], TEST_ENV
            )
            for metric in ALL_METRICS:
                if math.isnan(row[metric]):
                    assert math.isnan(again[metric]), metric
                else:
                    assert again[metric] == row[metric], (method, row["scenario_id"], metric)


def test_episode_from_trajectories_errors(baseline_results):
    trajectories = baseline_results["orca"].trajectories
    with pytest.raises(KeyError, match="no trajectory"):
        episode_from_trajectories(trajectories, "orca", BASELINE_SEED, 999)
    broken = pa.concat_tables([trajectories, trajectories.slice(0, 1)])
    with pytest.raises(ValueError, match="steps are not"):
        episode_from_trajectories(broken, "orca", BASELINE_SEED, 0)


def test_batch_size_does_not_change_the_results(baseline_results):
    again = evaluate_method(
        "sfm", env_params=TEST_ENV, scenario_seed=SCENARIO_SEED, episodes=EPISODES, batch_size=4
    )
    assert_tables_equal(again.episodes, baseline_results["sfm"].episodes)
    assert_tables_equal(again.trajectories, baseline_results["sfm"].trajectories)


def test_baseline_overrides_are_used_and_recorded():
    result = evaluate_method(
        "orca",
        env_params=TEST_ENV,
        scenario_seed=SCENARIO_SEED,
        episodes=2,
        baseline_overrides={"safety_margin": 0.0},
    )
    assert result.settings == {"baseline_overrides": {"safety_margin": 0.0}}
    with pytest.raises(ValueError, match="unknown option"):
        evaluate_method(
            "orca", env_params=TEST_ENV, scenario_seed=0, episodes=1, baseline_overrides={"x": 1}
        )


@pytest.mark.parametrize(
    ("method", "kwargs", "message"),
    [
        ("ppo", {}, "unknown 'ppo'"),
        ("orca", {"agent_paths": {0: "a.pt"}}, "takes no agent files"),
        ("maspm", {}, "needs agent files"),
        ("maspm", {"agent_paths": {0: "a.pt"}, "baseline_overrides": {"x": 1}}, "baseline"),
        ("orca", {"episodes": 0}, "episodes"),
    ],
)
def test_bad_arguments_fail_with_one_line(method, kwargs, message):
    options = {"env_params": TEST_ENV, "scenario_seed": 0, "episodes": 2} | kwargs
    with pytest.raises(ValueError, match=message):
        evaluate_method(method, **options)


# ------------------------------------------------------------------ agents (untrained files)


@pytest.fixture
def one_torch_thread():
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.mark.parametrize("variant", ["dueling-dqn", "2stepahead-maspm"])
def test_agent_evaluation_from_agent_files(tmp_path, one_torch_thread, variant):
    paths = {
        seed: save_tiny_agent(tmp_path / f"seed-{seed}.pt", variant, TEST_ENV, seed)
        for seed in (3, 0)
    }
    episodes = 4
    result = evaluate_method(
        variant, env_params=TEST_ENV, scenario_seed=SCENARIO_SEED, episodes=episodes,
        agent_paths=paths, device="cpu",
    )  # fmt: skip
    table = result.episodes
    assert result.training_seeds == (0, 3)
    assert table.num_rows == 2 * episodes
    keys = zip(table["training_seed"].to_pylist(), table["scenario_id"].to_pylist(), strict=True)
    assert sorted(keys) == [(seed, scenario) for seed in (0, 3) for scenario in range(episodes)]
    assert result.settings["agent_files"] == {"0": str(paths[0]), "3": str(paths[3])}

    # Discrete actions, and the executed command of each is the action's (v, ω).
    steps = result.trajectories.filter(pc.greater(result.trajectories["t"], 0))
    actions = steps["action"].to_numpy()
    assert set(actions.tolist()) <= {0, 1, 2, 3}
    table_of_commands = discrete_commands(TEST_ENV)
    np.testing.assert_array_equal(steps["v"].to_numpy(), table_of_commands[actions, 0])
    np.testing.assert_array_equal(steps["omega"].to_numpy(), table_of_commands[actions, 1])

    # Trajectories are complete for agents too.
    for row in table.to_pylist():
        again = recompute_metrics(
            result.trajectories, variant, row["training_seed"], row["scenario_id"], TEST_ENV
        )
        assert again["reward"] == row["reward"]
        assert again["personal_space_compliance"] == row["personal_space_compliance"]
        episode = episode_from_trajectories(
            result.trajectories, variant, row["training_seed"], row["scenario_id"]
        )
        assert episode.actions.dtype == np.int64

    # Greedy and seeded: a second evaluation (in other batches) is identical.
    again = evaluate_method(
        variant, env_params=TEST_ENV, scenario_seed=SCENARIO_SEED, episodes=episodes,
        agent_paths=paths, batch_size=3, device="cpu",
    )  # fmt: skip
    assert_tables_equal(again.episodes, table)

    # The same scenarios as the baselines (paired): same starts at t = 0.
    sfm = evaluate_method(
        "sfm", env_params=TEST_ENV, scenario_seed=SCENARIO_SEED, episodes=episodes
    )
    columns = ["scenario_id", "robot_x", "robot_y", "goal_x", "goal_y", "human_xy"]

    def starts(trajectories: pa.Table, seed: int) -> pa.Table:
        mask = pc.and_(
            pc.equal(trajectories["t"], 0), pc.equal(trajectories["training_seed"], seed)
        )
        return trajectories.filter(mask).sort_by("scenario_id").select(columns)

    assert starts(result.trajectories, 3).equals(starts(sfm.trajectories, BASELINE_SEED))

    # Per-seed means go to the JSON of an agent.
    out = tmp_path / "out"
    write_evaluation(result, out / "e.parquet", out / "t.parquet", out / "m.json")
    content = json.loads((out / "m.json").read_text())
    assert set(content["per_seed"]) == {"seed-0", "seed-3"}
    assert content["training_seeds"] == [0, 3]


def test_an_agent_of_another_variant_is_refused(tmp_path, one_torch_thread):
    path = save_tiny_agent(tmp_path / "a.pt", "dueling-dqn", TEST_ENV, 0)
    with pytest.raises(ValueError, match="variant 'dueling-dqn', not 'maspm'"):
        evaluate_method(
            "maspm",
            env_params=TEST_ENV,
            scenario_seed=0,
            episodes=1,
            agent_paths={0: path},
            device="cpu",
        )
