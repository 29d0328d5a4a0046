"""A run that tested nothing never looks like a pass: a plug-in that fails on a trial episode
stops the command before anything is written (exit 2); a run whose every episode ended in a
SUT error fails (exit 1) with the first error in one line; SUT errors below that show in the
summary, the campaign table and the report's verdict; a regression case whose SUT erred is an
error, not fixed; requirements judge only the episodes the SUT played, and one it erred in has
nothing to replay."""

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hazardhunt.campaign.config import RunConfig
from hazardhunt.campaign.run import NothingTested, record_run
from hazardhunt.campaign.store import file_checksums
from hazardhunt.sut.pursuit import PursuitController
from tests.helpers import hazardhunt

HERE = "tests.campaign.test_nothing_tested"
ROOT = Path(__file__).parents[2]
"""Where the command finds this module (the working directory is on a plug-in's search path)."""


class ResetRaises(PursuitController):
    """Cannot start an episode."""

    def reset(self, floor, route, robot, params):
        raise FileNotFoundError("map.yaml")


class RaisesOnceTheHumanMoves(PursuitController):
    """Works against a human standing still, raises as soon as the tracked human moves."""

    def control(self, time_s, robot, human):
        if human is not None and len(human.recent_positions) > 1:
            step = np.linalg.norm(human.recent_positions[-1] - human.recent_positions[-2])
            if step > 1e-6:
                raise RuntimeError("lost the localisation")
        return super().control(time_s, robot, human)


class RaisesNearTheHuman(PursuitController):
    """Raises when the human comes within 3 m of the robot: some episodes only."""

    def control(self, time_s, robot, human):
        if human is not None and math.dist(human.position, (robot.x, robot.y)) < 3.0:
            raise RuntimeError("tracking overflow")
        return super().control(time_s, robot, human)


class WearsOut(PursuitController):
    """Plays its first ``lasts`` episodes (a trial episode on the same object counts), then
    raises in every one."""

    def __init__(self, lasts=3):
        super().__init__()
        self.lasts = lasts
        self.episodes = 0

    def reset(self, floor, route, robot, params):
        self.episodes += 1
        super().reset(floor, route, robot, params)

    def control(self, time_s, robot, human):
        if self.episodes > self.lasts:
            raise RuntimeError("worn out")
        return super().control(time_s, robot, human)


REQUIREMENTS = """
[requirements.far-away]
formula = "always(clearance >= 50)"
description = "Violated by every episode played: the floor is 20 m across."

[requirements.anywhere]
formula = "always(clearance >= -1)"
description = "Kept by every episode played."
"""


