"""The default tester: a portfolio of samplers sharing the budget by what each finds."""

import json

import numpy as np
import pandas as pd
import pytest

from hazardhunt.analysis import verdict
from hazardhunt.analysis.results import load_results
from hazardhunt.campaign.config import RunConfig
from hazardhunt.campaign.run import record_run
from hazardhunt.sim.simulation import Simulation
from hazardhunt.sut.pursuit import PursuitController
from hazardhunt.testers.cem import CrossEntropySampler
from hazardhunt.testers.evaluator import Plan
from hazardhunt.testers.mirror import MirrorSampler
from hazardhunt.testers.portfolio import DEFAULT_ARMS, Arm, PortfolioParams, PortfolioSampler
from hazardhunt.testers.search import SearchContext
from hazardhunt.testers.spaces import DecisionSpace


def portfolio_run(directory, episodes, params=None, scenario="crossing"):
    config = RunConfig(
        scenario=scenario,
        field="none",
        tester="portfolio",
        tester_params=params or {},
        seed=0,
        episodes=episodes,
    )
    return record_run(config, directory)


def test_the_default_portfolio_says_which_arm_found_each_class_first(tmp_path):
    summary = portfolio_run(tmp_path / "run", 140)
    assert summary["episodes"] == 140
    record = json.loads((tmp_path / "run" / "tester" / "portfolio.json").read_text())
    arms = record["arms_played"]
    assert list(arms) == [arm.name for arm in DEFAULT_ARMS]
    # Every searching arm has had its first look, and the episodes add up to the budget.
    waiting = ("mirror", "boundary")  # they propose nothing before a failure
    assert all(arm["episodes"] > 0 for name, arm in arms.items() if name not in waiting)
    assert sum(arm["episodes"] for arm in arms.values()) == 140
    # Each class the run found was found first by exactly one arm, in an episode that is a
    # failure of that class in the run's own table.
    first = {
        cls: (name, episode)
        for name, arm in arms.items()
        for cls, episode in arm["classes_first_found"].items()
    }
    assert set(first) == set(summary["classes"])
    assert len(first) >= 2
    played_by = pd.read_csv(tmp_path / "run" / "tester" / "arms.csv")
    assert list(played_by["episode"]) == list(range(140))
    # The first look: the aimed arm's batch, then the plain attacks and searches of cem-mixed.
    assert set(played_by["arm"][:20]) == {"cem-aim"}
    assert set(played_by["arm"][20:80]) == {"cem-mixed"}
    failures = pd.read_parquet(tmp_path / "run" / "failures.parquet").set_index("episode")
    for failure_class, (arm, episode) in first.items():
        assert played_by["arm"][episode] == arm
        assert failures.loc[episode, "class"] == failure_class
    # The report's verdict says the same, read from the stored results.
    shown = verdict.arms_found(load_results(tmp_path / "run"))
    assert {row["class"]: (row["arm"], row["episode"]) for _, row in shown.iterrows()} == first


def test_an_arm_that_raises_is_dropped_and_the_others_spend_the_budget(tmp_path, monkeypatch):
    def broken(self, plans, results):
        raise ZeroDivisionError("the arm's own bug")

    monkeypatch.setattr(CrossEntropySampler, "tell", broken)  # the three cem arms fail
    with pytest.warns(RuntimeWarning) as warned:
        summary = portfolio_run(tmp_path / "run", 80)
    assert sorted(str(warning.message).split(":")[0] for warning in warned) == [
        "portfolio arm 'cem-aim' raised and was dropped",
        "portfolio arm 'cem-ambush' raised and was dropped",
        "portfolio arm 'cem-mixed' raised and was dropped",
    ]
    assert summary["episodes"] == 80
    arms = json.loads((tmp_path / "run" / "tester" / "portfolio.json").read_text())["arms_played"]
    assert arms["cem-aim"]["dropped"] == "ZeroDivisionError: the arm's own bug"
    assert arms["cem-aim"]["episodes"] == 20  # its one batch
    assert arms["random"]["dropped"] is None
    others = ("mirror", "qd-mixed", "random", "boundary")
    assert arms["cem-ambush"]["episodes"] == 20
    assert sum(arms[name]["episodes"] for name in others) == 80 - 60


