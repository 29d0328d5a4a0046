"""The campaign files hazardhunt ships load as their comments describe them."""

from pathlib import Path

import pytest

from hazardhunt.campaign.config import load_campaign
from hazardhunt.testers.portfolio import FIRST_DEFAULT_ARMS, PortfolioParams

CAMPAIGNS = Path(__file__).parents[2] / "campaigns"


@pytest.mark.parametrize(
    ("name", "runs", "episodes", "testers"),
    [
        ("quick.toml", 3, 450, {"portfolio", "random", "ppo-max"}),
        ("reduced.toml", 81, 300, {"random", "ppo-acc", "ppo-max"}),
        ("study.toml", 81, 20_000, {"random", "ppo-acc", "ppo-max"}),
        ("study-search.toml", 81, 20_000, {"cem", "qd", "ppo-novelty"}),
        ("study-portfolio.toml", 9, 20_000, {"portfolio"}),
    ],
)
def test_a_shipped_campaign_file_loads_with_its_grid(name, runs, episodes, testers):
    config = load_campaign(CAMPAIGNS / name)
    assert len(config.runs()) == runs
    assert config.episodes == episodes
    assert set(config.testers) == testers
    assert config.unused_tester_tables == []  # every tester's settings reach its runs


def test_every_shipped_campaign_file_is_tested():
    assert sorted(p.name for p in CAMPAIGNS.glob("*.toml")) == [
        "quick.toml",
        "reduced.toml",
        "study-portfolio.toml",
        "study-search.toml",
        "study.toml",
    ]


def test_the_study_budget_portfolio_runs_keep_the_arms_they_were_published_with():
    # benchmarks/results/study-portfolio/ was measured with the first default's six arms.
    config = load_campaign(CAMPAIGNS / "study-portfolio.toml")
    for run in config.runs():
        assert PortfolioParams(**run.tester_params).arms == FIRST_DEFAULT_ARMS
