"""A tester of one's own that ends the process, raises what is not an ``Exception`` or plays
actions that are not numbers: a run that fails in one line naming it, nothing of it kept; a
portfolio arm that does so is dropped; the user's Ctrl-C still interrupts."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hazardhunt.campaign.config import PluginSpec, RunConfig
from hazardhunt.campaign.records import RunFailed
from hazardhunt.campaign.run import execute_run_atomically, partial_directory
from tests.helpers import hazardhunt

ROOT = Path(__file__).parents[2]
HERE = "tests.campaign.test_misbehaving_testers"
MISBEHAVING = "tests.misbehaving"
CHEAP = "hazardhunt.benchmark.conservative:ConservativeController"


def run(tmp_path, tester, *params, episodes=3):
    return hazardhunt(
        "run", "--scenario", "head-on", "--field", "none", "--episodes", episodes,
        "--out", tmp_path / "run", "--controller", CHEAP, "--tester", tester,
        *(option for param in params for option in ("--tester-param", param)), cwd=ROOT,
    )  # fmt: skip


def assert_one_line_and_nothing_kept(done, tmp_path, says):
    assert done.returncode == 1, done.stderr
    [line] = done.stderr.strip().splitlines()
    assert line.startswith("error: run head-on__none__tests.misbehaving_")
    assert says in line
    assert line.endswith("; nothing of the run was kept")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("error", ["SystemExit(0)", "SystemExit(7)", "KeyboardInterrupt"])
def test_a_tester_that_exits_fails_the_run_in_one_line_naming_it(tmp_path, error):
    # It used to end `run` silently with exit 0 (or 7), or as if the user had pressed Ctrl-C.
    done = run(tmp_path, f"{MISBEHAVING}:ThrowingTester", f'error="{error}"', "first=1")
    raised = error.replace("(", ": ").rstrip(")")
    says = f"tester '{MISBEHAVING}:ThrowingTester' raised {raised} ("
    assert_one_line_and_nothing_kept(done, tmp_path, says)
    assert "misbehaving.py, line" in done.stderr
    assert "interrupted" not in done.stderr


@pytest.mark.parametrize("error", ["GeneratorExit", "BaseException"])
def test_a_tester_that_raises_what_is_no_exception_fails_the_run(tmp_path, error):
    config = RunConfig(
        scenario="head-on",
        field="none",
        seed=0,
        episodes=3,
        controller=PluginSpec(path=CHEAP),
        tester="throwing",
        tester_plugin=PluginSpec(path=f"{MISBEHAVING}:ThrowingTester", params={"error": error}),
    )
    out = tmp_path / "run"
    with pytest.raises(RunFailed, match=f"ThrowingTester' raised {error}"):
        execute_run_atomically(config, out)
    assert not out.exists()
    assert not partial_directory(out).exists()


@pytest.mark.parametrize(
    ("params", "action"),
    [(('value="nan"',), "[nan, 0.0]"), (('value="inf"', 'how="step"'), "[inf, 0.0]")],
)
def test_a_tester_whose_actions_are_not_finite_fails_the_run_not_plays_it(tmp_path, params, action):
    # A NaN action used to be played as a human standing still, and counted as a tested,
    # safe episode.
    done = run(tmp_path, f"{MISBEHAVING}:NonFiniteTester", *params)
    says = (
        f"tester '{MISBEHAVING}:NonFiniteTester' played an unusable action: the "
        f"human's action is {action}, not two finite numbers (speed, turn rate)"
    )
    assert_one_line_and_nothing_kept(done, tmp_path, says)


def test_a_search_whose_decisions_are_not_finite_fails_the_run(tmp_path):
    done = run(tmp_path, f"{MISBEHAVING}:NonFiniteSearch")
    says = "played an unusable action: proposed decisions that are not all finite"
    assert_one_line_and_nothing_kept(done, tmp_path, says)


@pytest.mark.parametrize(
    ("method", "dropped"),
    [
        ("ExitingSearch", "SystemExit: 0"),
        ("NonFiniteSearch", "UnusableActionError: proposed decisions that are not all finite"),
    ],
)
def test_a_portfolio_arm_that_exits_or_proposes_nan_is_dropped(tmp_path, method, dropped):
    # An arm's SystemExit used to end the run (silently, with exit 0, from the command line).
    arms = [
        {"name": "bad", "method": f"{MISBEHAVING}:{method}"},
        {"name": "uniform", "method": "uniform", "params": {"batch_size": 2}},
    ]
    config = RunConfig(
        scenario="head-on",
        field="none",
        seed=0,
        episodes=4,
        controller=PluginSpec(path=CHEAP),
        tester="portfolio",
        tester_params={"arms": arms},
    )
    with pytest.warns(RuntimeWarning, match="portfolio arm 'bad' .*and was dropped"):
        summary = execute_run_atomically(config, tmp_path / "run")
    assert summary["episodes"] == 4
    record = json.loads((tmp_path / "run" / "tester" / "portfolio.json").read_text())
    played = record["arms_played"]
    assert played["bad"]["dropped"].startswith(dropped)
    assert played["bad"]["episodes"] == 0
    assert played["uniform"]["episodes"] == 4


def test_a_campaigns_tester_that_exits_is_recorded_once_not_retried(tmp_path):
    # Its worker process used to die of it, three times, each with a long traceback, and the
    # run was recorded as a worker that "exited with code 7".
    campaign = tmp_path / "campaign.toml"
    campaign.write_text(
        'scenarios = ["head-on"]\nfields = ["none"]\ntesters = ["exits"]\nseeds = [0]\n'
        f'episodes = 3\n[controller]\npath = "{CHEAP}"\n'
        f'[tester.exits]\npath = "{MISBEHAVING}:ThrowingTester"\nerror = "SystemExit(7)"\n'
    )
    done = hazardhunt("campaign", campaign, "--out", tmp_path / "out", cwd=ROOT)
    assert done.returncode == 1, done.stderr
    assert "attempt" not in done.stdout + done.stderr
    assert "Traceback" not in done.stdout + done.stderr
    [entry] = json.loads((tmp_path / "out" / "summary.json").read_text())["runs"]
    assert entry["status"] == "failed"
    assert entry["error"].startswith(
        f"RunFailed: tester '{MISBEHAVING}:ThrowingTester' raised SystemExit: 7 ("
    )
    assert list((tmp_path / "out" / "runs").iterdir()) == []


class Waiting:
    """A tester that says it has started exploring, then waits: the user's Ctrl-C comes
    while the tester's own code runs."""

    name = "waiting"

    def __init__(self, seed, started):
        self.started = started

    def explore(self, env, episodes):
        Path(self.started).touch()
        time.sleep(120)

    def save(self, directory):
        pass