def test_a_portfolio_whose_every_arm_raises_fails_the_run(tmp_path, monkeypatch):
    def broken(self):
        raise ZeroDivisionError("the arm's own bug")

    monkeypatch.setattr(CrossEntropySampler, "ask", broken)
    params = {"arms": [{"name": "only", "method": "cem"}]}
    with (
        pytest.warns(RuntimeWarning),
        pytest.raises(RuntimeError, match=r"every arm failed \(only: ZeroDivisionError"),
    ):
        portfolio_run(tmp_path / "run", 10, params)


def test_a_mirrored_decision_comes_at_the_robot_from_its_other_side():
    aims = np.tile([1.0, 0.5, -1.0], (15, 1))  # into the robot's left side
    mirrored = DecisionSpace("aim").mirrored(aims)
    assert (mirrored[:, 1] == -0.5).all()  # its right side
    assert (mirrored[:, [0, 2]] == aims[:, [0, 2]]).all()
    route = np.tile([1.0, 1.0, 0.5], (15, 1))
    assert (DecisionSpace("route").mirrored(route)[:, 2] == -0.5).all()
    sim = Simulation.build("head-on", "none", controller=PursuitController())
    left = DecisionSpace("aim").play(sim, aims, False).summary
    right = DecisionSpace("aim").play(sim, mirrored, False).summary
    assert (left.contact_face, right.contact_face) == ("left", "right")


def test_the_mirror_arm_plays_the_other_side_of_failures_the_others_found(tmp_path):
    params = {
        "arms": [
            {"name": "mirror", "method": "mirror"},
            {"name": "aimed", "method": "cem", "params": {"space": "aim", "batch_size": 6}},
        ]
    }
    portfolio_run(tmp_path / "run", 60, params, scenario="head-on")
    arms = json.loads((tmp_path / "run" / "tester" / "portfolio.json").read_text())["arms_played"]
    assert arms["aimed"]["failures"] > 0
    assert 0 < arms["mirror"]["episodes"] <= 2 * arms["mirror"]["cells_seen"]


@pytest.mark.parametrize("min_share", [0.0, 0.5])
def test_an_arm_with_a_min_share_plays_that_share_once_it_has_episodes(tmp_path, min_share):
    params = {
        "floor": 0.0,
        "arms": [
            {"name": "aimed", "method": "cem", "params": {"space": "aim", "batch_size": 6}},
            {"name": "boundary", "method": "boundary", "min_share": min_share},
        ],
    }
    portfolio_run(tmp_path / "run", 90, params, scenario="head-on")
    arms = json.loads((tmp_path / "run" / "tester" / "portfolio.json").read_text())["arms_played"]
    assert arms["aimed"]["failures"] > 0
    if min_share:
        assert arms["boundary"]["episodes"] >= min_share * 90 - 6  # but the last batch
    else:  # the aimed arm keeps finding failures, so the budget stays with it
        assert arms["boundary"]["episodes"] < 0.5 * 90 - 6


def test_min_shares_that_add_up_to_more_than_the_run_are_refused():
    arms = [{"name": name, "method": "uniform", "min_share": 0.6} for name in ("a", "b")]
    with pytest.raises(ValueError, match="min_share add up to more than 1"):
        PortfolioParams(arms=arms)


def test_an_arm_that_raises_while_hearing_the_others_is_dropped(tmp_path, monkeypatch):
    def broken(self, plans, results):
        raise ZeroDivisionError("the arm's own bug")

    monkeypatch.setattr(MirrorSampler, "observe", broken)
    with pytest.warns(RuntimeWarning, match="'mirror' raised and was dropped"):
        summary = portfolio_run(tmp_path / "run", 70)
    assert summary["episodes"] == 70
    arms = json.loads((tmp_path / "run" / "tester" / "portfolio.json").read_text())["arms_played"]
    assert arms["mirror"]["dropped"] == "ZeroDivisionError: the arm's own bug"
    assert arms["mirror"]["episodes"] == 0
    assert all(arms[name]["dropped"] is None for name in arms if name != "mirror")


