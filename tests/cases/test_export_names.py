"""What ``export`` writes is what it says: names that one file name cannot tell apart get
files of their own, a requirement's name of any length gets a file name a file system takes,
and an ``--out`` that holds results is refused before anything is written."""

import json
from pathlib import Path

import pytest

from hazardhunt.textfiles import loads_toml
from tests.helpers import hazardhunt

ROOT = Path(__file__).parents[2]
PURSUIT = "hazardhunt.sut.pursuit:PursuitController"
LONG = "r" * 300
NAMES = ("a:b", "a_b", "ü", "é", LONG)
"""Requirement names: four that make two file names, and one longer than a file name can be."""


@pytest.fixture(scope="module")
def violating_run(tmp_path_factory):
    """A run of 2 episodes whose every episode violates each requirement of ``NAMES``."""
    folder = tmp_path_factory.mktemp("names")
    requirements = folder / "requirements.toml"
    formula = 'formula = "always(clearance >= 100)"'
    requirements.write_text("".join(f'[requirements."{name}"]\n{formula}\n' for name in NAMES))
    out = folder / "run"
    done = hazardhunt(
        "run", "--scenario", "head-on", "--field", "none", "--tester", "random",
        "--episodes", 2, "--out", out, "--controller", PURSUIT, "--requirement", requirements,
        cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    return out


@pytest.fixture(scope="module")
def exported(violating_run, tmp_path_factory):
    """The cases folder ``export`` wrote for ``violating_run``, and what it printed."""
    cases = tmp_path_factory.mktemp("exported") / "cases"
    done = hazardhunt("export", violating_run, "--out", cases)
    assert done.returncode == 0, done.stderr
    return cases, done.stdout


def test_requirements_whose_file_names_collide_get_a_case_each(exported):
    cases, printed = exported
    files = sorted(cases.glob("*.toml"))
    assert f"{len(files)} cases written to {cases}" in printed
    assert len(files) == len(NAMES)
    read = [loads_toml(path.read_text()) for path in files]
    assert sorted(case["requirement"]["name"] for case in read) == sorted(NAMES)
    assert all(case["name"] == path.stem for case, path in zip(read, files, strict=True))
    assert any(path.stem.endswith("__a_b-2") for path in files)


def test_a_requirement_named_longer_than_a_file_name_is_exported(exported):
    cases, _ = exported
    (case,) = [
        path for path in cases.glob("*.toml")
        if loads_toml(path.read_text())["requirement"]["name"] == LONG
    ]  # fmt: skip
    assert len(case.name) <= 130
    assert case.stem.startswith("head-on__none__random__seed0__episode1__rrrr")


@pytest.mark.parametrize("holds", ["run", "campaign", "estimate"])
def test_an_out_that_holds_results_is_refused(violating_run, tmp_path, holds):
    if holds == "run":
        out, marker = violating_run, "config.json"
    else:
        out = tmp_path / holds
        out.mkdir()
        marker = "campaign.json" if holds == "campaign" else "config.json"
        (out / marker).write_text("{}")
        if holds == "estimate":
            (out / "batches").mkdir()
    before = sorted(out.rglob("*"))
    done = hazardhunt("export", violating_run, "--out", out)
    assert done.returncode == 2
    article = "an" if holds == "estimate" else "a"
    assert done.stderr.strip() == (
        f"error: --out: {out} holds {article} {holds} ({marker}), not cases; choose another --out"
    )
    assert sorted(out.rglob("*")) == before


CAMPAIGN = """
scenarios = ["head-on"]
fields = ["none"]
testers = ["random"]
seeds = [0, 1]
episodes = 6

[controller]
path = "hazardhunt.sut.pursuit:PursuitController"
"""
"""Two runs of a cheap controller that each fail in the same episode."""


def test_runs_whose_ids_make_one_file_name_get_a_case_each(tmp_path):
    (tmp_path / "campaign.toml").write_text(CAMPAIGN)
    received = tmp_path / "received"
    done = hazardhunt("campaign", tmp_path / "campaign.toml", "--out", received, "--workers", 1)
    assert done.returncode == 0, done.stderr
    runs = sorted((received / "runs").iterdir())
    for run, run_id in zip(runs, ["..", ""], strict=True):  # as a stranger's summaries say
        summary = json.loads((run / "summary.json").read_text())
        (run / "summary.json").write_text(json.dumps(summary | {"run_id": run_id}))
    failures = sum(json.loads((run / "summary.json").read_text())["failures"] for run in runs)
    cases = tmp_path / "cases"
    done = hazardhunt("export", received, "--out", cases, "--all")
    assert done.returncode == 0, done.stderr
    files = sorted(cases.glob("*.toml"))
    assert len(files) == failures >= 2
    assert f"{failures} cases written to {cases}" in done.stdout
