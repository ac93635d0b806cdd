"""The pipeline's commands: one per stage of dvc.yaml (``collect``, ``train-vae``,
``train-lstm``, ``train-agent``, ``evaluate``, ``report``, ``predict``,
``train-planning-model``), each calling its :mod:`socnav_wm.stages` function, and ``check`` and
``deps``, which compare a rerun's metrics and the stages' source dependencies."""

from __future__ import annotations

import importlib
from collections.abc import Iterable
from pathlib import Path
from typing import Annotated, Any

import typer

from socnav_wm.cli.application import UserError, command, print_table
from socnav_wm.cli.options import (
    FrozenLstm,
    FrozenVae,
    History,
    ModelOut,
    Rollouts,
    SharedOptions,
    ValidationMetrics,
    documents_option,
    path_option,
    shared_options,
)
from socnav_wm.layout import LAYOUT

AgentsDir = path_option("Agents folder: reads {variant}/seed-{seed}.pt.")
ResultsDocuments = documents_option("results")
ScenariosDocuments = documents_option("scenarios")


def run_stage(module: str, options: SharedOptions, **arguments: Any) -> None:
    """Load the params, run :mod:`socnav_wm.stages` ``module`` with ``arguments`` (recording an
    MLflow run unless ``--no-tracking``), and print its one-line summary."""
    params = options.load()
    stage = importlib.import_module(f"socnav_wm.stages.{module}")
    typer.echo(stage.run(params, **options.stage_options(), **arguments))


Shards = path_option("Directory of Parquet shards.")
CollectMetrics = path_option("Summary metrics (JSON).")


@command()
@shared_options("params", "set", "overlay", "no-tracking", "quiet")
def collect(
    options: SharedOptions,
    out: Shards = LAYOUT.rollouts,
    metrics: CollectMetrics = LAYOUT.collect_metrics,
    policy: Annotated[
        str,
        typer.Option(
            help="random (the pipeline's), or a planner that needs no learned model (cv-mpc, "
            "oracle-mpc): the data a planning model meets when it plans."
        ),
    ] = "random",
    epsilon: Annotated[
        float,
        typer.Option(min=0.0, max=1.0, help="Under a planner: the share of random actions."),
    ] = 0.0,
) -> None:
    """Rollouts of the simulator into Parquet shards, under the random policy (stage
    `collect`) or a planner's."""
    planner = None
    if policy != "random":
        planner = (policy, _model_free_planner(policy, options, "--policy", "random or "))
    elif epsilon:
        raise UserError("--epsilon: only under a planner (--policy)")
    run_stage("collect", options, out=out, metrics=metrics, planner=planner, epsilon=epsilon)


def _model_free_planner(name: str, options: SharedOptions, option: str, other: str = "") -> Any:
    """The policies of planner ``name`` for ``option`` (``collect --policy``, ``predict
    --planner-policy``): one line when it is not a planner without model files (``other``: the
    option's other choices, for the message) or plans with other actions than the paper's four
    (what rollouts and the models' actions hold)."""
    from socnav_wm.method_names import PLANNER_NAMES
    from socnav_wm.methods import method

    chosen = [p for p in PLANNER_NAMES if not method(p).model_files]
    if name not in chosen:
        raise UserError(f"{option}: expected {other}one of {', '.join(chosen)}, got {name!r}")
    params = options.load()
    if params.planning.resolved(name).actions != "paper":
        raise UserError(
            f"{option}: the rollouts and the models hold the paper's four actions; "
            "planning.actions must be paper, not a lattice"
        )
    return method(name).configured(params.env, {"planning": params.planning})


@command("train-vae")
@shared_options("params", "set", "overlay", "threads", "no-tracking", "quiet", device="vae")
def train_vae_command(
    options: SharedOptions,
    rollouts: Rollouts = LAYOUT.rollouts,
    out: ModelOut = LAYOUT.vae,
    metrics: ValidationMetrics = LAYOUT.vae_metrics,
    history: History = LAYOUT.vae_history,
) -> None:
    """Train the VAE (23-d observation → latent) on the rollouts (stage `train-vae`)."""
    run_stage("train_vae", options, rollouts=rollouts, out=out, metrics=metrics, history=history)


