"""Stages ``evaluate``, ``evaluate_baseline`` and the planners' (``evaluate_planner``,
``evaluate_wm_mpc``, ``evaluate_vae_lstm_mpc``): one method, greedily, on the test scenarios
(every training seed of an agent, ``experiment.seeds``)."""

from __future__ import annotations

from pathlib import Path

from socnav_wm.config import Params
from socnav_wm.evaluation.evaluate import evaluate_method, evaluation_metrics, write_evaluation
from socnav_wm.io import check_writable, outputs_together
from socnav_wm.layout import agent_file
from socnav_wm.methods import method as lookup
from socnav_wm.metrics import METRIC_UNITS
from socnav_wm.stages.common import open_stage

HEADLINE_METRICS = ("success", "human_collision", "discomfort", "simulation_time")
"""What a user compares first in MLflow (each run's description; the means, their interval
bounds are the ``*_ci_low`` / ``*_ci_high`` metrics)."""


def run(
    params: Params,
    *,
    method: str,
    agents_dir: Path,
    out_dir: Path,
    metrics_dir: Path,
    planner_files: dict[str, Path] | None = None,
    tracking: bool = True,
    quiet: bool = True,
    transfer: bool = False,
) -> str:
    kind = lookup(method, "--method").kind
    stage = {"agent": "evaluate", "robot": "evaluate_baseline", "planner": "evaluate_planner"}[kind]
    episodes_path = out_dir / f"{method}.parquet"
    trajectories_path = out_dir / f"{method}-trajectories.parquet"
    metrics_path = metrics_dir / f"{method}.json"
    if planner_files and kind != "planner":
        roles = ", ".join(f"--{role.replace('_', '-')}" for role in planner_files)
        raise ValueError(f"{roles}: only for a planner, not {method!r}")
    check_writable(episodes_path, trajectories_path, metrics_path)
    reads = [agent_file(agents_dir, method, s) for s in params.experiment.seeds] * (kind == "agent")
    files = {
        "inputs": [*reads, *(planner_files or {}).values()],
        "outputs": (episodes_path, trajectories_path, metrics_path),
    }
    with open_stage(stage, f"evaluate/{method}", params, tracking=tracking, **files) as run:
        agent_paths = None
        if kind == "agent":
            agent_paths = {s: agent_file(agents_dir, method, s) for s in params.experiment.seeds}
            for s, path in agent_paths.items():
                if not path.is_file():
                    raise FileNotFoundError(
                        f"{path}: no such agent file (train it: socnav-wm train-agent "
                        f"--variant {method} --seed {s})"
                    )
        overrides_of = None
        if kind == "robot":
            overrides_of = getattr(params.baselines, method).model_dump()
        result = evaluate_method(
            method,
            env_params=params.env,
            scenario_seed=params.eval.scenario_seed,
            episodes=params.eval.episodes,
            agent_paths=agent_paths,
            baseline_overrides=overrides_of,
            planning=params.planning if kind == "planner" else None,
            planner_files=planner_files,
            device=params.eval.device,
            batch_size=params.eval.batch_size,
            quiet=quiet,
            transfer=transfer,
        )
        with outputs_together(episodes_path, trajectories_path, metrics_path) as paths:
            write_evaluation(result, *paths)
        content = evaluation_metrics(result)
        run.set_tag("method", method)
        run.log_params({"method": method})
        if agent_paths:  # the training runs whose weights this evaluation used
            run.link_runs(
                "training_runs", [f"train-agent/{method}/seed-{s}" for s in sorted(agent_paths)]
            )
        means = {m: v["mean"] for m, v in content["metrics"].items()}
        headline = {m: means[m] for m in HEADLINE_METRICS if m in means}
        units = {m: METRIC_UNITS[m] for m in headline if METRIC_UNITS.get(m) != "0/1"}
        run.log_headline(headline, units=units)  # rates (0/1) go without a unit
        run.log_metrics({m: v for m, v in means.items() if m not in headline})
        run.log_metrics({f"{m}_ci_low": v["low"] for m, v in content["metrics"].items()})
        run.log_metrics({f"{m}_ci_high": v["high"] for m, v in content["metrics"].items()})
        run.log_metrics({"wall_time_s": result.wall_time})
        for seed_name, means in content.get("per_seed", {}).items():  # e.g. seed-0.success
            run.log_metrics({f"{seed_name}.{m}": v for m, v in means.items() if v == v})
        run.log_artifact(metrics_path)
    success = content["metrics"]["success"]
    return (
        f"wrote {episodes_path}: {method} success {success['mean']:.1%} "
        f"[{success['low']:.1%}, {success['high']:.1%}] over {result.num_scenarios} scenarios "
        f"x {len(result.training_seeds)} seed(s) in {result.wall_time:.0f} s"
    )
