"""The studies' commands: ``sweep`` (a grid of agent runs as Ray tasks) and ``study-claims``
(the paper's claims with the studies' evidence)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from socnav_wm.cli.application import UserError, command
from socnav_wm.cli.options import (
    FrozenLstm,
    FrozenVae,
    SharedOptions,
    documents_option,
    path_option,
    shared_options,
)
from socnav_wm.layout import LAYOUT

ClaimsDocuments = documents_option("claims")


@command()
@shared_options("params", "set", "overlay", "no-tracking")
def sweep(
    *,
    study: Annotated[
        str | None,
        typer.Option(help="A study of params.yaml's `studies:` (its variants, seeds and grid)."),
    ] = None,
    variants: Annotated[
        str | None,
        typer.Option(help="Comma-separated variants (replace the study's), e.g. 2stepahead,maspm."),
    ] = None,
    seeds: Annotated[
        str | None, typer.Option(help="Training seeds (replace the study's): 0-4 or 0,2,7.")
    ] = None,
    grid: Annotated[
        list[str] | None,
        typer.Option(
            help="A parameter and its values, KEY=V1,V2,… (repeatable; replaces the study's grid)."
        ),
    ] = None,
    name: Annotated[
        str | None, typer.Option(help="The sweep's name (default: the study's); names its folders.")
    ] = None,
    options: SharedOptions,
    address: Annotated[
        str | None,
        typer.Option(help="A running Ray cluster (auto, HOST:PORT); default: Ray on this machine."),
    ] = None,
    cpus: Annotated[
        int | None, typer.Option(min=1, help="Local Ray's CPUs: runs at once (default: cores).")
    ] = None,
    vae: FrozenVae = LAYOUT.vae,
    lstm: FrozenLstm = LAYOUT.lstm,
    runs_dir: Annotated[
        Path | None,
        typer.Option(
            help="Every run's files and checkpoints (default: "
            f"{LAYOUT.study_run_dir('NAME').as_posix()})."
        ),
    ] = None,
    out_dir: Annotated[
        Path | None,
        typer.Option(
            help="results.parquet, summary.md, figures (default: "
            f"{LAYOUT.study_report_dir('NAME').as_posix()})."
        ),
    ] = None,
) -> None:
    """Train and evaluate a grid of agent runs (variants × seeds × parameter values) as Ray tasks,
    each exactly `train-agent --set …` then `evaluate`; finished runs are skipped, unfinished ones
    resume from their checkpoints, a failed one does not stop the others (docs/cluster.md)."""
    params = options.load()
    from socnav_wm import studies

    base = studies.named_study(params, study) if study is not None else None
    chosen = studies.study_from_options(base, variants, seeds, grid or [])
    sweep_name = name or study
    if sweep_name is None:
        raise UserError("--name: required without --study")
    plan = studies.plan_sweep(
        sweep_name,
        chosen,
        params_path=options.params_path,
        overlays=list(options.overlays),
        overrides=list(options.overrides),
        runs_dir=runs_dir,
        out_dir=out_dir,
        vae=vae,
        lstm=lstm,
    )
    outcome = studies.run_sweep(plan, address=address, cpus=cpus, tracking=options.tracking)
    typer.echo(studies.describe(outcome))
    if outcome.failed:
        first = outcome.failed[0]
        raise UserError(
            f"{len(outcome.failed)} of {len(plan.runs)} runs failed (first: {first['run']}: "
            f"{first.get('error', '')}); rerun the same command to retry them"
        )


ReportClaims = path_option("The report's claims (stage `report`).")
StudyReports = path_option("The studies' reports (each study's claims.json).")


@command("study-claims")
@shared_options("no-tracking")
def study_claims(
    options: SharedOptions,
    report_claims: ReportClaims = LAYOUT.report_claims,
    studies_dir: StudyReports = LAYOUT.study_reports,
    document: ClaimsDocuments = None,
) -> None:
    """The paper's claims, each decided by the strongest evidence present: the seeds study's
    five seeds for the training claims, the horizon study for the look-ahead claim, the report
    for the rest (stage `study_claims` of studies/dvc.yaml). Claims of other studies
    (--studies-dir not the pipeline's) go into no document unless --document names one."""
    from socnav_wm.stages import study_claims as stage

    documents = tuple(document) if document is not None else LAYOUT.studies_documents
    if document is None and studies_dir.resolve() != LAYOUT.study_reports.resolve():
        documents = ()  # docs/studies.md's claims are the pipeline's studies', not another's
    message = stage.run(
        report_claims=report_claims,
        studies_dir=studies_dir,
        documents=documents,
        **options.stage_options(),
    )
    typer.echo(message)
