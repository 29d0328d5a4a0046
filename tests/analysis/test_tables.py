"""The report's tables on small hand-made results, checked against hand-computed values."""

import dataclasses
import math

import pandas as pd
import pytest
from scipy.stats import beta

from hazardhunt.analysis import tables
from hazardhunt.analysis.results import Results
from hazardhunt.spec.episode import EpisodeSummary
from hazardhunt.spec.reward_hacking import LoiteringRule
from hazardhunt.sut.safety_layer import FIELD_SETTINGS


def runs(rows):
    """A runs table from (scenario, field, tester, seed, failures[, wall time]) tuples."""
    frame = pd.DataFrame(
        [
            {
                "run_id": f"{s}__{f}__{t}__seed{seed}",
                "scenario": s,
                "field": f,
                "tester": t,
                "seed": seed,
                "failures": k,
                "episodes": 100,
                "wall_time_s": rest[0] if rest else 10.0,
                "field_shape": dataclasses.asdict(FIELD_SETTINGS[f]),
            }
            for s, f, t, seed, k, *rest in rows
        ]
    )
    return frame


def test_tables_list_testers_in_the_registrys_order_then_plug_ins_by_name():
    table = tables.failure_rates(
        runs([("crossing", "2m", t, 0, 1) for t in ["mine", "ppo-max", "random", "ppo-acc"]])
    )
    assert table["tester"].tolist() == ["random", "ppo-acc", "ppo-max", "mine"]


def test_failures_per_run_is_the_mean_and_spread_over_seeds():
    table = tables.failures_per_run(
        runs([("crossing", "2m", "random", seed, k) for seed, k in enumerate([2, 4, 9])])
    )
    row = table.iloc[0]
    assert (row["mean"], row["min"], row["max"], row["seeds"]) == (5.0, 2, 9, 3)
    assert row["std"] == pytest.approx(math.sqrt(((2 - 5) ** 2 + 1 + 16) / 2))


def test_lesson_1_counts_seed_by_seed_wins_ties_and_losses_against_random():
    table = tables.lesson_1(
        runs(
            [
                ("crossing", "2m", "random", 0, 3),
                ("crossing", "2m", "random", 1, 5),
                ("crossing", "2m", "random", 2, 1),
                ("crossing", "2m", "ppo-max", 0, 4),  # more
                ("crossing", "2m", "ppo-max", 1, 5),  # tie
                ("crossing", "2m", "ppo-max", 2, 0),  # fewer
                ("crossing", "2m", "ppo-max", 3, 9),  # no random run with seed 3: not compared
            ]
        )
    ).set_index("tester")
    row = table.loc["ppo-max"]
    assert (row["more failures than random"], row["ties"], row["fewer"]) == (1, 1, 1)
    assert row["comparisons"] == 3
    assert row["study"] == "24 of 27"


def test_without_a_random_run_to_compare_with_lesson_1_is_empty():
    table = tables.lesson_1(
        runs([("crossing", "2m", "ppo-max", 0, 4), ("head-on", "2m", "random", 0, 1)])
    )
    assert table.empty


def test_a_rate_ratio_interval_is_the_exact_interval_of_the_runs_share_of_the_pairs_failures():
    ratio, low, high = tables.rate_ratio(30, 1000, 10, 1000)
    share = beta.ppf([0.025, 0.975], [30, 31], [11, 10])  # Clopper-Pearson of 30 in 40
    assert ratio == pytest.approx(3.0)
    assert (low, high) == pytest.approx(tuple(share / (1 - share)))
    # twice the episodes for the same failures is half the rate
    assert tables.rate_ratio(30, 2000, 10, 1000)[0] == pytest.approx(1.5)
    assert tables.rate_ratio(5, 100, 0, 100)[0] == math.inf
    assert tables.rate_ratio(0, 100, 5, 100)[:2] == (0.0, 0.0)
    assert math.isnan(tables.rate_ratio(0, 100, 0, 100)[0])


def test_lesson_1_by_case_holds_a_verdict_only_when_every_seed_gives_it():
    table = tables.lesson_1_by_case(
        runs(
            [
                ("crossing", "2m", "random", 0, 3),
                ("crossing", "2m", "random", 1, 5),
                ("crossing", "2m", "ppo-max", 0, 40),  # clearly ahead
                ("crossing", "2m", "ppo-max", 1, 60),  # clearly ahead
                ("crossing", "2m", "ppo-max", 2, 99),  # no random run with seed 2: not compared
                ("head-on", "2m", "random", 0, 30),
                ("head-on", "2m", "random", 1, 30),
                ("head-on", "2m", "ppo-max", 0, 80),  # ahead
                ("head-on", "2m", "ppo-max", 1, 31),  # within the noise
                ("overtaking", "2m", "random", 0, 50),
                ("overtaking", "2m", "ppo-max", 0, 2),  # behind
            ]
        )
    ).set_index(["scenario", "tester"])
    crossing = table.loc[("crossing", "ppo-max")]
    assert crossing["seeds"] == "0 / 1"
    assert crossing["failures (tester / random)"] == "40 / 3; 60 / 5"
    assert crossing["verdict"] == "ahead"
    assert table.loc[("head-on", "ppo-max"), "verdict"] == "mixed"
    assert table.loc[("overtaking", "ppo-max"), "verdict"] == "behind"
    assert ("crossing", "random") not in table.index


