"""The `hazardhunt run` command: smoke run, JSON summary, bad input."""

import json
from pathlib import Path

import pandas as pd
import pytest

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
    assert (summary["scenario"], summary["field"], summary["tester"]) == ("head-on", "2m", "random")
    assert summary["episodes"] == 4
    episodes = pd.read_parquet(out / "episodes.parquet")
    assert episodes["episode"].tolist() == [0, 1, 2, 3]
    assert set(episodes["outcome"]) <= {"goal", "failure", "safe_contact", "timeout", "stall"}
    assert len(pd.read_parquet(out / "failures.parquet")) == summary["failures"]
    config = json.loads((out / "config.json").read_text())
    assert config["run"]["seed"] == 3
    assert config["run"]["env"]["decision_period"] == 2.0
    # Running the same command again keeps the finished run.
    again = hazardhunt("run", *run_args(out), "--json")
    assert again.returncode == 0
    assert json.loads(again.stdout)["finished_at"] == summary["finished_at"]


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ({"scenario": "roundabout"}, "scenario: unknown scenario 'roundabout'"),
        ({"field": "3m"}, "field: unknown field '3m'"),
        ({"tester": "genetic"}, "tester: unknown tester 'genetic'"),
        ({"episodes": 0}, "episodes: Input should be greater than 0"),
        ({"tester-param": "n_envs"}, "'n_envs' is not KEY=VALUE"),
        (
            {"tester": "ppo-max", "tester-param": "n_env=2"},
            "tester_params: tester 'ppo-max': unknown parameter 'n_env'",
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
    (partial / "config.json").write_text("{}")  # what a killed run leaves behind
    done = hazardhunt("run", *run_args(out), "--json")
    assert done.returncode == 0, done.stderr
    assert not partial.exists()
    assert len(pd.read_parquet(out / "episodes.parquet")) == 4


def test_out_must_not_hold_something_else(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    done = hazardhunt("run", *run_args(tmp_path))
    assert done.returncode == 2
    assert "is not a finished run" in done.stderr
    assert (tmp_path / "notes.txt").read_text() == "mine"


def test_the_scenarios_command_draws_a_scenario_file_with_a_field_it_defines(tmp_path):
    dock = Path(__file__).parents[2] / "examples" / "loading_dock" / "dock_crossing.toml"
    done = hazardhunt("scenarios", dock, "--field", "sides", "--out", tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "dock_crossing.png").stat().st_size > 10_000


def test_the_scenarios_command_names_the_fields_there_are(tmp_path):
    done = hazardhunt("scenarios", "crossing", "--field", "wide", "--out", tmp_path)
    assert done.returncode == 2
    assert "unknown field 'wide': use one of none, 1.25m, 2m" in done.stderr
