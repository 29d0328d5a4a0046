"""A campaign run that failed (it tested nothing) never reads as a pass afterwards: the
campaign's table counts its SUT errors; report and export name it with its error and exit 1;
copy copies the rest and names it as failed, not as unfinished; and when every run failed,
report and export say so instead of "not finished yet"."""

import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from hazardhunt.benchmark.conservative import ConservativeController
from tests.helpers import hazardhunt

HERE = "tests.campaign.test_failed_runs"
ROOT = Path(__file__).parents[2]
"""Where the command finds this module (the working directory is on a plug-in's search path)."""

LOST = "every one of its 4 episodes ended in a SUT error, so it tested nothing"
"""What the error of a run whose every episode erred says."""


class LostInTheCrossing(ConservativeController):
    """Drives the head-on scenario; in the crossing, where the human starts south of the aisle,
    raises as soon as the human moves (so its trial episode, a human standing still, passes)."""

    def reset(self, floor, route, robot, params):
        self.in_the_crossing = None
        super().reset(floor, route, robot, params)

    def control(self, time_s, robot, human):
        if human is not None:
            if self.in_the_crossing is None:
                self.in_the_crossing = bool(human.position[1] < 7.5)
            steps = np.diff(human.recent_positions, axis=0)
            if self.in_the_crossing and np.abs(steps).max(initial=0.0) > 1e-6:
                raise RuntimeError("lost the localisation")
        return super().control(time_s, robot, human)


CAMPAIGN = f"""
scenarios = {{scenarios}}
fields = ["none"]
testers = ["random"]
seeds = [0]
episodes = 4

[controller]
path = "{HERE}:LostInTheCrossing"
"""


def campaign(folder: Path, scenarios: list[str]) -> tuple[Path, subprocess.CompletedProcess[str]]:
    """The campaign directory of ``CAMPAIGN`` on ``scenarios``, and the campaign command."""
    file = folder / "campaign.toml"
    file.write_text(CAMPAIGN.format(scenarios=json.dumps(scenarios)))
    out = folder / "results"
    return out, hazardhunt("campaign", file, "--out", out, cwd=ROOT)


def crossing_row(table: str) -> list[str]:
    """The cells of the crossing's row of the campaign's table."""
    [row] = [line for line in table.splitlines() if "crossing" in line and "│" in line]
    return [cell.strip() for cell in row.strip("│ ").split("│")]


@pytest.fixture(scope="module")
def one_failed(
    tmp_path_factory: pytest.TempPathFactory,
) -> tuple[Path, subprocess.CompletedProcess[str]]:
    """A campaign whose head-on run completed and whose crossing run tested nothing."""
    return campaign(tmp_path_factory.mktemp("one-failed"), ["head-on", "crossing"])


def test_the_campaign_table_counts_the_sut_errors_of_the_run_that_failed(one_failed):
    _, done = one_failed
    assert done.returncode == 1
    assert crossing_row(done.stdout)[:6] == ["crossing", "none", "random", "0/1", "-", "4"]
    assert "warning: 4 episodes ended in a SUT error and tested nothing" in done.stdout
    assert "runs that failed: 1" in done.stdout


def test_a_report_names_the_failed_run_first_and_exits_1(one_failed):
    results, _ = one_failed
    done = hazardhunt("report", results)
    assert done.returncode == 1
    assert "report written to" in done.stdout
    failed, error = done.stderr.strip().splitlines()
    assert failed.startswith("failed: crossing__none__random__seed0: NothingTested: every ")
    assert LOST in failed
    assert error == (
        "error: 1 run of the campaign failed, so the report covers only the runs that "
        "completed; run the campaign again to retry it (errors above and in summary.json)"
    )
    page = (results / "report" / "index.html").read_text()
    verdict = page[page.index("<h2>Verdict") :]
    headline = re.sub(r"<[^>]+>", "", verdict[: verdict.index("No unsafe failure")])
    assert "1 run of the campaign failed and is not in this verdict" in headline
    assert "Run crossing__none__random__seed0 failed: NothingTested:" in verdict
    assert "has not finished" not in page
    summary = json.loads((results / "report" / "summary.json").read_text())
    assert list(summary["failed_runs"]) == ["crossing__none__random__seed0"]
    assert summary["unfinished_runs"] == []
    assert summary["verdict"]["failed_runs"] == 1