def test_class_coverage_counts_distinct_named_classes_over_seeds_not_other():
    run_table = runs([("crossing", "1.25m", "random", 0, 3), ("crossing", "1.25m", "random", 1, 1)])
    failures = pd.DataFrame(
        {
            "scenario": "crossing",
            "field": "1.25m",
            "tester": "random",
            "seed": [0, 0, 0, 1],
            "class": ["side-left/no-stop", "side-left/no-stop", "other", "side-right/no-stop"],
        }
    )
    empty = pd.DataFrame()
    results = Results(None, run_table, empty, failures, empty)  # type: ignore[arg-type]
    row = tables.class_coverage(results).iloc[0]
    assert row["k / K"] == "2 / 10"
    assert row["per seed"] == "1 / 1"
    assert row["study k / K"] == "5 / 9"
    assert row["classes"] == "side-left/no-stop, side-right/no-stop, other"


def test_runtime_speedup_is_the_studys_and_scales_to_20000_episodes():
    table = tables.runtime_table(
        runs(
            [
                ("crossing", "1.25m", "ppo-acc", 0, 0, 200.0),
                ("crossing", "1.25m", "ppo-acc", 1, 0, 400.0),
                ("crossing", "1.25m", "ppo-max", 0, 0, 150.0),
            ]
        )
    )
    row = table.iloc[0]
    assert row["speedup"] == pytest.approx(0.5)  # 1 - 150 / 300
    assert row["ppo-max per 20k (h:mm)"] == "8:20"  # 1.5 s per episode x 20,000
    assert row["study ppo-max (h:mm)"] == "34:23"
    assert row["study speedup"] == pytest.approx(0.186, abs=1e-3)
    assert row["faster than the study (ppo-max)"] == pytest.approx((34 * 60 + 23) / 500)


@pytest.mark.parametrize(
    ("k", "n", "low", "high"),
    [
        (0, 10, 0.0, 1 - 0.025 ** (1 / 10)),
        (10, 10, 0.025 ** (1 / 10), 1.0),
        (5, 10, 0.187086, 0.812914),
    ],
)
def test_clopper_pearson_matches_the_exact_interval(k, n, low, high):
    assert tables.clopper_pearson(k, n) == pytest.approx((low, high), abs=1e-6)


@pytest.mark.parametrize(
    ("k", "n", "confidence"),
    [(1, 20, 0.95), (3, 100, 0.90), (7, 7, 0.99), (0, 1, 0.95), (412, 20000, 0.95)],
)
def test_clopper_pearson_is_the_beta_quantile_interval(k, n, confidence):
    tail = (1 - confidence) / 2
    low = 0.0 if k == 0 else beta.ppf(tail, k, n - k + 1)
    high = 1.0 if k == n else beta.ppf(1 - tail, k + 1, n - k)
    assert tables.clopper_pearson(k, n, confidence) == pytest.approx((low, high), abs=1e-9)


def test_clopper_pearson_without_trials_is_the_whole_range():
    assert tables.clopper_pearson(0, 0) == (0.0, 1.0)


def test_failure_rates_pool_the_seeds():
    rates = tables.failure_rates(
        runs([("crossing", "2m", "random", 0, 3), ("crossing", "2m", "random", 1, 1)])
    )
    row = rates.iloc[0]
    assert (row["failures"], row["episodes"], row["rate"]) == (4, 200, 0.02)
    assert row["low"] < 0.02 < row["high"]


def test_learning_curves_show_failures_rising_over_the_run():
    outcomes = ["goal"] * 50 + ["failure", "goal"] * 25
    episodes = pd.DataFrame(
        {
            "run_id": "r",
            "tester": "ppo-max",
            "field": "2m",
            "episode": range(100),
            "outcome": outcomes,
        }
    )
    curve = tables.learning_curves(episodes, bins=2)
    assert curve["episode"].tolist() == [50, 100]
    assert curve["failures per 100 episodes"].tolist() == [0.0, 50.0]


def test_reward_hacking_measures_time_in_field_stops_and_loitering_per_tester():
    episodes = pd.DataFrame(
        {
            "tester": "ppo-acc",
            "outcome": ["stall", "timeout", "failure", "goal"],
            "time_in_field": [10.0, 4.0, 0.0, 2.0],
            "emergency_stops": [1, 3, 0, 0],
            "risk_sum": [20.0, 10.0, 1.0, 0.0],
            "loitering": [True, True, False, False],
        }
    )
    row = tables.reward_hacking(episodes).iloc[0]
    assert row["time in field per episode (s)"] == 4.0
    assert row["emergency stops per episode"] == 1.0
    assert (row["stall share"], row["timeout share"]) == (0.25, 0.25)
    assert row["risk sum without failure"] == 10.0
    assert (row["loitering episodes"], row["loitering share"]) == (2, 0.5)


