"""Stage ``collect``: rollouts of the simulator into Parquet shards, under the random policy
(the pipeline's) or a planner's (``planner``: its name and policies, built by the caller)."""

from __future__ import annotations

from pathlib import Path

from socnav_wm.config import Params
from socnav_wm.data.collect import PlannerFactory, collect_rollouts
from socnav_wm.env.observation_layout import observation_size
from socnav_wm.io import check_writable, outputs_together, write_json_atomic
from socnav_wm.progress import progress
from socnav_wm.resources import check_disk
from socnav_wm.stages.common import open_stage, save_stage_params


def run(
    params: Params,
    *,
    out: Path,
    metrics: Path,
    tracking: bool = True,
    quiet: bool = True,
    planner: tuple[str, PlannerFactory] | None = None,
    epsilon: float = 0.0,
) -> str:
    c = params.collect
    check_writable(out, metrics, folders=(out,))
    # Every episode at its longest, every value of a row uncompressed: an upper bound.
    row_bytes = 8 * (2 * observation_size(params.env.num_humans) + 8 + 2 * params.env.num_humans)
    most = c.episodes * params.env.max_steps * row_bytes
    check_disk("collect.episodes", most, out.parent, f"{c.episodes:,} episodes")
    with open_stage("collect", "collect", params, tracking=tracking, outputs=(out, metrics)) as run:
        # The whole directory appears at once, with its metrics: a killed run never leaves a
        # partial dataset.
        with (
            outputs_together(out, metrics) as (staging, metrics_tmp),
            progress(c.episodes, "collect", quiet=quiet, unit="episodes") as bar,
        ):
            summary = collect_rollouts(
                params.env,
                episodes=c.episodes,
                num_envs=c.num_envs,
                seed=params.seed,
                out_dir=staging,
                max_rows_per_shard=c.max_rows_per_shard,
                on_episodes=bar.advance,
                planner=None if planner is None else planner[1],
                epsilon=epsilon,
            )
            save_stage_params("collect", params, staging / "params.yaml")
            policy = {} if planner is None else {"policy": planner[0], "epsilon": epsilon}
            write_json_atomic(metrics_tmp, {**summary.as_metrics(), **policy})
        run.log_metrics(summary.as_metrics())
        if planner is not None:
            run.log_params(policy)
        run.log_artifact(out / "params.yaml")
    under = "" if planner is None else f" under {planner[0]} (ε = {epsilon:g})"
    return (
        f"wrote {summary.episodes} episodes{under}, {summary.steps} steps in "
        f"{len(summary.shards)} shard(s) to {out} ({summary.steps / summary.seconds:,.0f} steps/s)"
    )
