"""The study's kept results and docs/reproduction.md agree: the document's generated part is
what scripts/reproduction.py writes from benchmarks/results/study today, so no number in it
is stale or typed by hand."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from hazardhunt.campaign.store import find_damage

ROOT = Path(__file__).parents[2]
KEPT = ROOT / "benchmarks" / "results" / "study"
BESIDE = [ROOT / "benchmarks" / "results" / name for name in ("study-search", "study-portfolio")]
DOC = ROOT / "docs" / "reproduction.md"
BEGIN = "<!-- full-budget results: written by scripts/reproduction.py; edits here are lost -->"
END = "<!-- end of the full-budget results -->"


def generated(text: str) -> str:
    return text.partition(BEGIN)[2].partition(END)[0]


@pytest.mark.skipif(not KEPT.is_dir(), reason="no kept study results")
def test_every_kept_study_run_matches_its_checksums():
    kept = [KEPT, *(directory for directory in BESIDE if directory.is_dir())]
    runs = sorted(p for directory in kept for p in (directory / "runs").iterdir() if p.is_dir())
    assert runs
    assert {run.name: find_damage(run) for run in runs} == {run.name: None for run in runs}


@pytest.mark.skipif(not KEPT.is_dir(), reason="no kept study results")
def test_the_reproduction_document_says_what_the_kept_results_say(tmp_path):
    doc = tmp_path / "docs" / "reproduction.md"
    doc.parent.mkdir()
    shutil.copy(DOC, doc)
    done = subprocess.run(
        [sys.executable, "scripts/reproduction.py", "--doc", doc,
         "--images", tmp_path / "docs" / "images" / "study"],
        cwd=ROOT, capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert generated(doc.read_text()) == generated(DOC.read_text()), (
        "docs/reproduction.md is stale: run python scripts/reproduction.py"
    )