@pytest.mark.skipif(sys.platform == "win32", reason="SIGINT")
def test_ctrl_c_while_a_testers_code_runs_still_interrupts_the_run(tmp_path):
    started = tmp_path / "started"
    command = [
        sys.executable, "-m", "hazardhunt.cli", "run", "--scenario", "head-on", "--field",
        "none", "--episodes", "3", "--out", str(tmp_path / "run"), "--controller", CHEAP,
        "--tester", f"{HERE}:Waiting", "--tester-param", f'started="{started}"',
    ]  # fmt: skip
    process = subprocess.Popen(
        command, cwd=ROOT, stderr=subprocess.PIPE, text=True, env=os.environ | {"COLUMNS": "1000"}
    )
    try:
        deadline = time.monotonic() + 60
        while not started.exists():
            assert process.poll() is None, process.stderr
            assert time.monotonic() < deadline
            time.sleep(0.1)
        process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=60)
    finally:
        process.kill()
    assert process.returncode == 130
    assert stderr.strip().startswith("interrupted: run the same command again to resume")
    assert not (tmp_path / "run").exists()


def test_a_keyboard_interrupt_a_controller_raises_itself_is_its_error_not_ctrl_c(tmp_path):
    # It used to end the run as if the user had pressed Ctrl-C (exit 130, "interrupted").
    done = hazardhunt(
        "run", "--scenario", "head-on", "--field", "none", "--episodes", 2, "--tester", "random",
        "--out", tmp_path / "run", "--controller", f"{MISBEHAVING}:InterruptingController",
        cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip() == (
        f"error: controller '{MISBEHAVING}:InterruptingController': control() raised "
        "KeyboardInterrupt (on a trial episode before the run; nothing was run)"
    )


@pytest.mark.slow
def test_a_keyboard_interrupt_a_controller_raises_in_a_worker_process_is_a_sut_error(tmp_path):
    done = hazardhunt(
        "run", "--scenario", "head-on", "--field", "none", "--episodes", 4, "--tester", "cem",
        "--tester-param", "workers=2", "--tester-param", "population=4", "--out",
        tmp_path / "run", "--controller", f"{MISBEHAVING}:InterruptingController",
        "--controller-param", "after=3.0", cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 1, done.stderr
    [line] = done.stderr.strip().splitlines()
    assert "every one of its 4 episodes ended in a SUT error" in line
    assert "KeyboardInterrupt" in line
    assert "interrupted" not in done.stderr
