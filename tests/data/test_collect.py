"""The collect stage's library function: valid episodes, batch-size independence, summary."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from socnav_wm.data.collect import collect_rollouts
from socnav_wm.data.shards import column_to_numpy, read_rollouts, validate_episodes
from socnav_wm.env import EnvParams


def _collect(tmp_path: Path, name: str, num_envs: int, episodes: int = 24, **kwargs):
    out = tmp_path / name
    summary = collect_rollouts(
        EnvParams(), episodes=episodes, num_envs=num_envs, seed=3, out_dir=out,
        max_rows_per_shard=kwargs.get("max_rows_per_shard", 10_000),
    )  # fmt: skip
    return summary, read_rollouts(out)


def test_collected_episodes_are_complete_and_never_cross_a_boundary(tmp_path: Path) -> None:
    summary, table = _collect(tmp_path, "a", num_envs=5, max_rows_per_shard=300)
    validate_episodes(table)  # t = 0..n−1, is_first/is_last, next_obs == following obs
    ids = column_to_numpy(table, "episode_id")
    assert sorted(np.unique(ids)) == list(range(24))
    assert summary.episodes == 24 and summary.steps == table.num_rows
    assert len(summary.shards) > 1  # 300-row shards force several files
    # Exactly one outcome per episode, on its last row.
    last = column_to_numpy(table, "is_last")
    outcome = (
        column_to_numpy(table, "success").astype(int)
        + (column_to_numpy(table, "collision") > 0)
        + column_to_numpy(table, "truncated")
    )
    assert np.all(outcome[last] == 1) and np.all(outcome[~last] == 0)
    terminal = column_to_numpy(table, "is_terminal")
    assert np.all(terminal <= last)
    rates = (
        summary.success_rate
        + summary.human_collision_rate
        + summary.wall_collision_rate
        + summary.timeout_rate
    )
    assert rates == 1.0


def test_the_data_does_not_depend_on_num_envs(tmp_path: Path) -> None:
    _, small = _collect(tmp_path, "small", num_envs=3)
    _, large = _collect(tmp_path, "large", num_envs=24)

    def by_episode(table):
        ids = column_to_numpy(table, "episode_id")
        order = np.lexsort((column_to_numpy(table, "t"), ids))
        return {name: column_to_numpy(table, name)[order] for name in ("obs", "action", "reward")}

    a, b = by_episode(small), by_episode(large)
    for name in a:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)


def test_random_actions_are_uniform_over_the_four_actions(tmp_path: Path) -> None:
    _, table = _collect(tmp_path, "u", num_envs=16, episodes=64)
    counts = np.bincount(column_to_numpy(table, "action"), minlength=4)
    share = counts / counts.sum()
    assert np.all(np.abs(share - 0.25) < 0.03), share


def _planner_collect(tmp_path: Path, name: str, epsilon: float):
    from socnav_wm.methods import method
    from socnav_wm.planning.params import PlanningParams

    env, out = EnvParams(), tmp_path / name
    planner = method("cv-mpc").policies(env, planning=PlanningParams())
    summary = collect_rollouts(
        env, episodes=24, num_envs=10, seed=3, out_dir=out, max_rows_per_shard=10_000,
        planner=planner, epsilon=epsilon,
    )  # fmt: skip
    return summary, read_rollouts(out)


def _sorted_rows(table):
    order = np.lexsort((column_to_numpy(table, "t"), column_to_numpy(table, "episode_id")))
    return {c: column_to_numpy(table, c)[order] for c in ("episode_id", "t", "action", "obs")}


def test_a_planner_with_every_action_random_gives_the_random_policys_data(tmp_path: Path) -> None:
    """The random actions and the coin are keyed by (seed, scenario, step): with ε = 1 the
    planner's waves record exactly the random policy's episodes."""
    _, random = _collect(tmp_path, "random", num_envs=7)
    _, planned = _planner_collect(tmp_path, "planned", epsilon=1.0)
    a, b = _sorted_rows(random), _sorted_rows(planned)
    for column in a:
        assert np.array_equal(a[column], b[column]), column


def test_the_planners_data_is_the_planners_episodes(tmp_path: Path) -> None:
    random, _ = _collect(tmp_path, "random", num_envs=7)
    summary, table = _planner_collect(tmp_path, "planned", epsilon=0.0)
    validate_episodes(table)
    assert sorted(np.unique(column_to_numpy(table, "episode_id"))) == list(range(24))
    # cv-mpc drives to the goal: it succeeds where the random policy wanders.
    assert summary.success_rate >= 0.8 > random.success_rate
