"""Every recorded failure replays exactly from its record."""

import pandas as pd
import pytest
from PIL import Image

from hazardhunt.campaign.config import RunConfig
from hazardhunt.campaign.replay import replay_failure
from hazardhunt.campaign.run import record_run
from hazardhunt.campaign.store import read_trajectory
from tests.helpers import hazardhunt


@pytest.fixture(scope="module")
def run_with_failures(tmp_path_factory):
    # Random humans often collide with the field-less robot when it overtakes them.
    directory = tmp_path_factory.mktemp("replay") / "run"
    config = RunConfig(scenario="overtaking", field="none", tester="random", seed=0, episodes=20)
    summary = record_run(config, directory)
    assert summary["failures"] >= 1, "the fixture needs a run with failures"
    return directory


def test_every_failure_replays_to_the_same_end(run_with_failures):
    failures = pd.read_parquet(run_with_failures / "failures.parquet")
    for episode in failures["episode"]:
        replay = replay_failure(run_with_failures, int(episode))
        assert replay.matches
        stored = read_trajectory(run_with_failures, int(episode))
        columns = ["time", "human_x", "human_y", "robot_x", "robot_y", "robot_speed"]
        for stored_sample, replayed_sample in zip(stored, replay.result.trajectory, strict=True):
            for column in columns:
                assert getattr(stored_sample, column) == getattr(replayed_sample, column)


def test_replay_command_confirms_and_animates(run_with_failures, tmp_path):
    episode = int(pd.read_parquet(run_with_failures / "failures.parquet")["episode"][0])
    gif = tmp_path / "failure.gif"
    done = hazardhunt("replay", run_with_failures, "--episode", episode, "--gif", gif)
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
    done = hazardhunt("replay", tampered, "--episode", int(failures.loc[0, "episode"]))
    assert done.returncode == 1
    assert "NOT reproduced" in done.stdout


def test_an_unknown_failure_is_a_clear_error(run_with_failures):
    done = hazardhunt("replay", run_with_failures, "--episode", 999_999)
    assert done.returncode == 2
    assert "no failure in episode 999999" in done.stderr
