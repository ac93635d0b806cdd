"""Stage ``study_claims`` (``studies/dvc.yaml``): the paper's claims, each decided by the
strongest evidence present.

The pipeline's report (stage ``report``) checks every claim on its own run: the evaluation
claims on the 500 paired test scenarios, the training claims on the pipeline's three seeds a
variant, which are too few to decide them, and not the look-ahead claim, which needs trainings
the pipeline does not run. The studies bring that evidence: ``seeds`` trains every variant on
five seeds and checks the training claims with the report's rules, ``horizon`` checks the
look-ahead claim. They take hours, so they are not upstream of the report (a plain
``dvc repro`` never starts one); this stage is downstream of both instead. For each claim it
takes the verdict of the study that checks it, where that study has run, and the report's
otherwise, and says which. It writes ``claims.md`` and ``claims.json`` beside the studies'
folders and the ``claims`` block of ``docs/studies.md``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import pyarrow.parquet as pq

from socnav_wm.evaluation.rendering import replace_marked_block
from socnav_wm.io import (
    first_line,
    outputs_together,
    read_json,
    write_json_atomic,
    write_text_atomic,
)
from socnav_wm.tracking import stage_run

HORIZON_ID = "horizon-two-steps-enough"
"""The look-ahead claim's id (the horizon study's ``claims.json`` has none)."""

HORIZON_SOURCE = "paper §3.1"

HORIZON_STATEMENT = (
    "Predicting more than 2 steps ahead does not improve the results and makes training slower"
)


def _horizon_verdict(text: str) -> str:
    """The horizon study's verdict sentence → the report's vocabulary."""
    if text.startswith("holds"):
        return "reproduced"
    if text.startswith("does not hold"):
        return "not reproduced"
    return "inconclusive"


def study_seeds(results: Path) -> str:
    """What a study's finished runs are, from its ``results.parquet``: ``5 seeds a variant``
    or, when the variants differ, ``3–5 seeds a variant``."""
    rows = pq.read_table(results, columns=["variant", "seed", "status"]).to_pylist()
    seeds: dict[str, set[int]] = {}
    for row in rows:
        if row["status"] == "done":
            seeds.setdefault(row["variant"], set()).add(row["seed"])
    counts = sorted({len(s) for s in seeds.values()}) or [0]
    shown = str(counts[0]) if len(counts) == 1 else f"{counts[0]}–{counts[-1]}"
    return f"{shown} seeds a variant"


def merge_claims(
    report: Mapping[str, Mapping[str, Any]],
    studies: Mapping[str, tuple[Any, str]],
) -> list[dict[str, Any]]:
    """Every claim with its verdict and where it comes from.

    ``report``: the report's ``claims.json`` (id → claim). ``studies``: study name → (its
    ``claims.json``, what its runs are); ``seeds`` gives a list of training claims that replace
    the report's of the same id, ``horizon`` the look-ahead claim, added after the others."""
    by_study: dict[str, tuple[dict[str, Any], str]] = {}
    if "seeds" in studies:
        found, runs = studies["seeds"]
        for claim in found:
            by_study[claim["id"]] = (claim, f"the `seeds` study, {runs}")
    merged = []
    for claim_id, claim in report.items():
        chosen, evidence = by_study.get(claim_id, (claim, "the pipeline's report"))
        merged.append(
            {
                "id": claim_id,
                "statement": claim["statement"],
                "source": claim["source"],
                "verdict": chosen["verdict"],
                "evidence": evidence,
                "checks": [f"{c['status']}: {c['evidence']}" for c in chosen["checks"]],
            }
        )
    if "horizon" in studies:
        found, runs = studies["horizon"]
        merged.append(
            {
                "id": HORIZON_ID,
                "statement": HORIZON_STATEMENT,
                "source": HORIZON_SOURCE,
                "verdict": _horizon_verdict(found["verdict"]),
                "evidence": f"the `horizon` study, {runs}",
                "checks": [line.removeprefix("- ") for line in found["comparisons"]]
                + [f"verdict: {found['verdict']}"],
            }
        )
    else:
        merged.append(
            {
                "id": HORIZON_ID,
                "statement": HORIZON_STATEMENT,
                "source": HORIZON_SOURCE,
                "verdict": "not checked",
                "evidence": "the `horizon` study has not run (`dvc repro "
                "studies/dvc.yaml:study_horizon`)",
                "checks": [],
            }
        )
    return merged