@pytest.mark.parametrize(
    ("outcome", "stops", "in_field", "loiters"),
    [
        ("stall", 1, 10.0, True),
        ("timeout", 2, 2.0, True),
        ("goal", 3, 1.0, False),  # stops, but hardly in the field
        ("timeout", 1, 8.0, False),  # one long stop that was not a stall
        ("failure", 5, 9.0, False),  # a failure is what the search is after
    ],
)
def test_the_loitering_rule(outcome, stops, in_field, loiters):
    summary = EpisodeSummary(outcome, emergency_stops=stops, time_in_field=in_field)
    assert LoiteringRule().matches(summary) is loiters


def test_the_representative_of_a_class_has_its_median_time_to_contact():
    failures = pd.DataFrame(
        {"class": ["a", "a", "a", "b"], "sim_time": [1.0, 5.0, 9.5, 3.0], "episode": range(4)}
    )
    chosen = tables.representatives(failures).set_index("class")
    assert chosen.loc["a", "episode"] == 1
    assert chosen.loc["b", "episode"] == 3


def test_the_typical_loitering_episode_is_the_one_nearest_the_median():
    loitering = pd.DataFrame(
        {"episode": [0, 1, 2], "time_in_field": [2.0, 6.0, 30.0], "emergency_stops": [2, 4, 9]}
    )
    assert tables.typical_loitering(loitering)["episode"] == 1
    assert tables.typical_loitering(loitering.iloc[0:0]) is None


def test_lesson_2_compares_classes_found_case_by_case_and_counts_the_studys_table_too():
    coverage = pd.DataFrame(
        {
            "scenario": ["crossing"] * 4 + ["head-on"] * 2,
            "field": ["2m", "2m", "none", "none", "2m", "2m"],
            "tester": ["random", "ppo-max", "random", "ppo-max", "random", "ppo-max"],
            "found": [3, 5, 4, 4, 6, 1],
        }
    )
    row = tables.lesson_2(coverage).iloc[0]
    assert (row["more classes than random"], row["as many"], row["fewer"]) == (1, 1, 1)
    # The study: ppo-max found more classes than random in 4 cases and fewer in 1 of 9.
    assert row["study (more / as many / fewer)"] == "4 / 4 / 1"


def test_failures_per_class_counts_each_testers_failures_of_each_class():
    failures = pd.DataFrame(
        {
            "episode": range(4),
            "tester": ["random", "ppo-max", "ppo-max", "ppo-max"],
            "class": ["left/moving", "left/moving", "left/moving", "front/moving"],
        }
    )
    table = tables.failures_per_class(failures).set_index("class")
    assert table.loc["left/moving", "ppo-max"] == 2
    assert table.loc["front/moving", "random"] == 0


def test_runtime_table_gives_the_simulated_hours_that_no_machine_load_biases():
    run_table = runs(
        [
            ("crossing", "1.25m", "ppo-acc", 0, 0, 200.0),
            ("crossing", "1.25m", "ppo-max", 0, 0, 900.0),  # slower only because the machine was
        ]
    )
    episodes = pd.DataFrame(
        {
            "run_id": [run_table["run_id"][0]] * 2 + [run_table["run_id"][1]] * 2,
            "sim_time": [3600.0, 3600.0, 1800.0, 1800.0],
        }
    )
    row = tables.runtime_table(run_table, episodes).iloc[0]
    assert row["speedup"] < 0
    assert (row["ppo-acc simulated (h)"], row["ppo-max simulated (h)"]) == (2.0, 1.0)
    assert row["simulated speedup"] == pytest.approx(0.5)


def test_runtime_table_gives_cpu_times_only_where_every_run_recorded_one():
    recorded = runs(
        [
            ("crossing", "1.25m", "ppo-acc", 0, 0, 200.0),
            ("crossing", "1.25m", "ppo-acc", 1, 0, 300.0),
            ("crossing", "1.25m", "ppo-max", 0, 0, 900.0),
            ("head-on", "1.25m", "ppo-acc", 0, 0, 200.0),
            ("head-on", "1.25m", "ppo-max", 0, 0, 100.0),
        ]
    )
    recorded["cpu_time_s"] = [180.0, 220.0, 100.0, 150.0, math.nan]  # head-on's ppo-max: older
    table = tables.runtime_table(recorded).set_index("scenario")
    crossing = table.loc["crossing"]
    assert (crossing["ppo-acc CPU (s)"], crossing["ppo-max CPU (s)"]) == (200.0, 100.0)
    assert crossing["CPU speedup"] == pytest.approx(0.5)  # where the wall time says -260 %
    assert math.isnan(table.loc["head-on", "CPU speedup"])
    assert "CPU speedup" not in tables.runtime_table(recorded.drop(columns="cpu_time_s"))
