"""The verdict a report opens with, computed from small tables."""

from pathlib import Path

import pandas as pd

from hazardhunt.analysis import verdict
from hazardhunt.analysis.results import Results
from tests.analysis.test_tables import runs


def campaign() -> Results:
    """cem found two classes (one of them twice) and a failure no class fits, random one class
    late, ppo-max nothing."""
    run_table = runs(
        [
            ("crossing", "1.25m", "cem", 0, 4),
            ("crossing", "1.25m", "random", 0, 1),
            ("crossing", "1.25m", "ppo-max", 0, 0),
        ]
    )
    failures = pd.DataFrame(
        {
            "run_id": ["cem"] * 4 + ["random"],
            "scenario": "crossing",
            "field": "1.25m",
            "tester": ["cem"] * 4 + ["random"],
            "seed": 0,
            "episode": [12, 30, 31, 70, 88],
            "class": [
                "other",
                "side-left/no-stop",
                "side-left/no-stop",
                "side-right/restarted",
                "side-left/no-stop",
            ],
            "max_risk": [101.0, 140.5, 120.0, 140.5, 170.0],
        }
    )
    empty = pd.DataFrame()
    return Results(Path("results/demo"), run_table, empty, failures, empty)


def test_the_verdict_counts_failures_distinct_named_classes_and_the_rest():
    clusters = pd.DataFrame(
        {"scenario": ["crossing"], "field": ["1.25m"], "tester": ["all"], "clusters": [3]}
    )
    found = verdict.verdict(campaign(), clusters)
    assert (found.runs, found.episodes, found.failures) == (3, 300, 5)
    assert found.classes == ("side-left/no-stop", "side-right/restarted")
    assert found.unclassified == 1
    assert found.clusters == 3
    assert verdict.verdict(campaign(), None).clusters is None


def test_the_clusters_of_several_cases_are_those_of_all_failures_together():
    clusters = pd.DataFrame(
        {
            "scenario": ["all", "all", "crossing", "head-on"],
            "field": ["all", "all", "1.25m", "1.25m"],
            "tester": ["all", "cem", "all", "all"],
            "clusters": [5, 4, 2, 2],
        }
    )
    assert verdict.verdict(campaign(), clusters).clusters == 5


def test_the_worst_failure_is_the_one_of_highest_risk():
    worst = verdict.worst_failure(campaign().failures)
    assert worst is not None
    assert (worst["tester"], worst["episode"]) == ("random", 88)
    assert verdict.worst_failure(campaign().failures.iloc[0:0]) is None


def test_the_tester_table_says_who_found_which_class_first_and_when():
    table = verdict.testers_found(campaign()).set_index("found")
    assert list(table.columns) == ["cem", "random", "ppo-max"]
    assert table.loc["unsafe failures"].tolist() == [4, 1, 0]
    assert table.loc["classes found"].tolist() == [2, 1, 0]
    assert table.loc["first failure (episode)"].tolist() == [12, 88, ""]
    assert table.loc["side-left/no-stop"].tolist() == [30, 88, ""]
    assert table.loc["side-right/restarted"].tolist() == [70, "", ""]
    assert "other" not in table.index


def test_the_regression_commands_export_then_regress_the_cases():
    assert verdict.regression_commands(Path("results/my demo"), plugins=False) == [
        "hazardhunt export 'results/my demo' --out 'results/my demo/cases'",
        "hazardhunt regress 'results/my demo/cases'",
    ]
    commands = verdict.regression_commands(
        Path("results/demo"), {"--controller": ["os:system"], "--safety-layer": []}
    )
    # A place for one's own plug-in: never the import path the results name.
    assert commands[1] == "hazardhunt regress results/demo/cases --controller package.module:Class"
    assert not any("--trust-plugins" in command for command in commands)


def test_a_verdict_of_no_failure_does_not_read_as_a_pass():
    from hazardhunt.analysis.report import verdict_headline

    nothing = verdict.Verdict(
        runs=1,
        episodes=300,
        failures=0,
        classes=(),
        unclassified=0,
        clusters=None,
        rate_bound=0.0122,
    )
    said = str(verdict_headline(nothing))
    assert "<strong>No unsafe failure</strong> in 300 episodes of 1 run" in said
    assert "not a proof of safety" in said
    assert "below 0.012 per tested episode" in said
    assert "hazardhunt estimate" in said


def test_a_verdict_with_runs_that_failed_says_so_before_anything_else():
    from hazardhunt.analysis.report import verdict_headline

    results = campaign()
    results.failed["crossing__1.25m__ppo-max__seed1"] = "NothingTested: ... tested nothing"
    findings = verdict.verdict(results, None)
    assert findings.failed_runs == 1
    said = str(verdict_headline(findings))
    assert said.startswith(
        '<strong class="warning">1 run of the campaign failed</strong> and is not in this verdict'
    )
    assert "<strong>5 unsafe failures</strong> in 300 episodes of 3 runs" in said