def claims_table(merged: Sequence[Mapping[str, Any]]) -> str:
    """The claims as one markdown table (the ``claims`` block of ``docs/studies.md``)."""
    lines = [
        "Each of the paper's claims with its verdict from the strongest evidence present: the "
        "`seeds` study for the training claims, the `horizon` study for the look-ahead claim, "
        "the pipeline's report (500 paired test scenarios) for the rest. Written by `socnav-wm "
        "study-claims` (`dvc repro studies/dvc.yaml:study_claims`; the checks: "
        "`reports/studies/claims.md`).",
        "",
        "| claim | verdict | evidence |",
        "|---|---|---|",
    ]
    for claim in merged:
        statement = claim["statement"].replace("|", "\\|")
        lines.append(
            f"| {statement} [{claim['source']}] | **{claim['verdict']}** | {claim['evidence']} |"
        )
    return "\n".join(lines)


def claims_markdown(merged: Sequence[Mapping[str, Any]]) -> str:
    lines = ["# The paper's claims, with the studies", "", claims_table(merged), ""]
    for claim in merged:
        lines.append(
            f"- **{claim['verdict'].upper()}**: {claim['statement']} ({claim['evidence']})"
        )
        lines += [f"  - {check}" for check in claim["checks"]]
    return "\n".join(lines).rstrip() + "\n"


def _is_study_claims(name: str, found: Any) -> bool:
    """``found`` has the shape of study ``name``'s ``claims.json``: for ``seeds`` a list of
    claims with an id, a verdict and checks (status, evidence); for ``horizon`` a verdict and
    its comparisons."""
    if name == "horizon":
        comparisons = found.get("comparisons") if isinstance(found, dict) else None
        return (
            isinstance(found, dict)
            and isinstance(found.get("verdict"), str)
            and isinstance(comparisons, list)
            and all(isinstance(line, str) for line in comparisons)
        )
    return isinstance(found, list) and all(
        isinstance(claim, dict)
        and isinstance(claim.get("id"), str)
        and isinstance(claim.get("verdict"), str)
        and isinstance(claim.get("checks"), list)
        and all(isinstance(c, dict) and {"status", "evidence"} <= c.keys() for c in claim["checks"])
        for claim in found
    )


def _study(studies_dir: Path, name: str) -> tuple[Any, str] | None:
    """A study's ``claims.json`` and what its runs are (None if it has not run).

    Raises:
        ValueError: one line naming the file: its ``claims.json`` is not readable JSON, not of
            the study's shape, or has no ``results.parquet`` beside it, or that is unreadable.
    """
    folder = studies_dir / name
    claims, results = folder / "claims.json", folder / "results.parquet"
    if not claims.exists():
        return None
    found = read_json(claims, "claims file")
    if not _is_study_claims(name, found):
        raise ValueError(f"{claims}: not the {name} study's claims (socnav-wm sweep writes them)")
    if not results.is_file():
        raise ValueError(f"{claims}: no results.parquet beside it (rerun the {name} study)")
    try:
        return found, study_seeds(results)
    except (OSError, ValueError, KeyError) as exc:
        raise ValueError(f"{results}: not a study's results ({first_line(exc)})") from None


def run(
    *,
    report_claims: Path,
    studies_dir: Path,
    documents: Sequence[Path],
    tracking: bool = True,
) -> str:
    """Merge ``report_claims`` with the studies' claims under ``studies_dir``, write
    ``studies_dir/claims.md`` and ``claims.json`` together and the ``claims`` block of each of
    ``documents``."""
    if not report_claims.is_file():
        raise FileNotFoundError(f"{report_claims}: no report claims (run `dvc repro report`)")
    report = read_json(report_claims, "claims file")
    if not isinstance(report, dict):
        raise ValueError(f"{report_claims}: not the report's claims (expected id → claim)")
    studies = {
        name: found
        for name in ("seeds", "horizon")
        if (found := _study(studies_dir, name)) is not None
    }
    merged = merge_claims(report, studies)
    table = claims_table(merged)
    texts = {
        path: replace_marked_block(path.read_text("utf-8"), "claims", table) for path in documents
    }
    with stage_run("study_claims", {"studies": sorted(studies)}, enabled=tracking) as mlflow_run:
        markdown, machine = studies_dir / "claims.md", studies_dir / "claims.json"
        with outputs_together(markdown, machine) as (markdown_tmp, machine_tmp):
            write_text_atomic(markdown_tmp, claims_markdown(merged))
            write_json_atomic(machine_tmp, merged)
        for path, text in texts.items():
            write_text_atomic(path, text)
        for claim in merged:
            mlflow_run.set_tag(f"claim.{claim['id']}", claim["verdict"])
        mlflow_run.log_artifact(markdown)
    decided = sum(claim["verdict"] != "not checked" for claim in merged)
    used = ", ".join(sorted(studies)) or "none"
    return f"wrote {markdown} ({decided} of {len(merged)} claims checked; studies: {used})"