@command("train-lstm")
@shared_options("params", "set", "overlay", "threads", "no-tracking", "quiet", device="lstm")
def train_lstm_command(
    options: SharedOptions,
    rollouts: Rollouts = LAYOUT.rollouts,
    vae: Annotated[Path, typer.Option(help="Trained VAE (frozen here).")] = LAYOUT.vae,
    out: ModelOut = LAYOUT.lstm,
    metrics: ValidationMetrics = LAYOUT.lstm_metrics,
    history: History = LAYOUT.lstm_history,
) -> None:
    """Train the LSTM world model on VAE latents of the rollouts (stage `train-lstm`)."""
    run_stage(
        "train_lstm", options, rollouts=rollouts, vae=vae, out=out, metrics=metrics, history=history
    )


AgentsOut = path_option("Agents folder: writes {variant}/seed-{seed}.pt.")
TrainingLogs = path_option("Training logs: writes {variant}/seed-{seed}.parquet.")
AgentMetrics = path_option("Summary metrics: writes {variant}/seed-{seed}.json.")
Checkpoints = path_option("Resumable checkpoints (one file per distinct run).")


@command("train-agent")
@shared_options("params", "set", "overlay", "threads", "no-tracking", "quiet", device="agent")
def train_agent_command(
    *,
    variant: Annotated[str, typer.Option(help="Agent variant (see `agent` in params.yaml).")],
    seed: Annotated[int, typer.Option(min=0, help="Training seed.")] = 0,
    options: SharedOptions,
    vae: FrozenVae = LAYOUT.vae,
    lstm: FrozenLstm = LAYOUT.lstm,
    out_dir: AgentsOut = LAYOUT.agents_dir,
    log_dir: TrainingLogs = LAYOUT.training_logs,
    metrics_dir: AgentMetrics = LAYOUT.agent_metrics_dir,
    checkpoint_dir: Checkpoints = LAYOUT.checkpoints,
    resume: Annotated[
        bool, typer.Option(help="Continue from this run's last checkpoint, if there is one.")
    ] = False,
    keep_checkpoint: Annotated[
        bool, typer.Option(help="Keep the checkpoint after the agent file is written.")
    ] = False,
) -> None:
    """Train one Dueling DQN variant with one seed on the frozen world model (stage
    `train-agent`)."""
    from socnav_wm.agents.params import check_variant
    from socnav_wm.section import check_seed

    check_variant(variant)
    check_seed(seed, "--seed")
    run_stage(
        "train_agent",
        options,
        variant=variant,
        seed=seed,
        vae=vae,
        lstm=lstm,
        out_dir=out_dir,
        log_dir=log_dir,
        metrics_dir=metrics_dir,
        checkpoint_dir=checkpoint_dir,
        resume=resume,
        keep_checkpoint=keep_checkpoint,
    )


def _default(path: Path) -> str:
    """``[default: path]`` in a help text (escaped: --help's markup would take it for a tag)."""
    return f"\\[default: {path.as_posix()}]"


TRANSFER_HELP = (
    "Use model files trained in another scenario (other humans' behaviour, obstacles, groups "
    "or speeds; the same observation): a transfer evaluation. Without it they are refused."
)
EvaluationOut = path_option("Writes {method}.parquet and {method}-trajectories.parquet.")
EvaluationMetrics = path_option("Writes {method}.json.")


