"""The `hazardhunt run` command: smoke run, JSON summary, bad input."""

import io
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
from PIL import Image
from rich.console import Console

import hazardhunt as hazardhunt_package
from hazardhunt.campaign import run as run_module
from hazardhunt.campaign.config import RunConfig
from hazardhunt.world.scenario import load_scenario
from tests.helpers import hazardhunt

SUMMARY_KEYS = {
    "scenario",
    "field",
    "tester",
    "seed",
    "episodes",
    "failures",
    "safe_contacts",
    "stalls",
    "wall_time_s",
    "cpu_time_s",
    "episodes_per_s",
}


def run_args(out, **overrides):
    options = {"scenario": "head-on", "field": "2m", "tester": "random", "episodes": 4, "seed": 3}
    options |= overrides
    args = []
    for key, value in options.items():
        args += [f"--{key}", value]
    return [*args, "--out", out]


def test_a_run_writes_tables_pandas_reads_and_a_json_summary(tmp_path):
    out = tmp_path / "run"
    done = hazardhunt("run", *run_args(out), "--json")
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert set(summary) >= SUMMARY_KEYS
    assert summary["cpu_time_s"] > 0
    assert (summary["scenario"], summary["field"], summary["tester"]) == ("head-on", "2m", "random")
    assert summary["episodes"] == 4
    episodes = pd.read_parquet(out / "episodes.parquet")
    assert episodes["episode"].tolist() == [0, 1, 2, 3]
    assert set(episodes["outcome"]) <= {"goal", "failure", "safe_contact", "timeout", "stall"}
    assert len(pd.read_parquet(out / "failures.parquet")) == summary["failures"]
    config = json.loads((out / "config.json").read_text())
    assert config["run"]["seed"] == 3
    assert config["run"]["env"]["decision_period"] == 2.0
    # The BLAS kernel numpy picked for this CPU: a search through BLAS draws by it.
    assert config["blas"] == hazardhunt_package.blas_kernel() != "unknown"
    # Running the same command again keeps the finished run.
    again = hazardhunt("run", *run_args(out), "--json")
    assert again.returncode == 0
    assert json.loads(again.stdout)["finished_at"] == summary["finished_at"]


def test_a_run_without_scenario_and_field_runs_the_studys_main_case(tmp_path):
    done = hazardhunt(
        "run", "--tester", "random", "--episodes", 2, "--out", tmp_path / "run", "--json"
    )
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert (summary["scenario"], summary["field"], summary["episodes"]) == ("crossing", "1.25m", 2)


def test_a_run_that_found_failures_names_their_classes_and_how_to_see_them(tmp_path):
    out = tmp_path / "run"
    done = hazardhunt("run", *run_args(out, scenario="overtaking", seed=0, episodes=6))
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["failures"] > 0
    first = summary["first_failure_episode"]
    said = (
        f"failure classes found: {summary['classes_found']} of {summary['classes_total']} "
        f"({', '.join(summary['classes'])}); first failure: episode {first}. To see it: "
        f"hazardhunt replay {out} --episode {first} --gif failure.gif"
    )
    assert said in done.stdout


def test_a_run_that_found_no_failure_does_not_read_as_a_pass(tmp_path):
    out = tmp_path / "run"
    done = hazardhunt("run", *run_args(out))
    assert done.returncode == 0, done.stderr
    assert json.loads((out / "summary.json").read_text())["failures"] == 0
    said = " ".join(done.stdout.split())
    assert "no unsafe failure found in 4 episodes: none in this budget, not a proof" in said
    assert "failure classes found" not in said


