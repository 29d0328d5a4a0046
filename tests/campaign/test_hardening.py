"""Plug-ins that exit, classifiers that misbehave, numbers no clock can hold, grids that name a
run twice: each is an error that says why, or a recorded outcome, never a silent exit or a
traceback."""

import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hazardhunt.testers.evaluator import Plan
from hazardhunt.testers.search import SearchTester, SpaceParams
from tests.helpers import hazardhunt

HERE = "tests.campaign.test_hardening"
ROOT = Path(__file__).parents[2]
PURSUIT = "hazardhunt.sut.pursuit:PursuitController"


class ExitingLayer:
    """A safety layer that ends the process it runs in."""

    def reset(self):
        pass

    def update(self, time_s, robot, human_position, radius):
        raise SystemExit(0)


class ExitingOnBuild:
    """A controller whose constructor ends the process."""

    control_period = 0.2

    def __init__(self):
        raise SystemExit(0)


class NumberClassifier:
    """Names every failure with a number."""

    name = "numbers"

    def classes_for(self, field):
        return ("one", "other")

    def classify(self, trajectory, summary, field):
        return 1


class RaisingClassifier(NumberClassifier):
    def classify(self, trajectory, summary, field):
        raise ValueError("no face")


class BrokenSampler:
    """A sampler of one's own whose ``tell`` raises."""

    def __init__(self, params, context):
        self.space, self.horizon = params.space.decision_spaces[0], context.horizon

    def ask(self):
        return [Plan(self.space, np.zeros((self.horizon, self.space.size)))]

    def tell(self, plans, results):
        raise ZeroDivisionError("the arm's own bug")

    def record(self):
        return {}


class BrokenSearch(SearchTester):
    name = "broken"
    params_model = SpaceParams

    def make_sampler(self, context):
        return BrokenSampler(self.params, context)


def run(tmp_path, *options, episodes=6):
    return hazardhunt(
        "run", "--scenario", "head-on", "--field", "none", "--tester", "random",
        "--episodes", episodes, "--out", tmp_path / "run", "--json", *options, cwd=ROOT,
    )  # fmt: skip


def test_a_safety_layer_that_exits_is_one_line_not_a_silent_exit(tmp_path):
    done = run(tmp_path, "--safety-layer", f"{HERE}:ExitingLayer")
    assert done.returncode == 2
    assert done.stdout == ""
    assert done.stderr.strip() == (
        f"error: safety layer '{HERE}:ExitingLayer': update() raised SystemExit: 0 (on a trial "
        "episode before the run; nothing was run)"
    )
    assert not (tmp_path / "run").exists()


def test_a_controller_that_exits_while_built_is_one_line(tmp_path):
    done = run(tmp_path, "--controller", f"{HERE}:ExitingOnBuild")
    assert done.returncode == 2
    assert "building the controller raised SystemExit: 0" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize(
    ("classifier", "error"),
    [
        ("NumberClassifier", "TypeError: classify() returned 1, not a class name (str)"),
        ("RaisingClassifier", "ValueError: no face"),
    ],
)
def test_a_classifier_that_fails_costs_the_failure_its_class_not_the_run(
    tmp_path, classifier, error
):
    done = run(
        tmp_path, "--controller", PURSUIT, "--classifier", f"{HERE}:{classifier}", episodes=8
    )
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert summary["failures"] > 0
    assert summary["classifier_errors"] == summary["failures"]
    assert summary["first_classifier_error"]["error"] == error
    failures = pd.read_parquet(tmp_path / "run" / "failures.parquet")
    assert set(failures["class"]) == {"other"}
    report = hazardhunt("report", tmp_path / "run")
    assert report.returncode == 0, report.stderr
    # In a pipe, the report's one line and nothing before it (no progress bar's empty line).
    assert report.stdout.startswith("report written to ")