@command()
@shared_options("params", "set", "overlay", "threads", "no-tracking", "quiet", device="eval")
def evaluate(
    *,
    method: Annotated[str, typer.Option(help="An agent variant, a baseline or a planner.")],
    options: SharedOptions,
    agents_dir: AgentsDir = LAYOUT.agents_dir,
    out_dir: EvaluationOut = LAYOUT.eval_dir,
    metrics_dir: EvaluationMetrics = LAYOUT.eval_metrics_dir,
    planning_model: Annotated[
        Path | None,
        typer.Option(help=f"wm-mpc's planning model {_default(LAYOUT.planning_model(0))}."),
    ] = None,
    vae: Annotated[
        Path | None, typer.Option(help=f"vae-lstm-mpc's VAE {_default(LAYOUT.vae)}.")
    ] = None,
    lstm: Annotated[
        Path | None, typer.Option(help=f"vae-lstm-mpc's LSTM {_default(LAYOUT.lstm)}.")
    ] = None,
    critic: Annotated[
        Path | None,
        typer.Option(
            help=f"wm-mpc-q's critic, a dueling-dqn agent {_default(LAYOUT.agent('dueling-dqn'))}."
        ),
    ] = None,
    transfer: Annotated[bool, typer.Option(help=TRANSFER_HELP)] = False,
) -> None:
    """Run one method greedily on the test scenarios: every training seed of an agent
    (`experiment.seeds`), a baseline, or a planner (cv-mpc, wm-mpc, vae-lstm-mpc, oracle-mpc,
    wm-mpc-q)
    (stages `evaluate`, `evaluate_baseline`, `evaluate_planner`, `evaluate_wm_mpc`,
    `evaluate_vae_lstm_mpc`)."""
    from socnav_wm.method_names import check_method

    check_method(method, "--method")
    run_stage(
        "evaluate",
        options,
        method=method,
        agents_dir=agents_dir,
        out_dir=out_dir,
        metrics_dir=metrics_dir,
        planner_files={
            role: path
            for role, path in (
                ("planning_model", planning_model),
                ("vae", vae),
                ("lstm", lstm),
                ("critic", critic),
            )
            if path is not None
        },
        transfer=transfer,
    )


@command()
@shared_options("params", "set", "overlay", "no-tracking")
def report(
    options: SharedOptions,
    eval_dir: Annotated[Path, typer.Option(help="Evaluation files.")] = LAYOUT.eval_dir,
    training_dir: Annotated[Path, typer.Option(help="Training logs.")] = LAYOUT.training_logs,
    out_dir: Annotated[Path, typer.Option(help="Report folder.")] = LAYOUT.reports,
    metrics: Annotated[
        Path, typer.Option(help="Machine-readable summary (JSON).")
    ] = LAYOUT.report_metrics,
    document: ResultsDocuments = None,
) -> None:
    """Table, paired tests, Pareto set, figures and the paper's claims checked; the results
    table also goes into the results blocks of README.md and docs/evaluation.md (stage
    `report`), or of the --document files. A report of other evaluations (--eval-dir or
    --out-dir not the pipeline's) writes no block unless --document names one."""
    documents = tuple(document) if document is not None else None
    if documents is None and (eval_dir != LAYOUT.eval_dir or out_dir != LAYOUT.reports):
        documents = ()  # the README's table is the pipeline's, not another set's
    run_stage(
        "report", options,
        eval_dir=eval_dir, training_dir=training_dir, out_dir=out_dir, metrics=metrics,
        documents=documents, prediction=LAYOUT.prediction_metrics,
    )  # fmt: skip


@command("scenarios-report")
@shared_options("params", "set", "overlay", "no-tracking")
def scenarios_report(
    options: SharedOptions,
    presets_dir: Annotated[
        Path, typer.Option(help="The presets: one overlay {preset}.yaml each.")
    ] = LAYOUT.scenario_presets,
    metrics_dir: Annotated[
        Path, typer.Option(help="Reads {preset}/{method}.json.")
    ] = LAYOUT.scenario_metrics,
    episodes_dir: Annotated[
        Path, typer.Option(help="Reads {preset}/{method}.parquet (the paired gaps).")
    ] = LAYOUT.scenario_episodes,
    out: Annotated[Path, typer.Option(help="The table (markdown).")] = LAYOUT.scenarios_report,
    summary: Annotated[Path, typer.Option(help="The table (JSON).")] = (
        LAYOUT.scenario_metrics / "summary.json"
    ),
    document: ScenariosDocuments = None,
) -> None:
    """Every non-learning method in every scenario preset: success and collisions with their
    intervals, `oracle-mpc` − `cv-mpc` paired, CrowdNav's published rows side by side (stage
    `scenarios_report` of scenarios/dvc.yaml); the table also goes into the scenarios block of
    docs/scenarios.md, or of the --document files (none when --metrics-dir is another)."""
    if document is not None:
        documents = tuple(document)
    elif metrics_dir != LAYOUT.scenario_metrics:
        documents = ()  # the docs' table is the pipeline's, not another set's
    else:
        documents = tuple(p for p in LAYOUT.scenarios_documents if p.is_file())
    run_stage(
        "scenarios_report", options,
        presets_dir=presets_dir, metrics_dir=metrics_dir, episodes_dir=episodes_dir, out=out,
        summary=summary, documents=documents,
    )  # fmt: skip


