"""The sampler of one's own that docs/plugins.md shows runs as written."""

import json
import re
from pathlib import Path

import pytest

from hazardhunt.campaign.config import ConfigError, PluginSpec, RunConfig
from hazardhunt.campaign.plugins import make_plugin_tester
from hazardhunt.campaign.run import record_run
from hazardhunt.testers import make_tester

DOCS = Path(__file__).parents[2] / "docs" / "plugins.md"


def documented_sampler() -> str:
    blocks = re.findall(r"```python\n(.*?)```", DOCS.read_text(), flags=re.S)
    return next(block for block in blocks if "class GridSampler" in block)


def test_the_documented_sampler_runs_and_records_its_settings(tmp_path):
    (tmp_path / "my_testers.py").write_text(documented_sampler())
    spec = PluginSpec(
        path="my_testers:GridSearch",
        params={"speeds": 3, "space": "aim"},
        search_path=[str(tmp_path)],
    )
    config = RunConfig(
        scenario="crossing",
        field="none",
        tester="grid",
        tester_plugin=spec,
        seed=0,
        episodes=4,
        controller=PluginSpec(path="hazardhunt.sut.pursuit:PursuitController"),
    )
    assert record_run(config, tmp_path / "run")["episodes"] == 4
    settings = json.loads((tmp_path / "run" / "tester" / "grid.json").read_text())
    assert settings["speeds"] == 3
    assert settings["space"]["kind"] == "aim"


def test_a_wrong_setting_of_the_documented_sampler_names_it(tmp_path):
    (tmp_path / "my_testers.py").write_text(documented_sampler())
    spec = PluginSpec(
        path="my_testers:GridSearch", params={"speeds": 1}, search_path=[str(tmp_path)]
    )
    with pytest.raises((ConfigError, ValueError), match="speeds: must be greater than or equal"):
        make_plugin_tester(spec, seed=0)


def test_the_documented_sampler_joins_the_portfolio_as_an_arm(tmp_path, monkeypatch):
    (tmp_path / "my_testers.py").write_text(documented_sampler())
    monkeypatch.chdir(tmp_path)  # the arm's module is found in the working directory
    arms = [
        {"name": "grid", "method": "my_testers:GridSearch", "params": {"speeds": 3}},
        {"name": "uniform", "method": "uniform", "params": {"batch_size": 2}},
    ]
    assert portfolio_arms_played(tmp_path / "run", arms, episodes=6)["grid"]["episodes"] > 0


def portfolio_arms_played(directory, arms, episodes):
    """Run a portfolio of ``arms`` against the pursuit controller for ``episodes``; what each
    arm played and recorded (``tester/portfolio.json``)."""
    config = RunConfig(
        scenario="crossing",
        field="none",
        tester="portfolio",
        tester_params={"arms": arms},
        seed=0,
        episodes=episodes,
        controller=PluginSpec(path="hazardhunt.sut.pursuit:PursuitController"),
    )
    assert record_run(config, directory)["episodes"] == episodes
    return json.loads((directory / "tester" / "portfolio.json").read_text())["arms_played"]


def test_an_arm_of_ones_own_that_does_not_load_is_a_clear_error(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    arms = [{"name": "mine", "method": "no_such_module:Search"}]
    with pytest.raises(ValueError, match="arm 'mine': 'no_such_module:Search': cannot import"):
        make_tester("portfolio", 0, {"arms": arms})


OBSERVING_SAMPLER = """
import numpy as np

from hazardhunt.testers.evaluator import Plan
from hazardhunt.testers.search import SearchTester, SpaceParams


class StandStill:
    def __init__(self, params, context):
        self.space, self.horizon, self.heard = params.space.decision_spaces[0], context.horizon, 0

    def ask(self):
        return [Plan(self.space, np.full((self.horizon, self.space.size), -1.0))]

    def tell(self, plans, results):
        pass

    def observe(self, plans, results):
        self.heard += len(results)

    def record(self):
        return {"heard": self.heard}


class StandStillSearch(SearchTester):
    name = "stand-still"
    params_model = SpaceParams

    def make_sampler(self, context):
        return StandStill(self.params, context)
"""


def test_an_arm_of_ones_own_with_observe_hears_the_other_arms_episodes(tmp_path, monkeypatch):
    (tmp_path / "my_observer.py").write_text(OBSERVING_SAMPLER)
    monkeypatch.chdir(tmp_path)
    arms = [
        {"name": "still", "method": "my_observer:StandStillSearch"},
        {"name": "uniform", "method": "uniform", "params": {"batch_size": 3}},
    ]
    played = portfolio_arms_played(tmp_path / "run", arms, episodes=12)
    still, uniform = played["still"], played["uniform"]
    assert still["episodes"] > 0
    assert uniform["episodes"] > 0
    assert still["heard"] == uniform["episodes"]  # every episode the other arm played, only those
