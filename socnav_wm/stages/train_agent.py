"""Stage ``train_agent``: one Dueling DQN variant, one seed, on the frozen world model."""

from __future__ import annotations

import sys
from pathlib import Path

import torch

from socnav_wm.agents.agent_file import agent_from_result, greedy_episodes, save_agent
from socnav_wm.agents.checkpoint import checkpoint_file, run_identity
from socnav_wm.agents.params import check_variant
from socnav_wm.agents.served import ServedPolicy
from socnav_wm.agents.training import (
    train_agent,
    training_metrics,
    validation_seed,
    write_training_log,
)
from socnav_wm.config import Params
from socnav_wm.io import check_writable, outputs_together, write_json_atomic
from socnav_wm.layout import agent_file
from socnav_wm.stages.common import (
    config_path,
    log_torch_model,
    open_stage,
    save_stage_params,
    training_logger,
)


def run(
    params: Params,
    *,
    variant: str,
    seed: int,
    vae: Path,
    lstm: Path,
    out_dir: Path,
    log_dir: Path,
    metrics_dir: Path,
    checkpoint_dir: Path,
    resume: bool = False,
    keep_checkpoint: bool = False,
    tracking: bool = True,
    quiet: bool = True,
) -> str:
    check_variant(variant)
    name = f"{variant}/seed-{seed}"
    p = params.agent
    out = agent_file(out_dir, variant, seed)
    log = log_dir / variant / f"seed-{seed}.parquet"
    metrics = metrics_dir / variant / f"seed-{seed}.json"
    check_writable(out, config_path(out), log, metrics)
    files = {"inputs": (vae, lstm), "outputs": (out, config_path(out), log, metrics)}
    run_name = f"train-agent/{name}"
    with open_stage("train_agent", run_name, params, tracking=tracking, **files) as run:
        identity = run_identity(variant, p, params.env, seed, vae, lstm)
        checkpoint = checkpoint_file(checkpoint_dir, identity)
        if resume and checkpoint.exists():
            print(f"resuming from {checkpoint}", file=sys.stderr)
        run.set_tag("variant", variant)
        run.set_tag("training_seed", seed)
        run.log_params({"method": variant, "variant": variant, "training_seed": seed})
        result = train_agent(
            variant,
            p,
            params.env,
            vae,
            lstm,
            seed=seed,
            checkpoint_path=checkpoint,
            resume=resume,
            on_episodes=training_logger(
                run, every=max(1, min(50, p.episodes // 10)), window=p.solved_window
            ),
            quiet=quiet,
        )
        greedy = greedy_episodes(
            agent_from_result(result),
            params.env,
            seed=validation_seed(seed),
            scenario_ids=range(result.params.eval_episodes),
        )
        summary = training_metrics(result, greedy)
        with outputs_together(out, config_path(out), log, metrics) as paths:
            save_agent(paths[0], result, extra={"metrics": summary, "selection": result.selection})
            save_stage_params("train_agent", params, paths[1])
            write_training_log(result.episodes, paths[2])
            write_json_atomic(paths[3], summary)
        run.log_metrics({k: float(v) for k, v in summary.items() if v is not None})
        headline = ("greedy_success_rate", "greedy_collision_rate", "episodes_to_solve")
        run.log_headline({k: float(summary[k]) for k in headline if summary[k] is not None})
        for selection_run in result.selection:
            run.log_metrics(
                {"selection_success_rate": selection_run["success_rate"]},
                step=selection_run["episode"],
            )
        run.log_artifact(out)
        run.log_artifact(config_path(out))
        agent = agent_from_result(result)
        observations = torch.zeros(1, 2, agent.variant.obs_dim)
        log_torch_model(
            run,
            ServedPolicy(agent),
            observations,
            ("observations", "greedy_actions"),
            name=f"{variant}-seed-{seed}",
            model_type="agent",
            variable_axes=2,
        )
        if not keep_checkpoint:
            checkpoint.unlink(missing_ok=True)
    solved = summary["episodes_to_solve"]
    selected = ""
    if result.selected_episode is not None:
        selected = (
            f" (weights of episode {result.selected_episode}, best of {len(result.selection)} "
            "greedy runs on the selection scenarios)"
        )
    return (
        f"wrote {out}: greedy success {summary['greedy_success_rate']:.1%} on "
        f"{len(greedy)} validation scenarios{selected}; solved at episode {solved or 'never'}; "
        f"{result.env_steps:,} env steps, {result.updates:,} updates in "
        f"{result.wall_time / 60:.1f} min"
    )
