"""The study's kept results and docs/reproduction.md agree: the document's generated part is
what scripts/reproduction.py writes from benchmarks/results/study today, so no number in it
is stale or typed by hand."""

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
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


PORTFOLIO = ROOT / "benchmarks" / "results" / "study-portfolio"


@pytest.mark.skipif(not PORTFOLIO.is_dir(), reason="no kept portfolio runs")
def test_the_portfolio_runs_arms_are_printed_and_add_up_to_each_run():
    done = subprocess.run(
        [sys.executable, "scripts/study_numbers.py", "--results", PORTFOLIO],
        cwd=ROOT, capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    for run in sorted((PORTFOLIO / "runs").iterdir()):
        summary = json.loads((run / "summary.json").read_text())
        block = done.stdout.split(run.name + "\n", 1)[1]
        arms = re.search(r"  arms \(episodes, failures\): (.*)\n", block)
        assert arms is not None, run.name
        played = re.findall(r"([\w-]+) (\d+) \((\d+)\)", arms.group(1))
        assert "unknown" not in {name for name, _, _ in played}
        assert sum(int(episodes) for _, episodes, _ in played) == summary["episodes"]
        assert sum(int(failures) for _, _, failures in played) == summary["failures"]
        assert "  first of each class: {" in block
    # Over every run: each class's failures by arm add up to its failures in the kept runs.
    failures = pd.concat(
        pd.read_parquet(run / "failures.parquet") for run in (PORTFOLIO / "runs").iterdir()
    )
    per_class = failures["class"].astype(str).value_counts()
    by_arm = done.stdout.split("failures per class and arm, over every portfolio run\n", 1)[1]
    for name, count in per_class.items():
        line = re.search(rf"  {re.escape(name)}: \{{(.*)\}}\n", by_arm)
        assert line is not None, name
        assert sum(int(n) for n in re.findall(r": (\d+)", line.group(1))) == count


@pytest.mark.slow
@pytest.mark.skipif(not PORTFOLIO.is_dir(), reason="no kept portfolio runs")
def test_the_runs_that_found_every_class_of_their_case_are_printed_as_the_document_counts_them():
    done = subprocess.run(
        [sys.executable, "scripts/study_numbers.py", "--results", KEPT, PORTFOLIO],
        cwd=ROOT, capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    reached = re.findall(r"classes; all of them: \[(.*)\]", done.stdout)
    assert len(reached) == 9
    # docs/reproduction.md, "The portfolio over the nine cases": cases where the run of seed 0
    # found every class that any run of the case found.
    counts = {
        tester: sum(f"__{tester}__seed0" in line for line in reached)
        for tester in ("portfolio", "random", "ppo-acc", "ppo-max")
    }
    assert counts == {"portfolio": 8, "random": 5, "ppo-acc": 7, "ppo-max": 6}
