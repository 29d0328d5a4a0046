"""A small campaign with failures and loitering, and its report, made once per test session."""

from pathlib import Path

import pytest

from tests.helpers import hazardhunt

CAMPAIGN = """
scenarios = ["overtaking"]
fields = ["none", "2m"]
testers = ["ppo-acc", "ppo-max", "random", "qd"]
seeds = [0]
episodes = 16

[tester.ppo-acc]
n_steps = 64
batch_size = 32

[tester.ppo-max]
n_steps = 64
batch_size = 32

[tester.qd]
emitters = 2
batch_size = 4
"""
"""Without a field humans collide within a few episodes; with the 2 m field they loiter."""


@pytest.fixture(scope="session")
def campaign(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished campaign directory of ``CAMPAIGN`` (8 runs x 16 episodes)."""
    folder = tmp_path_factory.mktemp("report-campaign")
    (folder / "campaign.toml").write_text(CAMPAIGN)
    out = folder / "campaign"
    result = hazardhunt("campaign", folder / "campaign.toml", "--out", out, "--workers", "2")
    assert result.returncode == 0, result.stderr
    return out


@pytest.fixture(scope="session")
def report(campaign: Path) -> Path:
    """The campaign's report directory, written by ``hazardhunt report``."""
    result = hazardhunt("report", campaign)
    assert result.returncode == 0, result.stderr
    assert str(campaign / "report" / "index.html") in result.stdout
    return campaign / "report"
