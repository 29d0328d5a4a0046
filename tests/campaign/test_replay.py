"""Every recorded failure replays exactly from its record."""

import pandas as pd
import pytest
from PIL import Image

from hazardhunt.campaign.config import RunConfig
from hazardhunt.campaign.replay import replay_failure
from hazardhunt.campaign.run import execute_run
from hazardhunt.campaign.store import read_trajectory
from tests.helpers import hazardhunt


@pytest.fixture(scope="module")
def run_with_failures(tmp_path_factory):
    # Random humans often collide with the field-less robot when it overtakes them.
    directory = tmp_path_factory.mktemp("replay") / "run"
    config = RunConfig(scenario="overtaking", field="none", tester="random", seed=0, episodes=20)
    summary = execute_run(config, directory)
    assert summary["failures"] >= 1, "the fixture needs a run with failures"
    return directory


def test_every_failure_replays_to_the_same_end(run_with_failures):
    failures = pd.read_parquet(run_with_failures / "failures.parquet")
    for failure_id in failures["failure_id"]:
        result = replay_failure(run_with_failures, int(failure_id))
        assert result.matches
        stored = read_trajectory(run_with_failures, int(failure_id))
        replayed = pd.DataFrame(result.env.trajectory())
        columns = ["time", "human_x", "human_y", "robot_x", "robot_y", "robot_speed"]
        pd.testing.assert_frame_equal(stored[columns], replayed[columns])


def test_replay_command_confirms_and_animates(run_with_failures, tmp_path):
    failure_id = int(pd.read_parquet(run_with_failures / "failures.parquet")["failure_id"][0])
    gif = tmp_path / "failure.gif"
    done = hazardhunt("replay", run_with_failures, "--failure", failure_id, "--gif", gif)
    assert done.returncode == 0, done.stderr
    assert "reproduced" in done.stdout
    with Image.open(gif) as animation:
        assert animation.n_frames > 5


def test_a_tampered_record_is_reported_as_not_reproduced(run_with_failures, tmp_path):
    failures = pd.read_parquet(run_with_failures / "failures.parquet")
    tampered = tmp_path / "run"
    tampered.mkdir()
    for name in ("config.json", "episodes.parquet"):
        (tampered / name).write_bytes((run_with_failures / name).read_bytes())
    standing = [[-1.0, 0.0]] * len(failures.loc[0, "actions"])
    failures["actions"] = [standing, *failures["actions"][1:]]  # the first stands still
    failures.to_parquet(tampered / "failures.parquet")
    done = hazardhunt("replay", tampered, "--failure", int(failures.loc[0, "failure_id"]))
    assert done.returncode == 1
    assert "NOT reproduced" in done.stdout


def test_an_unknown_failure_is_a_clear_error(run_with_failures):
    done = hazardhunt("replay", run_with_failures, "--failure", 999_999)
    assert done.returncode == 2
    assert "no failure 999999" in done.stderr