@command()
@shared_options("params", "set", "overlay", "no-tracking", "threads")
def predict(
    options: SharedOptions,
    vae: Annotated[Path, typer.Option(help="The VAE file.")] = LAYOUT.vae,
    lstm: Annotated[Path, typer.Option(help="The LSTM file.")] = LAYOUT.lstm,
    agent: Annotated[
        Path | None,
        typer.Option(help="Agent file of the ε-greedy policy (default: dueling-dqn seed 0)."),
    ] = LAYOUT.prediction_agent,
    agent_policy: Annotated[
        bool,
        typer.Option(
            help="Measure under --agent's ε-greedy policy too; --no-agent-policy: under the "
            "random policy only (a preset without agents of its own)."
        ),
    ] = True,
    planning_model: Annotated[
        list[Path] | None,
        typer.Option(
            help="A planning world model file (repeat: one per training seed; default: "
            f"{LAYOUT.planning_dir.as_posix()}/seed-S.pt for each of planning_model.seeds)."
        ),
    ] = None,
    out: Annotated[Path, typer.Option(help="The errors (JSON).")] = LAYOUT.prediction_metrics,
    figure: Annotated[Path, typer.Option(help="Error against k (PNG).")] = LAYOUT.prediction_figure,
    transfer: Annotated[bool, typer.Option(help=TRANSFER_HELP)] = False,
    world_model: Annotated[
        bool,
        typer.Option(
            help="Measure the paper's world model (--vae, --lstm); --no-world-model: only the "
            "planning models and the baselines (a preset without a VAE + LSTM of its own)."
        ),
    ] = True,
    planner_policy: Annotated[
        str | None,
        typer.Option(
            help="Measure under this planner's ε-greedy policy too (cv-mpc, oracle-mpc): the "
            "situations a planning model meets when it plans."
        ),
    ] = None,
) -> None:
    """k-step prediction errors in metres of the world model (VAE + LSTM) and the planning world
    model's seeds beside copy-last, static humans and constant velocity (the robot's own motion
    exact), under the random policy and a trained agent's ε-greedy one, open loop with the true
    actions; the settings are params.yaml's `prediction` section."""
    params = options.load()
    from socnav_wm.evaluation.model_sections import PREDICTION_KS
    from socnav_wm.stages import predict as stage

    if planning_model is None:
        planning_model = [LAYOUT.planning_model(s) for s in params.planning_model.seeds]
    planner = None
    if planner_policy is not None:
        planner = (
            planner_policy,
            _model_free_planner(planner_policy, options, "--planner-policy"),
        )
    result = stage.run(
        params,
        vae=vae if world_model else None,
        lstm=lstm if world_model else None,
        agent=agent if agent_policy else None,
        planning_models=planning_model,
        out=out,
        figure=figure,
        transfer=transfer,
        planner=planner,
        **options.stage_options(),
    )
    for title, rows, formats in stage.tables(result, PREDICTION_KS):
        print_table(rows, title, formats)
    typer.echo(f"wrote {out} and {figure}")


CollectedRollouts = path_option("The rollouts (collect's output).")
PlanningOut = path_option("Where seed-N.pt is written.")
PlanningMetrics = path_option("Where seed-N.json is written.")


