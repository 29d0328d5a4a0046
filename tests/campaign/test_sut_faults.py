"""A run survives its system under test: a controller or safety layer that raises, returns
something unusable or hangs costs one recorded ``sut_error`` episode, and the run goes on;
settings that cannot work stop it with one line before anything is written."""

import time
from pathlib import Path

import pandas as pd
import pytest

from hazardhunt.campaign.config import ConfigError, EnvOptions, RunConfig
from hazardhunt.campaign.plugins import PluginSpec
from hazardhunt.campaign.run import NothingTested, record_run
from hazardhunt.sut.protocols import SafetyStatus
from hazardhunt.sut.pursuit import PursuitController
from tests.helpers import hazardhunt

HERE = "tests.campaign.test_sut_faults"
ROOT = Path(__file__).parents[2]
"""Where the command finds this module (the working directory is on a plug-in's search path)."""


class GarbageEveryOtherEpisode:
    """A pursuit controller that, from 1 s on in its first, third, ... episode, returns a string
    instead of a command."""

    control_period = 0.2

    def __init__(self):
        self.inner, self.resets = PursuitController(), 0

    def reset(self, floor, route, robot, params):
        self.resets += 1
        self.inner.reset(floor, route, robot, params)

    def control(self, time_s, robot, human):
        command = self.inner.control(time_s, robot, human)
        if self.resets % 2 == 1 and time_s >= 1.0:
            return "full speed ahead"
        return command


class Hanging(PursuitController):
    """A pursuit controller that, from 1 s on, takes a minute to answer."""

    def control(self, time_s, robot, human):
        if time_s >= 1.0:
            time.sleep(60.0)
        return super().control(time_s, robot, human)


class RaisingEveryOtherEpisode:
    """A safety layer that never stops the robot and raises from 1 s on in its first, third, ...
    episode."""

    def __init__(self):
        self.resets = 0

    def reset(self):
        self.resets += 1

    def update(self, time_s, robot, human_position, radius):
        if self.resets % 2 == 1 and time_s >= 1.0:
            raise ConnectionError("scanner unplugged")
        return SafetyStatus(emergency_stop=False, human_in_field=False)


def faulty_run(tmp_path, tester="random", tester_params=None, episodes=4, env=None, **sut):
    config = RunConfig(
        scenario="head-on",
        field="none",
        tester=tester,
        tester_params=tester_params or {},
        seed=0,
        episodes=episodes,
        env=env or EnvOptions(decision_period=1.0),
        **{key: PluginSpec(path=f"{HERE}:{name}") for key, name in sut.items()},
    )
    summary = record_run(config, tmp_path / "run")
    return summary, pd.read_parquet(tmp_path / "run" / "episodes.parquet")


@pytest.mark.parametrize(
    ("tester", "params"), [("random", {}), ("cem", {"population": 2, "elite_fraction": 0.5})]
)
def test_a_controller_returning_garbage_costs_its_episodes_and_the_run_goes_on(
    tmp_path, tester, params
):
    summary, episodes = faulty_run(tmp_path, tester, params, controller="GarbageEveryOtherEpisode")
    assert summary["episodes"] == 4
    assert summary["sut_errors"] == 2
    faulty, sound = episodes.iloc[::2], episodes.iloc[1::2]
    assert set(faulty["outcome"]) == {"sut_error"}
    assert all(
        error == "UnusableReturnError: control() returned a str ('full speed ahead'), "
        "not a ControlCommand"
        for error in faulty["controller_errors"]
    )
    # The episode after each starts clean.
    assert "sut_error" not in set(sound["outcome"])
    assert set(sound["controller_errors"]) == {""}


def test_a_safety_layer_that_raises_costs_its_episodes_and_the_run_goes_on(tmp_path):
    summary, episodes = faulty_run(tmp_path, safety_layer="RaisingEveryOtherEpisode")
    assert summary["sut_errors"] == 2
    assert episodes["outcome"].iloc[::2].tolist() == ["sut_error", "sut_error"]
    assert episodes["safety_layer_errors"].tolist() == [
        "ConnectionError: scanner unplugged",
        "",
        "ConnectionError: scanner unplugged",
        "",
    ]


@pytest.mark.slow
def test_the_time_limit_holds_in_the_worker_processes_of_a_batch(tmp_path):
    # Every episode hangs, so the run tested nothing and fails, naming the time limit.
    with pytest.raises(NothingTested, match=r"every one of its 4 episodes .* TimeLimitError: "):
        faulty_run(
            tmp_path,
            "cem",
            {"population": 2, "elite_fraction": 0.5, "n_workers": 2},
            env=EnvOptions(decision_period=1.0, controller_timeout=0.2),
            controller="Hanging",
        )


def test_a_decision_period_that_cannot_work_stops_the_run_before_it_writes(tmp_path):
    with pytest.raises(ConfigError, match=r"^decision_period \(0.3 s\) must be a multiple"):
        record_run(
            RunConfig(
                scenario="head-on",
                field="none",
                tester="random",
                seed=0,
                episodes=2,
                env=EnvOptions(decision_period=0.3),
                controller=PluginSpec(path="hazardhunt.sut.pursuit:PursuitController"),
            ),
            tmp_path / "run",
        )
    assert list(tmp_path.iterdir()) == []


def run_command(tmp_path, *options):
    return hazardhunt(
        "run", "--scenario", "head-on", "--field", "none", "--tester", "random",
        "--episodes", 2, "--out", tmp_path / "run", "--json", *options, cwd=ROOT,
    )  # fmt: skip


def test_the_command_line_sets_a_time_limit_on_the_controller(tmp_path):
    done = run_command(tmp_path, "--controller", f"{HERE}:Hanging", "--controller-timeout", 0.2)
    # The trial episode before the run finds the controller too slow: nothing is run.
    assert done.returncode == 2
    assert done.stderr.strip() == (
        f"error: controller '{HERE}:Hanging': TimeLimitError: control() took longer than its "
        "time limit of 0.2 s (on a trial episode before the run; nothing was run)"
    )


def test_a_huge_decision_period_is_one_line_and_writes_nothing(tmp_path):
    done = run_command(
        tmp_path,
        "--controller",
        "hazardhunt.sut.pursuit:PursuitController",
        "--decision-period",
        "1e9",
    )
    assert done.returncode == 2
    assert "decision_period: 1e+09 s is longer than an episode (episode_duration, 30 s)" in (
        done.stderr
    )
    assert len(done.stderr.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []
