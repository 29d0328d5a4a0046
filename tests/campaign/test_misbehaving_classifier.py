"""A failure classifier of one's own that raises ``SystemExit``: a run records the failure's
class as ``other`` with the error, and ``report`` and ``export``, which stopped silently with
exit 0, stop in one line naming it."""

import json
from pathlib import Path

import pytest

from hazardhunt.campaign.config import PluginSpec, RunConfig
from hazardhunt.campaign.run import record_run
from tests.helpers import hazardhunt

ROOT = Path(__file__).parents[2]
EXITING = "tests.misbehaving:ExitingClassifier"
SAYS = f"failure classifier '{EXITING}': classify() raised SystemExit: 0 ("


@pytest.fixture(scope="module")
def failing_run(tmp_path_factory):
    """A run of 8 episodes with two failures (head-on, no field, the pursuit controller)."""
    config = RunConfig(
        scenario="head-on",
        field="none",
        tester="random",
        seed=0,
        episodes=8,
        controller=PluginSpec(path="hazardhunt.sut.pursuit:PursuitController"),
    )
    directory = tmp_path_factory.mktemp("failing") / "run"
    summary = record_run(config, directory)
    assert summary["failures"] > 0
    return directory


@pytest.mark.parametrize("command", ["report", "export"])
def test_report_and_export_with_a_classifier_that_exits_stop_in_one_line(
    tmp_path, failing_run, command
):
    out = ("--out", tmp_path / "cases") if command == "export" else ()
    done = hazardhunt(command, failing_run, *out, "--classifier", EXITING, cwd=ROOT)
    assert done.returncode == 1, done.stderr
    [line] = done.stderr.strip().splitlines()
    assert line.startswith(f"error: {SAYS}")
    assert "misbehaving.py, line" in line
    assert not (tmp_path / "cases").exists()
    assert not (failing_run / "report").exists()


def test_a_run_records_a_classifier_that_exits_and_goes_on(tmp_path):
    config = RunConfig(
        scenario="head-on",
        field="none",
        tester="random",
        seed=0,
        episodes=8,
        controller=PluginSpec(path="hazardhunt.sut.pursuit:PursuitController"),
        classifier=PluginSpec(path=EXITING),
    )
    summary = record_run(config, tmp_path / "run")
    assert summary["classifier_errors"] == summary["failures"] > 0
    assert summary["first_classifier_error"]["error"].startswith(f"ClassifierExitError: {SAYS}")
    assert json.loads((tmp_path / "run" / "summary.json").read_text())["classes"] == ["other"]