@command("train-planning-model")
@shared_options("params", "set", "overlay", "threads", "no-tracking", "quiet")
def train_planning_model(
    options: SharedOptions,
    seed: Annotated[
        int, typer.Option(min=0, help="Training seed (one of planning_model.seeds).")
    ] = 0,
    rollouts: CollectedRollouts = LAYOUT.rollouts,
    out_dir: PlanningOut = LAYOUT.planning_dir,
    metrics_dir: PlanningMetrics = LAYOUT.planning_metrics_dir,
) -> None:
    """Train the planning world model (socnav_wm/worldmodel/residual.py: constant velocity plus a
    learned correction of each human's velocity) on the rollouts (stage `train_planning_model`,
    params.yaml's planning_model). Its k-step errors are measured by `socnav-wm predict`."""
    run_stage(
        "train_planning_model", options,
        seed=seed, rollouts=rollouts, out_dir=out_dir, metrics_dir=metrics_dir,
    )  # fmt: skip


@command()
def check(
    rerun: Annotated[
        Path,
        typer.Argument(help=f"{LAYOUT.eval_metrics_dir.as_posix()} of a rerun (another clone)."),
    ],
    committed: Annotated[
        Path, typer.Option(help="The committed evaluation metrics.")
    ] = LAYOUT.eval_metrics_dir,
) -> None:
    """Compare a rerun's test metrics with the committed ones: each mean within the other's 95%
    interval (what reproduces across machines), or identical (same CPU, build and threads)."""
    from socnav_wm.evaluation.reproduce import compare_runs

    checks = compare_runs(committed, rerun)
    rows = [
        {
            "method": c.method,
            "metric": c.metric,
            "committed": f"{c.committed['mean']:.4g} [{c.committed['low']:.4g}, "
            f"{c.committed['high']:.4g}]",
            "rerun": f"{c.rerun['mean']:.4g} [{c.rerun['low']:.4g}, {c.rerun['high']:.4g}]",
            "verdict": "identical" if c.identical else "agrees" if c.agrees else "DIFFERS",
        }
        for c in checks
    ]
    print_table(rows, f"socnav-wm check {rerun} against {committed}", {})
    differs = sum(not c.agrees for c in checks)
    typer.echo(f"{len(checks) - differs} of {len(checks)} agree within the 95% intervals")
    for name in _one_training(c.method for c in checks if not c.agrees):
        typer.echo(
            f"{name}: plans with one training of its model files; its interval counts the test "
            "scenarios only, not that training's chance (docs/reproducibility.md)"
        )
    if differs:
        raise typer.Exit(code=1)


def _one_training(names: Iterable[str]) -> list[str]:
    """The planners among ``names`` that read model files: one training of them, whatever the
    seeds (an agent's interval counts its training seeds too)."""
    from socnav_wm.methods import METHODS

    chosen = set(names)
    return [
        name
        for name, entry in METHODS.items()
        if name in chosen and entry.kind == "planner" and entry.model_files
    ]


@command()
def deps(
    check: Annotated[
        list[Path] | None,
        typer.Option(
            help="Compare with this dvc.yaml (repeatable: dvc.yaml, studies/dvc.yaml); exit 1 "
            "if a stage's deps differ."
        ),
    ] = None,
    write: Annotated[
        list[Path] | None,
        typer.Option(help="Rewrite the source deps of this dvc.yaml's stages (repeatable)."),
    ] = None,
) -> None:
    """Each stage's source dependencies: the import closure of its module (what dvc.yaml and
    studies/dvc.yaml list)."""
    from socnav_wm.stages.deps import dvc_yaml_differences, stage_dependencies, write_dvc_yaml

    if write:
        for path in write:
            changed = write_dvc_yaml(path)
            typer.echo(f"{path}: {'updated' if changed else 'already up to date'}")
        return

    if check:
        problems = [line for path in check for line in dvc_yaml_differences(path)]
        for line in problems:
            typer.echo(line, err=True)
        if problems:
            raise typer.Exit(code=1)
        files = ", ".join(map(str, check))
        typer.echo(f"{files}: every stage lists exactly the sources it executes")
        return
    for stage, files in stage_dependencies().items():
        typer.echo(f"{stage}:")
        for path in files:
            typer.echo(f"  - {path}")
