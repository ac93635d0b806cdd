"""The README and docs/ stay what a user reads: short, without history, their links alive, and
their results blocks where `socnav-wm report` writes them."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCUMENTS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def test_the_readme_reads_in_five_minutes() -> None:
    assert len((ROOT / "README.md").read_text(encoding="utf-8").splitlines()) <= 150


@pytest.mark.parametrize("document", DOCUMENTS, ids=lambda p: p.name)
def test_no_history_in_the_text(document: Path) -> None:
    history = re.compile(r"this round|throwaway|commit [0-9a-f]{7}", re.IGNORECASE)
    found = history.findall(document.read_text(encoding="utf-8"))
    assert not found, f"{document.name}: {found}"


@pytest.mark.parametrize("document", DOCUMENTS, ids=lambda p: p.name)
def test_relative_links_point_to_files(document: Path) -> None:
    """Links to files of the repository exist."""
    text = document.read_text(encoding="utf-8")
    for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text):
        if "://" in target:
            continue
        assert (document.parent / target).exists(), f"{document.name}: {target}"


def test_the_report_writes_into_the_readme_and_docs_evaluation() -> None:
    from socnav_wm.stages.report import RESULTS_DOCUMENTS

    for document in RESULTS_DOCUMENTS:
        text = (ROOT / document).read_text(encoding="utf-8")
        assert text.count("<!-- socnav-wm:results -->") == 1, document
        assert text.count("<!-- /socnav-wm:results -->") == 1, document
