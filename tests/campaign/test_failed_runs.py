"""A campaign run that failed (it tested nothing) never reads as a pass afterwards: the
campaign's table counts its SUT errors."""

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from hazardhunt.benchmark.conservative import ConservativeController
from tests.helpers import hazardhunt

HERE = "tests.campaign.test_failed_runs"
ROOT = Path(__file__).parents[2]
"""Where the command finds this module (the working directory is on a plug-in's search path)."""


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