def test_the_summary_table_says_the_classifier_failed(tmp_path):
    done = hazardhunt(
        "run", "--scenario", "head-on", "--field", "none", "--tester", "random",
        "--episodes", 8, "--out", tmp_path / "run", "--controller", PURSUIT,
        "--classifier", f"{HERE}:RaisingClassifier", cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "warning: the failure classifier failed on" in done.stdout
    assert "ValueError: no face" in done.stdout


@pytest.mark.parametrize("timeout", ["1e10", "1e12"])
def test_a_time_limit_no_timer_can_hold_is_refused_when_read(tmp_path, timeout):
    done = run(tmp_path, "--controller", PURSUIT, "--controller-timeout", timeout)
    assert done.returncode == 2
    assert "controller_timeout" in done.stderr
    assert "less than or equal to 86400" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(
    ("key", "value"),
    [("testers", '["random", "random"]'), ("fields", '["none", "2m", "none"]')],
)
def test_a_grid_that_names_a_run_twice_is_refused(tmp_path, key, value):
    grid = {
        "scenarios": '["head-on"]',
        "fields": '["none"]',
        "testers": '["random"]',
        "seeds": "[0]",
        "episodes": "2",
    }
    grid[key] = value
    campaign = tmp_path / "campaign.toml"
    campaign.write_text("".join(f"{k} = {v}\n" for k, v in grid.items()))
    done = hazardhunt("campaign", campaign, "--out", tmp_path / "out")
    assert done.returncode == 2
    assert f"{key}: " in done.stderr
    assert "is given twice" in done.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
@pytest.mark.skipif(sys.platform != "linux", reason="workers die with their parent on Linux")
@pytest.mark.parametrize("tester", ["cem", "qd"])
def test_a_killed_run_leaves_no_worker_process(tmp_path, tester):
    from tests.campaign.test_campaign import live_processes_in_group

    command = [
        sys.executable, "-m", "hazardhunt.cli", "run", "--scenario", "head-on",
        "--field", "none", "--tester", tester, "--tester-param", "workers=2",
        "--episodes", "400", "--out", str(tmp_path / "run"), "--controller", PURSUIT,
    ]  # fmt: skip
    run = subprocess.Popen(
        command, start_new_session=True, cwd=ROOT,
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 120
        while len(live_processes_in_group(run.pid)) < 3:  # the run and its two workers
            assert run.poll() is None, "the run ended before its workers started"
            assert time.monotonic() < deadline
            time.sleep(0.1)
        os.kill(run.pid, signal.SIGKILL)
        run.wait()
        deadline = time.monotonic() + 10
        while live_processes_in_group(run.pid) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert live_processes_in_group(run.pid) == []
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(run.pid, signal.SIGKILL)


DEEP = "[" * 5_000 + "]" * 5_000


def test_toml_nested_too_deeply_is_one_line_wherever_it_is_read(tmp_path):
    case = tmp_path / "case.toml"
    case.write_text(f"format = 1\nhuman = {DEEP}\n")
    regressed = hazardhunt("regress", case)
    assert regressed.returncode == 2
    assert "not valid TOML: arrays or tables nested too deeply" in regressed.stderr
    scenario = tmp_path / "deep.toml"
    scenario.write_text(f"robot = {DEEP}\n")
    ran = hazardhunt(
        "run", "--scenario", scenario, "--field", "none", "--tester", "random",
        "--episodes", 2, "--out", tmp_path / "run",
    )  # fmt: skip
    assert ran.returncode == 2
    assert "nested too deeply" in ran.stderr
    param = run(tmp_path, "--controller", PURSUIT, "--tester-param", f"batch_size={DEEP}")
    assert param.returncode == 2
    assert "--tester-param: batch_size: arrays or tables nested too deeply" in param.stderr
    for done in (regressed, ran, param):
        assert "Traceback" not in done.stderr
        assert len(done.stderr.strip().splitlines()) == 1


def test_names_that_look_like_mathtext_are_drawn_as_text(tmp_path):
    out = tmp_path / "run"
    done = hazardhunt(
        "run", "--scenario", "head-on", "--field", "none", "--tester", "$\\frac{$",
        "--tester-param", "method=random", "--episodes", 6, "--out", out,
        "--controller", PURSUIT, "--classifier", f"{HERE}:DollarClassifier", cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    report = hazardhunt("report", out)
    assert report.returncode == 0, report.stderr
    assert "Traceback" not in report.stderr


class DollarClassifier(NumberClassifier):
    """Names every failure ``$\\frac{$``."""

    def classes_for(self, field):
        return ("$\\frac{$", "other")

    def classify(self, trajectory, summary, field):
        return "$\\frac{$"


def test_a_negative_seed_for_scenarios_is_a_usage_error(tmp_path):
    done = hazardhunt("scenarios", "--seed", "-1", "--out", tmp_path / "pictures")
    assert done.returncode == 2
    assert "Traceback" not in done.stderr
    assert "--seed" in done.stderr


@pytest.fixture(scope="module")
def pursuit_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("pursuit") / "run"
    done = hazardhunt(
        "run", "--scenario", "head-on", "--field", "none", "--tester", "random",
        "--episodes", 6, "--out", out, "--controller", PURSUIT, cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    return out


@pytest.mark.parametrize(
    ("config", "problem"),
    [
        ("[1, 2", "config.json: cannot be read as JSON: "),
        ('{"run": {"scenario": 5}}', "config.json: not a run's configuration: run.scenario: "),
        ("[]", "config.json: not a run's configuration (no run table)"),
    ],
)
def test_an_invalid_config_json_is_one_line_for_replay_and_export(
    pursuit_run, tmp_path, config, problem
):
    received = tmp_path / "received"
    shutil.copytree(pursuit_run, received)
    (received / "config.json").write_text(config)
    summary = json.loads((received / "summary.json").read_text())
    del summary["checksums"]  # as for a run recorded before checksums
    (received / "summary.json").write_text(json.dumps(summary))
    episode = int(pd.read_parquet(received / "failures.parquet")["episode"][0])
    for command in (
        ["replay", received, "--episode", episode],
        ["export", received, "--out", tmp_path / "cases"],
    ):
        done = hazardhunt(*command)
        assert done.returncode == 2, command
        assert "Traceback" not in done.stderr
        assert len(done.stderr.strip().splitlines()) == 1
    replayed = hazardhunt("replay", received, "--episode", episode)
    assert problem in replayed.stderr


@pytest.mark.parametrize(
    ("change", "problem"),
    [
        (
            lambda failures: failures.assign(max_risk=float("nan")),
            "failures.parquet: max_risk holds a value that is not a finite number",
        ),
        (
            lambda failures: failures.drop(columns="contact_face"),
            "failures.parquet lacks the column contact_face",
        ),
        (
            lambda failures: failures.assign(**{"class": 5}),
            "failures.parquet: class holds a value that is not text",
        ),
        (
            lambda failures: failures.assign(episode=-3),
            "failures.parquet: episode holds a value that is not a whole number from 0",
        ),
        (
            lambda failures: failures.assign(episode=10**6),
            "failures.parquet: episode 1000000 is not an episode of episodes.parquet",
        ),
    ],
)
def test_a_received_table_without_its_numbers_or_columns_is_named_damaged(
    pursuit_run, tmp_path, change, problem
):
    from hazardhunt.campaign.store import file_checksums

    received = tmp_path / "received"
    shutil.copytree(pursuit_run, received)
    failures = pd.read_parquet(received / "failures.parquet")
    change(failures).to_parquet(received / "failures.parquet", index=False)
    summary = json.loads((received / "summary.json").read_text())
    summary["checksums"] = file_checksums(received)  # made that way, checksums and all
    (received / "summary.json").write_text(json.dumps(summary))
    done = hazardhunt("report", received)
    assert done.returncode == 2
    assert done.stderr.strip() == (
        f"error: {received}: the run is damaged ({problem}); run it again"
    )


class Short:
    """A tester that plays two episodes, whatever its budget."""

    name = "short"

    def __init__(self, seed):
        self.seed = seed

    def explore(self, env, episodes):
        for _ in range(2):
            env.reset(seed=self.seed)
            done = False
            while not done:
                _, _, terminated, truncated, _ = env.step(env.action_space.sample())
                done = terminated or truncated

    def save(self, directory):
        directory.mkdir(parents=True, exist_ok=True)


def test_a_tester_that_plays_less_than_its_budget_fails_its_run(tmp_path):
    done = hazardhunt(
        "run", "--scenario", "head-on", "--field", "none", "--tester", f"{HERE}:Short",
        "--episodes", 5, "--out", tmp_path / "run", "--controller", PURSUIT, cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 1
    assert "its tester played 2 episodes of a budget of 5" in done.stderr
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(
    ("option", "value", "problem"),
    [
        ("--robot", "length=1e6", "length must be at most 10"),
        ("--robot", "max_speed=true", "robot.max_speed: must be a number, not true"),
        ("--robot", 'max_speed="1.1"', 'robot.max_speed: must be a number, not "1.1"'),
        ("--robot", "bogus=1", "robot.bogus: unknown key"),
        ("--seed", "5000000000", "seed: must be less than or equal to 4294967295"),
        ("--stall-duration", "1e-300", "stall_duration: must be greater than or equal"),
        ("--field", "3m", "unknown field '3m': use one of none, 1.25m, 2m"),
    ],
)
def test_values_no_robot_or_clock_can_hold_are_refused_in_one_line(
    tmp_path, option, value, problem
):
    done = hazardhunt(
        "run", "--scenario", "head-on", "--field", "none", "--tester", "random",
        "--episodes", 2, "--out", tmp_path / "run", option, value,
    )  # fmt: skip
    assert done.returncode == 2
    assert done.stderr.strip() == f"error: {problem}" or (
        problem in done.stderr and len(done.stderr.strip().splitlines()) == 1
    )
    assert "2m, none" not in done.stderr  # the field settings are listed once


@pytest.mark.parametrize("key", ["diameter", "standstill_speed"])
@pytest.mark.parametrize("value", ["true", '"1.25"'])
def test_a_field_size_that_is_not_a_number_is_refused_not_converted(tmp_path, key, value):
    done = hazardhunt(
        "run", "--scenario", "head-on", "--field", "none", "--episodes", 2,
        "--out", tmp_path / "run", "--controller", PURSUIT,
        "--safety-layer", "hazardhunt.sut.safety_layer:LaserSafetyLayer",
        "--safety-layer-param", f"{key}={value}",
    )  # fmt: skip
    assert done.returncode == 2
    [line] = done.stderr.strip().splitlines()
    assert f"{key} must be a number, not {value}" in line
    assert not (tmp_path / "run").exists()


def test_an_out_on_a_file_system_that_cannot_hold_it_is_bad_input(tmp_path):
    done = hazardhunt(
        "run", "--scenario", "head-on", "--field", "none", "--tester", "random",
        "--episodes", 2, "--out", "/proc/hazardhunt-run", "--controller", PURSUIT,
    )  # fmt: skip
    assert done.returncode == 2
    assert done.stderr.startswith("error: --out: cannot write in /proc")


def test_a_run_whose_summary_was_deleted_is_run_again(pursuit_run, tmp_path):
    out = tmp_path / "run"
    shutil.copytree(pursuit_run, out)
    (out / "summary.json").unlink()
    done = hazardhunt(
        "run", "--scenario", "head-on", "--field", "none", "--tester", "random",
        "--episodes", 6, "--out", out, "--controller", PURSUIT, cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "unfinished (no summary.json); running it again" in done.stderr
    assert (out / "summary.json").is_file()


def test_copy_on_a_full_disk_says_so_in_one_short_line(pursuit_run, tmp_path, monkeypatch):
    import errno

    from hazardhunt.campaign import store

    def full(source, destination, **_):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), destination)

    monkeypatch.setattr(shutil, "copyfile", full)  # a fault: the disk is full
    with pytest.raises(OSError, match="files could not be copied") as raised:
        store.copy_run(pursuit_run, tmp_path / "kept")
    message = str(raised.value)
    assert "files could not be copied; the first:" in message
    assert len(message) < 400
    assert not list(tmp_path.glob(".kept.partial"))


BROKEN_ARM_CAMPAIGN = (
    'scenarios = ["crossing"]\nfields = ["none"]\ntesters = ["portfolio"]\nseeds = [0]\n'
    f'episodes = 6\n[controller]\npath = "{PURSUIT}"\n[tester.portfolio]\narms = [\n'
    f'  {{ name = "broken", method = "{HERE}:BrokenSearch" }},\n'
    '  { name = "uniform", method = "uniform", params = { batch_size = 2 } },\n]\n'
)


def test_an_arm_dropped_in_a_campaign_worker_is_one_line_naming_the_run(tmp_path):
    campaign = tmp_path / "campaign.toml"
    campaign.write_text(BROKEN_ARM_CAMPAIGN)
    done = hazardhunt("campaign", campaign, "--out", tmp_path / "out", cwd=ROOT)
    assert done.returncode == 0, done.stderr
    [warned] = [line for line in done.stderr.splitlines() if "dropped" in line]
    assert warned == (
        "warning: crossing__none__portfolio__seed0: portfolio arm 'broken' raised and was "
        "dropped: ZeroDivisionError: the arm's own bug"
    )
    assert "portfolio.py" not in done.stderr  # not Python's two lines with the source


@pytest.mark.parametrize("executor", ["local", pytest.param("ray", marks=pytest.mark.slow)])
def test_a_campaign_process_shows_its_workers_warnings(executor, tmp_path, capsys, monkeypatch):
    # A worker writing to the terminal itself breaks the progress bars drawn there (and a Ray
    # worker's output never reaches it); the campaign process shows the line instead.
    from hazardhunt.campaign.campaign import run_campaign
    from hazardhunt.campaign.config import load_campaign

    monkeypatch.setenv("PYTHONPATH", str(ROOT))  # Ray's workers import the broken arm
    campaign = tmp_path / "campaign.toml"
    campaign.write_text(BROKEN_ARM_CAMPAIGN)
    summary = run_campaign(load_campaign(campaign), tmp_path / "out", executor=executor)
    assert summary["runs_complete"] == 1
    assert capsys.readouterr().err.splitlines() == [
        "warning: crossing__none__portfolio__seed0: portfolio arm 'broken' raised and was "
        "dropped: ZeroDivisionError: the arm's own bug"
    ]