def run_that_wears_out(tmp_path):
    """A run of 8 episodes whose SUT (:class:`WearsOut`) erred in the last 5, judged by
    :data:`REQUIREMENTS`: its directory and the command's output."""
    requirements = tmp_path / "requirements.toml"
    requirements.write_text(REQUIREMENTS)
    run = tmp_path / "run"
    done = hazardhunt(
        "run", "--scenario", "head-on", "--field", "none", "--tester", "random",
        "--episodes", 8, "--out", run, "--controller", f"{HERE}:WearsOut",
        "--requirement", requirements, cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    return run, done


def recorded_as_before_0_2(run):
    """Make ``run`` what versions before 0.2.0 recorded: the episodes that ended in a SUT
    error violate the requirements their first episode violated (its files signed anew, as
    they were then)."""
    violations = pd.read_parquet(run / "violations.parquet")
    erred = pd.read_parquet(run / "episodes.parquet").query("outcome == 'sut_error'")
    first = violations[violations["episode"] == 0]
    judged = [first.assign(episode=episode, outcome="sut_error") for episode in erred["episode"]]
    pd.concat([violations, *judged], ignore_index=True).to_parquet(run / "violations.parquet")
    summary = json.loads((run / "summary.json").read_text())
    summary["checksums"] = file_checksums(run)
    (run / "summary.json").write_text(json.dumps(summary))


def test_requirements_judge_only_the_episodes_the_sut_played(tmp_path):
    run, done = run_that_wears_out(tmp_path)
    for name, violated in (("far-away", 3), ("anywhere", 0)):
        assert (
            f"requirement {name}: {violated} of 3 tested episodes violated it (5 ended in a SUT "
            "error and are not judged)"
        ) in done.stdout
    summary = json.loads((run / "summary.json").read_text())
    assert summary["requirements"]["far-away"]["judged"] == 3
    violations = pd.read_parquet(run / "violations.parquet")
    assert sorted(violations["episode"]) == [0, 1, 2]
    assert "sut_error" not in set(violations["outcome"])

    # An episode that ended in a SUT error has nothing to reproduce, in this run and in one
    # recorded before 0.2.0, which kept its violations.
    nothing_to_reproduce(run, 5)
    recorded_as_before_0_2(run)
    nothing_to_reproduce(run, 5)
    # A violation replayed against a SUT that now errs is not reproduced, and says why.
    replayed = hazardhunt(
        "replay", run, "--episode", 1, "--controller", f"{HERE}:RaisesOnceTheHumanMoves", cwd=ROOT
    )
    assert replayed.returncode == 1
    assert (
        "NOT reproduced: the SUT erred, so the replay tested nothing (controller: RuntimeError: "
        "lost the localisation)"
    ) in replayed.stdout


def nothing_to_reproduce(run, episode):
    """Replaying ``episode``, which ended in a SUT error, fails, naming the error."""
    replayed = hazardhunt(
        "replay", run, "--episode", episode, "--controller", f"{HERE}:WearsOut", cwd=ROOT
    )
    assert replayed.returncode != 0
    assert "reproduced" not in replayed.stdout
    said = "it ended in a SUT error, which tested nothing: controller: RuntimeError: worn out"
    assert said in replayed.stderr


def run_command(tmp_path, controller, *options, episodes=6):
    return hazardhunt(
        "run", "--scenario", "head-on", "--field", "none", "--tester", "random",
        "--episodes", episodes, "--out", tmp_path / "out" / "run",
        "--controller", f"{HERE}:{controller}", *options, cwd=ROOT,
    )  # fmt: skip


def test_a_controller_that_cannot_reset_is_one_line_before_anything_is_written(tmp_path):
    done = run_command(tmp_path, "ResetRaises")
    assert done.returncode == 2
    assert done.stderr.strip() == (
        f"error: controller '{HERE}:ResetRaises': reset() raised FileNotFoundError: map.yaml "
        "(on a trial episode before the run; nothing was run)"
    )
    assert not (tmp_path / "out").exists()


def test_a_run_whose_every_episode_erred_fails_with_the_first_error(tmp_path):
    done = run_command(tmp_path, "RaisesOnceTheHumanMoves", "--json")
    assert done.returncode == 1
    assert done.stdout == ""
    lines = done.stderr.strip().splitlines()
    assert lines[-1] == (
        "error: run head-on__none__random__seed0: every one of its 6 episodes ended in a SUT "
        "error, so it tested nothing (sut_error_limit 1); the first, episode 0: controller: "
        "RuntimeError: lost the localisation; nothing of it was kept"
    )
    assert not (tmp_path / "out" / "run").exists()


def test_sut_errors_below_the_limit_are_counted_where_a_reader_cannot_miss_them(tmp_path):
    done = run_command(tmp_path, "RaisesNearTheHuman", episodes=12)
    assert done.returncode == 0, done.stderr
    summary = json.loads((tmp_path / "out" / "run" / "summary.json").read_text())
    errors = summary["sut_errors"]
    assert 0 < errors < 12
    assert summary["first_sut_error"]["error"] == "controller: RuntimeError: tracking overflow"
    assert f"warning: {errors} of 12 episodes ended in a SUT error and tested nothing" in (
        done.stdout
    )
    assert "SUT errors" in done.stdout.splitlines()[1]  # the table's header

    # A limit below that share fails the run.
    share = errors / 12
    strict = run_command(
        tmp_path / "strict", "RaisesNearTheHuman", "--sut-error-limit", share, episodes=12
    )
    assert strict.returncode == 1
    assert f"{errors} of its" in strict.stderr
    assert "tested nothing" in strict.stderr

    report = hazardhunt("report", tmp_path / "out" / "run", cwd=tmp_path)
    assert report.returncode == 0, report.stderr
    data = json.loads((tmp_path / "out" / "run" / "report" / "summary.json").read_text())
    assert data["verdict"]["sut_errors"] == errors
    page = (tmp_path / "out" / "run" / "report" / "index.html").read_text()
    assert f"{errors} of these episodes" in page
    assert "tested nothing" in page


def test_a_tester_that_plays_no_episode_tested_nothing(tmp_path):
    config = RunConfig(
        scenario="head-on",
        field="none",
        tester="idle",
        tester_plugin={"path": f"{HERE}:Idle"},
        seed=0,
        episodes=5,
    )
    with pytest.raises(NothingTested, match="its tester played no episode, so it tested nothing"):
        record_run(config, tmp_path / "run")


class Idle:
    """A tester that returns at once."""

    name = "idle"

    def __init__(self, seed):
        pass

    def explore(self, env, episodes):
        pass

    def save(self, directory):
        pass


CAMPAIGN = """
scenarios = ["head-on"]
fields = ["none"]
testers = ["random"]
seeds = [0]
episodes = 4

[controller]
path = "{path}"
"""


def test_a_campaign_with_a_controller_that_cannot_reset_writes_nothing(tmp_path):
    campaign = tmp_path / "campaign.toml"
    campaign.write_text(CAMPAIGN.format(path=f"{HERE}:ResetRaises"))
    done = hazardhunt("campaign", campaign, "--out", tmp_path / "results", cwd=ROOT)
    assert done.returncode == 2
    assert "reset() raised FileNotFoundError: map.yaml" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "results").exists()


def test_a_campaign_run_that_tested_nothing_is_a_failed_run(tmp_path):
    campaign = tmp_path / "campaign.toml"
    campaign.write_text(CAMPAIGN.format(path=f"{HERE}:RaisesOnceTheHumanMoves"))
    done = hazardhunt("campaign", campaign, "--out", tmp_path / "results", cwd=ROOT)
    assert done.returncode == 1
    assert "every one of its 4 episodes ended in a SUT error" in done.stdout
    summary = json.loads((tmp_path / "results" / "summary.json").read_text())
    assert summary["runs_failed"] == 1
    assert summary["runs_complete"] == 0