def test_a_run_in_a_log_file_writes_lines_not_a_cut_off_bar(tmp_path, monkeypatch):
    monkeypatch.setattr(run_module, "LOG_INTERVAL_S", 0.0)
    log = io.StringIO()
    config = RunConfig(scenario="head-on", field="2m", tester="random", seed=3, episodes=4)
    run_module.execute_run(config, tmp_path / "run", Console(file=log, width=80))
    lines = log.getvalue().splitlines()
    last = r"head-on__2m__random__seed3: 4 of 4 episodes, \d+ failures, [\d.]+ episodes/s"
    assert re.fullmatch(last, lines[-1]), lines
    assert not any("━" in line or "…" in line for line in lines)


def test_a_runs_cpu_time_counts_the_processes_it_started_once_they_end():
    from hazardhunt.campaign.records import cpu_seconds

    before = cpu_seconds()
    burn = "import time\nend = time.process_time() + 0.5\nwhile time.process_time() < end: pass"
    subprocess.run([sys.executable, "-c", burn], check=True)
    assert cpu_seconds() - before >= 0.5


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ({"scenario": "roundabout"}, "scenario: unknown scenario 'roundabout'"),
        ({"field": "3m"}, "field: unknown field '3m'"),
        ({"tester": "genetic"}, "tester: unknown tester 'genetic'"),
        ({"episodes": 0}, "episodes: must be greater than 0"),
        ({"tester-param": "n_envs"}, "'n_envs' is not KEY=VALUE"),
        (
            {"tester": "cem", "tester-param": 'space={kind="aim"'},
            'space: {kind="aim" does not read as TOML (Unclosed inline table)',
        ),
        (
            {"tester": "ppo-max", "tester-param": "n_env=2"},
            "tester_params.n_env: unknown parameter",
        ),
        # Settings that passed the first check and failed once the run had started.
        ({"decision-period": 0.07}, "env.decision_period: 0.07 s is not a whole multiple"),
        ({"decision-period": 0.3}, "env.decision_period: 0.3 s is not a whole multiple"),
        ({"decision-period": "inf"}, "decision_period: must be a finite number"),
        ({"decision-period": "1e9"}, "decision_period: 1e+09 s is longer than an episode"),
        ({"tester-param": "attemps=3"}, "tester_params.attemps: unknown parameter"),
        ({"tester-param": "attempts=many"}, "tester_params.attempts: must be a whole number"),
        (
            {"tester": "ppo-max", "tester-param": "learning_rate=-1"},
            "tester_params.learning_rate: must be a number in (0, 1], not -1",
        ),
        ({"tester": "ppo-max", "tester-param": "n_steps=0"}, "tester_params.n_steps: must be"),
        ({"tester": "ppo-max", "tester-param": "n_steps=1"}, "tester_params.n_steps: n_steps x"),
        (
            {"tester": "ppo-max", "tester-param": "batch_size=0"},
            "tester_params.batch_size: must be a whole number >= 2, not 0",
        ),
        (
            {"tester": "ppo-max", "tester-param": "gamma=5"},
            "tester_params.gamma: must be a number in (0, 1], not 5",
        ),
        (
            {"tester": "ppo-max", "tester-param": "n_envs=1000"},
            "tester_params.n_envs: must be a whole number from 1 to 64, not 1000",
        ),
    ],
)
def test_bad_input_is_one_clear_line_and_writes_nothing(tmp_path, override, message):
    out = tmp_path / "run"
    done = hazardhunt("run", *run_args(out, **override))
    assert done.returncode == 2
    assert message in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_a_run_killed_midway_is_redone_from_scratch(tmp_path):
    out = tmp_path / "run"
    partial = tmp_path / ".run.partial"
    partial.mkdir()
    (partial / "config.json").write_text("{}")  # what a killed run leaves behind,
    (tmp_path / ".run.lock").write_text("999999999\n")  # and the file of its lock
    done = hazardhunt("run", *run_args(out), "--json")
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]
    assert len(pd.read_parquet(out / "episodes.parquet")) == 4


def test_out_must_not_hold_something_else(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    done = hazardhunt("run", *run_args(tmp_path))
    assert done.returncode == 2
    assert "is not a finished run" in done.stderr
    assert (tmp_path / "notes.txt").read_text() == "mine"
    # A campaign's folder (its campaign.json) is named as one, not as a damaged run.
    (tmp_path / "campaign.json").write_text("{}")
    (tmp_path / "summary.json").write_text("{}")
    done = hazardhunt("run", *run_args(tmp_path))
    assert done.returncode == 2
    assert done.stderr.strip() == (
        f"error: {tmp_path}: holds a campaign, not a run; choose another --out"
    )
    assert sorted(path.name for path in tmp_path.iterdir()) == [
        "campaign.json", "notes.txt", "summary.json"
    ]  # fmt: skip


def test_the_scenarios_command_draws_a_scenario_file_with_a_field_it_defines(tmp_path):
    dock = Path(__file__).parents[2] / "examples" / "loading_dock" / "dock_crossing.toml"
    done = hazardhunt("scenarios", dock, "--field", "sides", "--out", tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "dock_crossing.png").stat().st_size > 10_000
    with Image.open(tmp_path / "dock_crossing.png") as picture:  # the dock is 16 m x 10 m
        assert 1.4 < picture.width / picture.height < 1.8


def test_the_scenarios_command_checks_every_name_before_drawing_any(tmp_path):
    done = hazardhunt("scenarios", "crossing", "bogus", "--out", tmp_path / "pictures")
    assert done.returncode == 2
    [line] = done.stderr.strip().splitlines()
    assert "bogus: no such scenario file" in line
    assert not (tmp_path / "pictures").exists()


def test_the_scenarios_command_names_the_fields_there_are(tmp_path):
    done = hazardhunt("scenarios", "crossing", "--field", "wide", "--out", tmp_path)
    assert done.returncode == 2
    assert "unknown field 'wide': use one of none, 1.25m, 2m" in done.stderr


SHOPFLOOR = Path(load_scenario("head-on").source).parent / "shopfloor.toml"

SCENARIO = f"""\
name = "mine"
map = "{SHOPFLOOR}"
[robot]
start = {{ x = 2.0, y = 10.0, heading_deg = 0.0 }}
goal = {{ x = 18.0, y = 10.0 }}
[human]
start = {{ x = 10.0, y = 5.0, heading_deg = 90.0 }}
"""


@pytest.mark.parametrize(
    ("change", "key"),
    [
        pytest.param(
            ("heading_deg = 90.0", "heading_deg = nan"),
            "human.start.heading_deg: must be a finite number",
            id="nan-heading",
        ),
        pytest.param(
            ("y = 10.0, heading", "y = inf, heading"),
            "robot.start.y: must be a finite number",
            id="inf-position",
        ),
        pytest.param(
            ("goal = { x = 18.0, y = 10.0 }", "goal = { x = 5.0, y = 8.8 }"),
            "robot.goal: the robot cannot get there: route point (5.00, 8.80) lies within",
            id="unreachable-goal",
        ),
        pytest.param(
            ("x = 10.0, y = 5.0", "x = 2.3, y = 10.2"),
            "human.start: (2.3, 10.2) touches the robot at its start: every episode would begin",
            id="human-touching-the-robot",
        ),
        pytest.param(
            ("x = 10.0, y = 5.0", "x = 8.6, y = 7.0"),
            "human.start: (8.6, 7) overlaps an obstacle (the human is a disc of radius 0.25 m)",
            id="human-overlapping-a-shelf",
        ),
        pytest.param(
            ("[human]", "[fields.wide]\ndiameter = inf\n[human]"),
            "fields.wide.diameter: diameter must be a positive number of m, not inf",
            id="inf-field-diameter",
        ),
    ],
)
def test_a_scenario_value_that_cannot_work_is_one_line_before_anything_is_written(
    tmp_path, change, key
):
    scenario = tmp_path / "files" / "mine.toml"
    scenario.parent.mkdir()
    scenario.write_text(SCENARIO.replace(*change))
    out = tmp_path / "results" / "run"
    done = hazardhunt("run", *run_args(out, scenario=scenario))
    assert done.returncode == 2
    [line] = done.stderr.strip().splitlines()
    assert f"{scenario}: {key}" in line
    assert not (tmp_path / "results").exists()


def test_the_scenarios_command_names_what_is_wrong_with_a_scenario_file(tmp_path):
    unreachable = tmp_path / "unreachable.toml"
    unreachable.write_text(
        SCENARIO.replace("goal = { x = 18.0, y = 10.0 }", "goal = { x = 5.0, y = 8.8 }")
    )
    touching = tmp_path / "touching.toml"
    touching.write_text(SCENARIO.replace("x = 10.0, y = 5.0", "x = 2.3, y = 10.2"))
    for scenario, says in (
        (unreachable, "robot.goal: the robot cannot get there: route point (5.00, 8.80)"),
        (touching, "human.start: (2.3, 10.2) touches the robot at its start"),
    ):
        done = hazardhunt("scenarios", scenario, "--out", tmp_path / "pictures")
        assert done.returncode == 2
        [line] = done.stderr.strip().splitlines()
        assert f"{scenario}: {says}" in line
    assert not (tmp_path / "pictures").exists()


def test_an_out_that_cannot_be_written_is_one_line(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    done = hazardhunt("run", *run_args(tmp_path / "notes.txt" / "run"))
    assert done.returncode == 2
    [line] = done.stderr.strip().splitlines()
    assert f"--out: {tmp_path / 'notes.txt'} is a file, not a directory" in line
    read_only = tmp_path / "read-only"
    read_only.mkdir(mode=0o555)
    if os.access(read_only, os.W_OK):
        # Permissions do not stop root (as in CI); a file system that takes no files does.
        read_only = Path("/sys")
        if not read_only.is_dir():
            pytest.skip("root may write anywhere here, and there is no /sys")
    done = hazardhunt("run", *run_args(read_only / "run"))
    assert done.returncode == 2
    [line] = done.stderr.strip().splitlines()
    assert f"--out: cannot write in {read_only}" in line
    assert not (read_only / "run").exists()


def test_a_corrupt_config_of_a_finished_run_is_one_line(tmp_path):
    out = tmp_path / "run"
    assert hazardhunt("run", *run_args(out)).returncode == 0
    (out / "config.json").write_text('{"run": {"scenario": "head-on", ')
    done = hazardhunt("run", *run_args(out))
    assert done.returncode == 2
    [line] = done.stderr.strip().splitlines()
    assert line.startswith(f"error: {out}: holds a damaged run (config.json ")
    assert "delete it or choose another --out" in line


def test_ctrl_c_says_the_run_was_interrupted_and_how_to_resume(tmp_path):
    out = tmp_path / "run"
    command = [
        sys.executable,
        "-m",
        "hazardhunt.cli",
        "run",
        *map(str, run_args(out, episodes=10_000)),
    ]
    environment = os.environ | {"COLUMNS": "1000"}
    with subprocess.Popen(
        command,
        stderr=subprocess.PIPE,
        text=True,
        env=environment,
        # As in a terminal, whatever started the tests (a shell's background job ignores it).
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    ) as process:
        try:
            started = tmp_path / ".run.partial" / "config.json"
            deadline = time.monotonic() + 120
            while not started.exists() and process.poll() is None and time.monotonic() < deadline:
                time.sleep(0.1)
            assert started.exists(), "the run did not start"
            process.send_signal(signal.SIGINT)
            _, stderr = process.communicate(timeout=60)
        finally:
            process.kill()  # a run that ignored Ctrl-C must not hold the test for its whole length
    assert process.returncode == 130
    assert "Traceback" not in stderr
    assert "interrupted: run the same command again to resume" in stderr.strip().splitlines()[-1]