def test_an_export_names_the_failed_run_and_exits_1(one_failed, tmp_path):
    results, _ = one_failed
    done = hazardhunt("export", results, "--out", tmp_path / "cases")
    assert done.returncode == 1
    assert "0 cases written" in done.stdout
    assert "the runs that completed hold no failure" in done.stdout  # not "the results"
    assert LOST in done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("error: 1 run of the campaign failed, so the cases cover only the runs")


def test_a_copy_says_the_run_failed_and_its_report_still_does(one_failed, tmp_path):
    results, _ = one_failed
    copy = tmp_path / "kept"
    done = hazardhunt("copy", results, "--out", copy)
    assert done.returncode == 0, done.stderr
    assert "1 run copied, 0 already there, 1 failed (nothing to copy), 0 not finished yet" in (
        done.stdout
    )
    assert done.stderr.startswith("failed: crossing__none__random__seed0: NothingTested: ")
    report = hazardhunt("report", copy)
    assert report.returncode == 1
    assert LOST in report.stderr


def test_when_every_run_failed_report_and_export_say_why(tmp_path):
    out, done = campaign(tmp_path, ["crossing"])
    assert done.returncode == 1
    assert crossing_row(done.stdout)[3:6] == ["0/1", "-", "4"]
    for command in (("report", out), ("export", out, "--out", tmp_path / "cases")):
        done = hazardhunt(*command)
        assert done.returncode == 1
        said = done.stderr.strip()
        assert said.startswith(
            f"error: {out}: no run of the campaign is complete: run "
            "crossing__none__random__seed0 failed (NothingTested: "
        )
        assert LOST in said
        assert said.count("crossing__none__random__seed0") == 1  # the error says it once
        assert "finished yet" not in said

    # A run that has simply not run yet is still called so.
    summary = json.loads((out / "summary.json").read_text())
    summary["runs"][0] = {key: summary["runs"][0][key] for key in ("run_id", "scenario")} | {
        "status": "pending"
    }
    (out / "summary.json").write_text(json.dumps(summary))
    done = hazardhunt("report", out)
    assert done.returncode == 2
    assert done.stderr.strip() == f"error: {out}: no run of the campaign has finished yet"


def test_a_ledger_that_does_not_read_leaves_failed_runs_in_doubt_not_unfinished(
    one_failed, tmp_path
):
    results, _ = one_failed
    broken = tmp_path / "broken"
    shutil.copytree(results, broken)
    (broken / "summary.json").write_text("{not json")
    doubt = "1 run of the campaign has not finished, and may have failed: the campaign's ledger"

    report = hazardhunt("report", broken)
    assert report.returncode == 0, report.stderr
    assert doubt in report.stderr
    page = (broken / "report" / "index.html").read_text()
    assert "Some may have failed: the campaign&#39;s ledger cannot tell" in page

    copy = hazardhunt("copy", broken, "--out", tmp_path / "kept")
    assert copy.returncode == 0, copy.stderr
    assert "the campaign's ledger is not copied, and runs not finished may have failed" in (
        copy.stderr
    )
    assert "1 run copied" in copy.stdout
    assert not (tmp_path / "kept" / "summary.json").exists()

    # With no run complete, it says that it cannot tell, not that nothing has finished yet.
    shutil.rmtree(broken / "runs" / "head-on__none__random__seed0")
    report = hazardhunt("report", broken)
    assert report.returncode == 2
    assert report.stderr.startswith(
        f"error: {broken}: no run of the campaign has finished, and its ledger cannot tell "
        "which failed: "
    )


def test_a_copy_reads_a_ledger_of_the_wrong_shape_as_data(one_failed, tmp_path):
    results, _ = one_failed
    odd = tmp_path / "odd"
    shutil.copytree(results, odd)
    entries = [
        1,
        {"run_id": 5},
        {"status": "failed"},
        {"run_id": "head-on__none__random__seed0", "status": "complete", "episodes": "4"},
    ]
    (odd / "summary.json").write_text(json.dumps({"runs": entries}))
    first = hazardhunt("copy", odd, "--out", tmp_path / "kept")
    again = hazardhunt("copy", odd, "--out", tmp_path / "kept")  # reads the copy's ledger too
    assert (first.returncode, again.returncode) == (0, 0), first.stderr + again.stderr
    assert "Traceback" not in first.stderr + again.stderr
