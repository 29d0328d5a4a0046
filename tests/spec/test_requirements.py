"""Requirements beyond the contact rule: signal temporal logic over an episode's signals."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hazardhunt.spec.requirements import (
    LIBRARY,
    SIGNALS,
    RequirementError,
    StlRequirement,
    load_requirements,
    requirements_of,
)
from tests.helpers import hazardhunt
from tests.spec.test_failure_classes_recorded import RECORDED, recorded_simulation

ROOT = Path(__file__).resolve().parents[2]


def trace(**signals):
    """Signals sampled every 0.2 s; unnamed ones constant 0."""
    count = len(next(iter(signals.values())))
    values = {name: np.zeros(count) for name in SIGNALS}
    values.update({name: np.asarray(v, dtype=float) for name, v in signals.items()})
    return {"time": np.arange(count) * 0.2, **values}


def test_the_library_reads_and_every_requirement_names_known_signals():
    library = load_requirements(LIBRARY)
    assert [r.name for r in library] == [
        "separation",
        "slow-near-people",
        "no-restart-in-field",
        "reach-goal",
    ]
    for requirement in library:
        assert requirement.description
        assert requirement.source
        assert set(requirement.signals) <= set(SIGNALS)


def test_robustness_is_the_margin_and_its_sign_the_verdict():
    slow = requirements_of(["slow-near-people"])[0]
    careful = slow.check(trace(clearance=[2.0, 0.4, 0.3], robot_speed=[1.0, 0.2, 0.1]))
    hasty = slow.check(trace(clearance=[2.0, 0.4, 0.3], robot_speed=[1.0, 0.7, 0.1]))
    assert careful.robustness == pytest.approx(0.1)
    assert not careful.violated
    assert hasty.robustness == pytest.approx(-0.1)  # 0.4 m from 0.5 m
    assert hasty.violated
    # What explains it: both signals of the implication, from the second sample on.
    assert hasty.signals == ("clearance", "robot_speed")
    assert hasty.time == pytest.approx(0.2)
    assert careful.signals == ()
    assert careful.time is None


def test_a_violation_names_the_signal_that_decided_it():
    late = requirements_of(["reach-goal"])[0].check(trace(goal_distance=[5.0] * 150))
    assert late.signals == ("goal_distance",)
    close = requirements_of(["separation"])[0]
    verdict = close.check(
        trace(clearance=[3.0, 2.0, 0.4, 1.0], protective_separation=[1.0, 1.0, 0.6, 0.2])
    )
    assert verdict.robustness == pytest.approx(-0.2)
    assert verdict.signals == ("clearance", "protective_separation")
    assert verdict.time == pytest.approx(0.4)


def test_time_bounds_are_seconds():
    arrives = trace(goal_distance=[5.0] * 20 + [0.1] * 30)  # at 4 s
    soon = StlRequirement("soon", "eventually[0:3](goal_distance <= 0.3)")
    late = StlRequirement("late", "eventually[0:5](goal_distance <= 0.3)")
    assert soon.check(arrives).violated
    assert not late.check(arrives).violated


@pytest.mark.parametrize(
    ("formula", "says"),
    [
        ("always(clearence >= 1)", "formula position 8: unknown signal 'clearence'"),
        ("always((clearance < 0.5) implies robot_speed <= )", "formula position 49"),
        ("always(clearance >", "formula position 19"),
    ],
)
def test_a_formula_that_cannot_be_monitored_names_file_requirement_and_position(
    tmp_path, formula, says
):
    path = tmp_path / "mine.toml"
    path.write_text(f'[requirements.gap]\nformula = "{formula}"\n')
    with pytest.raises(RequirementError) as raised:
        load_requirements(path)
    message = str(raised.value)
    assert message.startswith(f"{path}: requirement 'gap': ")
    assert says in message
    assert "\n" not in message


@pytest.mark.parametrize(
    ("formula", "says"),
    [
        (
            "eventually[0:1e9](clearance >= 1)",
            "formula: the time bound 1e+09 s of 'eventually' is longer than the longest "
            "episode (3600 s)",
        ),
        (
            "always(clearance >= 1 or once[0:4000000ms](robot_speed < 1))",
            "formula: the time bound 4e+06ms of 'once' is longer than the longest episode",
        ),
        (
            "not " * 30 + "clearance >= 1",
            "formula: 30 negations ('not', '!'), at most 12",
        ),
        (
            "always[0:3600](" * 40 + "clearance >= 1" + ")" * 40,
            "formula: too costly to evaluate: about 1.3e+10 steps per episode (each temporal "
            "operator nested adds the samples of its time bound), at most 4e+08",
        ),
        (
            "(clearance >= 1) until[0:300] (robot_speed < 1)",
            "formula: too costly to evaluate: about 6.8e+10 steps per episode",
        ),
    ],
)
def test_a_formula_too_costly_to_monitor_is_refused_when_read(tmp_path, formula, says):
    path = tmp_path / "mine.toml"
    path.write_text(f'[requirements.gap]\nformula = "{formula}"\n')
    with pytest.raises(RequirementError) as raised:
        load_requirements(path)
    assert str(raised.value).startswith(f"{path}: requirement 'gap': {says}")


def test_a_formula_bounded_by_the_longest_episode_is_read():
    assert StlRequirement("long", "eventually[0:3600](goal_distance <= 0.3)").formula
    nested = "always[0:30](" * 40 + "clearance >= 1" + ")" * 40
    assert StlRequirement("nested", nested).check(trace(clearance=[2.0] * 150)).robustness == 1
    assert StlRequirement("until", "(clearance >= 1) until[0:30] (robot_speed < 1)").formula


@pytest.mark.parametrize(
    ("content", "says"),
    [
        (b"x = " + b"[" * 100_000, "not valid TOML: arrays or tables nested too deeply"),
        (b'[requirements.a]\nformula = "always(clearance >= 1)"\ndescription = "\xff"\n',
         "not a text file"),
    ],
)  # fmt: skip
def test_a_requirements_file_that_cannot_be_read_is_one_line_naming_it(tmp_path, content, says):
    path = tmp_path / "mine.toml"
    path.write_bytes(content)
    done = hazardhunt(
        "run", "--scenario", "crossing", "--field", "2m", "--episodes", 2,
        "--out", tmp_path / "run", "--requirement", path, cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 2
    [line] = done.stderr.strip().splitlines()
    assert f"{path}: {says}" in line
    assert not (tmp_path / "run").exists()


def test_a_requirements_file_with_unknown_keys_or_names_is_refused(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text('[requirements.gap]\nformula = "always(clearance >= 1)"\nlevel = 3\n')
    with pytest.raises(RequirementError, match=r"requirements.gap: level: unknown key"):
        load_requirements(path)
    with pytest.raises(RequirementError, match="not in hazardhunt's library"):
        requirements_of(["seperation"])
    with pytest.raises(RequirementError, match="named twice"):
        requirements_of(["separation", "separation"])


def test_every_recorded_failure_violates_the_separation_and_replays_its_verdict():
    separation = requirements_of(["separation", "slow-near-people"])
    for name in ("edge-entry/moving", *sorted(RECORDED)[:2]):
        example = RECORDED[name]
        simulation = recorded_simulation(example)
        simulation.requirements = separation
        actions = np.asarray(example["actions"], dtype=np.float32)
        first = simulation.simulate(actions, keep_trajectory=False)
        assert first.outcome == "failure"
        assert first.trajectory is None  # judged all the same
        assert first.verdicts["separation"].violated  # a contact while the robot moves
        again = simulation.simulate(actions, keep_trajectory=False)
        assert again.verdicts == first.verdicts


def test_a_run_records_each_episodes_robustness_and_counts_the_violations(tmp_path):
    done = hazardhunt(
        "run", "--scenario", "crossing", "--field", "2m", "--tester", "random",
        "--episodes", 12, "--decision-period", 0.2, "--out", tmp_path / "run",
        "--requirement", "separation", "--requirement", "reach-goal", "--json", cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    episodes = pd.read_parquet(tmp_path / "run" / "episodes.parquet")
    for name in ("separation", "reach-goal"):
        robustness = episodes[f"requirement:{name}"]
        assert len(robustness) == 12
        assert robustness.notna().all()
        counted = summary["requirements"][name]
        assert counted["violations"] == int((robustness < 0).sum())
        assert counted["min_robustness"] == pytest.approx(robustness.min())
        assert sum(counted["decided_by"].values()) == counted["violations"]
    shown = hazardhunt("report", tmp_path / "run", cwd=ROOT)
    assert shown.returncode == 0, shown.stderr
    page = (tmp_path / "run" / "report" / "index.html").read_text()
    assert "Requirements beyond the contact rule" in page
    table = pd.read_csv(tmp_path / "run" / "report" / "tables" / "requirements.csv")
    assert list(table["requirement"]) == ["separation", "reach-goal"]
    assert list(table["violations"]) == [
        summary["requirements"][name]["violations"] for name in table["requirement"]
    ]
    separation = table.set_index("requirement").loc["separation"]
    assert separation["violations"] > 0  # seed 0 walks into the robot's separation
    assert "clearance" in separation["decided_by"]


def test_a_bad_requirement_stops_the_run_before_anything_is_written(tmp_path):
    mine = tmp_path / "mine.toml"
    mine.write_text('[requirements.gap]\nformula = "always(gap >= 1)"\n')
    done = hazardhunt(
        "run", "--scenario", "crossing", "--field", "2m", "--episodes", 5,
        "--out", tmp_path / "run", "--requirement", f"{mine}:gap", cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 2
    assert "mine.toml: requirement 'gap': formula position 8: unknown signal 'gap'" in done.stderr
    assert not (tmp_path / "run").exists()


def test_a_campaign_file_finds_its_requirements_file_beside_it(tmp_path):
    from hazardhunt.campaign.config import ConfigError, load_campaign

    (tmp_path / "mine.toml").write_text('[requirements.gap]\nformula = "always(clearance >= 1)"\n')
    campaign = tmp_path / "campaign.toml"
    body = 'scenarios = ["crossing"]\nfields = ["2m"]\ntesters = ["random"]\nseeds = [0]\n'
    campaign.write_text(body + 'episodes = 5\nrequirements = ["mine.toml", "separation"]\n')
    runs = load_campaign(campaign).runs()
    assert runs[0].requirements == [str(tmp_path / "mine.toml"), "separation"]
    campaign.write_text(body + 'episodes = 5\nrequirements = ["theirs.toml"]\n')
    with pytest.raises(ConfigError, match=r"campaign.toml: requirements: .*theirs.toml"):
        load_campaign(campaign)


def test_a_search_on_a_requirement_closes_in_on_its_violations(tmp_path):
    done = hazardhunt(
        "run", "--scenario", "crossing", "--field", "2m", "--tester", "cem",
        "--tester-param", "batch_size=20", "--episodes", 60, "--out", tmp_path / "run",
        "--requirement", "slow-near-people", "--search-on", "slow-near-people", "--json",
        cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    robustness = pd.read_parquet(tmp_path / "run" / "episodes.parquet")[
        "requirement:slow-near-people"
    ]
    first, last = robustness[:20].median(), robustness[40:].median()
    assert last < 0.5 * first  # each batch refitted to the episodes nearest a violation
    assert json.loads(done.stdout)["requirements"]["slow-near-people"]["violations"] > 0


@pytest.mark.parametrize(
    ("options", "says"),
    [
        (["--search-on", "separation"], "is not one of the run's requirements"),
        (
            ["--tester", "ppo-acc", "--requirement", "separation", "--search-on", "separation"],
            "learns from the risk summed per decision",
        ),
    ],
)
def test_searching_on_what_cannot_be_searched_is_refused(tmp_path, options, says):
    done = hazardhunt(
        "run", "--scenario", "crossing", "--field", "2m", "--episodes", 5,
        "--out", tmp_path / "run", *options, cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 2
    assert says in done.stderr
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(
    ("lines", "says"),
    [
        (
            'testers = ["random"]\nsearch_on = "separation"\n',
            "is not one of the run's requirements",
        ),
        (
            'testers = ["ppo-acc"]\nrequirements = ["separation"]\nsearch_on = "separation"\n',
            "tester 'ppo-acc' learns from the risk summed per decision",
        ),
        (
            'testers = ["mine"]\nrequirements = ["separation"]\nsearch_on = "separation"\n'
            '[tester.mine]\nmethod = "ppo-novelty"\n',
            "tester 'mine' learns from the risk summed per decision",
        ),
    ],
    ids=["not-a-requirement", "ppo-acc", "method-ppo-novelty"],
)
def test_a_campaign_searching_on_what_cannot_be_searched_is_one_line(tmp_path, lines, says):
    campaign = tmp_path / "campaign.toml"
    campaign.write_text(
        'scenarios = ["crossing"]\nfields = ["2m"]\nseeds = [0]\nepisodes = 5\n' + lines
    )
    done = hazardhunt("campaign", campaign, "--out", tmp_path / "out", cwd=ROOT)
    assert done.returncode == 2
    [line] = done.stderr.strip().splitlines()
    assert line.startswith(f"error: {campaign}: search_on: {says}")
    assert not (tmp_path / "out").exists()