@pytest.fixture(scope="module")
def approaches():
    """Episodes on crossing / 1.25 m that come ever closer to the robot, and one that fails."""
    sim = Simulation.build("crossing", "1.25m", controller=PursuitController())

    def episode(space, decision):
        plan = Plan(DecisionSpace(space), np.tile(decision, (sim.horizon, 1)))
        return plan.space.play(sim, plan.decisions, False)

    stand = episode("open", [-1.0, 0.0])  # the human stays where it starts, 4.5 m off
    three_metres = episode("aim", [1.0, 0.5, 1.0])  # keeps 3 m, then 1.5 m, from the robot
    metre_and_half = episode("aim", [1.0, 0.5, 0.0])
    failure = episode("aim", [1.0, 0.6, -1.0])  # into its side
    assert all(result.outcome == "goal" for result in (stand, three_metres, metre_and_half))
    assert stand.summary.max_risk < three_metres.summary.max_risk < metre_and_half.summary.max_risk
    assert failure.outcome == "failure"
    return sim, stand, three_metres, metre_and_half, failure


def uniform_arms(*names):
    return [Arm(name=name, method="uniform", params={"batch_size": 2}) for name in names]


@pytest.mark.parametrize("closer_gain", [0.1, 0.0])
def test_before_any_failure_the_budget_goes_to_the_arm_that_came_closer(approaches, closer_gain):
    sim, stand, three_metres, metre_and_half, _ = approaches
    params = PortfolioParams(arms=uniform_arms("far", "near"), closer_gain=closer_gain)
    sampler = PortfolioSampler(params, SearchContext(sim, seed=0))
    sampler.tell(sampler.ask(), [stand, stand])  # the first look of each arm, in order
    sampler.tell(sampler.ask(), [three_metres, metre_and_half])
    sampler.tell(sampler.ask(), [stand, stand])
    chosen = "near" if closer_gain else "far"  # without the gain a tie: the first in order
    assert sampler.episode_arms == ["far", "far", "near", "near", chosen, chosen]


def test_from_the_first_failure_on_coming_closer_counts_for_nothing(approaches):
    sim, stand, three_metres, metre_and_half, failure = approaches

    def values(closer_gain):
        params = PortfolioParams(arms=uniform_arms("far", "near", "hit"), closer_gain=closer_gain)
        sampler = PortfolioSampler(params, SearchContext(sim, seed=0))
        sampler.tell(sampler.ask(), [stand, stand])  # the first looks, in order
        sampler.tell(sampler.ask(), [three_metres, metre_and_half])
        before = [state.value(6.0, params.optimism) for state in sampler.arms]
        sampler.tell(sampler.ask(), [failure, stand])
        after = [state.value(6.0, params.optimism) for state in sampler.arms]
        return before, after

    with_gain, without = values(0.1), values(0.0)
    assert with_gain[0] != without[0]  # the gains for coming closer counted
    assert with_gain[1] == without[1]  # and were forgotten at the failure, to the last bit


@pytest.mark.parametrize("gains", [{}, {"class_gain": 0.5, "repeat_gain": 0.0}])
def test_what_a_new_class_and_a_repeat_earn_an_arm_are_settings(approaches, gains):
    sim, stand, _, _, failure = approaches
    params = PortfolioParams(arms=uniform_arms("first", "again", "after"), floor=0.0, **gains)
    sampler = PortfolioSampler(params, SearchContext(sim, seed=0))
    sampler.tell(sampler.ask(), [failure, stand])  # a class no arm had found
    sampler.tell(sampler.ask(), [failure, stand])  # the same failure again: a repeat
    sampler.tell(sampler.ask(), [stand, stand])
    first, again, _ = sampler.arms
    assert first.weighted_gain == pytest.approx(params.class_gain * params.discount**2)
    assert again.weighted_gain == pytest.approx(params.repeat_gain * params.discount)
    # Paid nothing for its repeat, the second arm is worth no more than the one that found
    # nothing, but for the bonus of arms tried less.
    if not params.repeat_gain:
        assert again.value(6.0, 0.0) == 0.0
