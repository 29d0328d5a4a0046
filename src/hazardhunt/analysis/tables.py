"""The study's tables and hazardhunt's own, computed from a campaign's results (SPEC 8).

Each function takes the tables of ``Results`` and returns a plain DataFrame, one row per line of
the printed table, so that the report can write it as CSV, Markdown and HTML alike.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd
from scipy.stats import binomtest

from hazardhunt.analysis.results import Results, in_tester_order
from hazardhunt.analysis.study import (
    STUDY_BASELINE,
    STUDY_CLASSES,
    STUDY_EPISODES,
    STUDY_LESSON_1,
    STUDY_REWARDS,
    STUDY_RUNTIME_MINUTES,
)
from hazardhunt.spec.failure_classes import OTHER
from hazardhunt.testers.registry import sort_testers


def failures_per_run(runs: pd.DataFrame) -> pd.DataFrame:
    """Failures per run by field, scenario and tester: mean and spread over the seeds."""
    grouped = runs.groupby(["field", "scenario", "tester"], sort=True)["failures"]
    table = grouped.agg(["mean", "std", "min", "max", "count"]).reset_index()
    table["std"] = table["std"].fillna(0.0)
    return in_tester_order(table.rename(columns={"count": "seeds"}), ("field", "scenario"))


def class_coverage(results: Results) -> pd.DataFrame:
    """Table I: the distinct classes found over all seeds, ``k / K``, beside the study's, and
    how many each seed found (``per seed``, in the seeds' order: ``5 / 4``).

    ``other`` is listed but not counted in k; K is the number of named classes (as the runs
    recorded it when the results' classifier is not known).
    """
    rows = []
    failures = results.failures
    for (scenario, field, tester), runs in results.runs.groupby(["scenario", "field", "tester"]):
        mask = (
            (failures["scenario"] == scenario)
            & (failures["field"] == field)
            & (failures["tester"] == tester)
        )
        found = set(failures.loc[mask, "class"]) if "class" in failures else set()
        classes = results.classes_for(field, scenario)
        if classes is None:
            total = int(runs["classes_total"].max())
            classes = (*sorted(found - {OTHER}), OTHER)
        else:
            total = len(classes) - 1
        study = STUDY_CLASSES.get((scenario, field), {}).get(tester)
        named = failures.loc[mask & (failures["class"] != OTHER)] if found else failures.iloc[:0]
        per_seed = [
            named.loc[named["seed"] == seed, "class"].nunique() for seed in sorted(runs["seed"])
        ]
        rows.append(
            {
                "scenario": scenario,
                "field": field,
                "tester": tester,
                "found": len(found - {OTHER}),
                "total": total,
                "k / K": f"{len(found - {OTHER})} / {total}",
                "per seed": " / ".join(str(count) for count in per_seed),
                "study k / K": f"{study[0]} / {study[1]}" if study else "",
                "classes": ", ".join(name for name in classes if name in found),
            }
        )
    return in_tester_order(pd.DataFrame(rows), ("scenario", "field"))


def lesson_2(coverage: pd.DataFrame) -> pd.DataFrame:
    """Lesson 2: in how many (scenario, field) cases each tester found more, as many or fewer
    distinct classes than the baseline, random sampling (from ``class_coverage``), beside the
    same count over the study's Table I."""
    rows = []
    for tester, (more, same, fewer, cases) in _against_baseline(
        coverage, ["scenario", "field"], "found"
    ):
        study = [
            (found[tester][0], found[STUDY_BASELINE][0])
            for found in STUDY_CLASSES.values()
            if tester in found
        ]
        rows.append(
            {
                "tester": tester,
                f"more classes than {STUDY_BASELINE}": more,
                "as many": same,
                "fewer": fewer,
                "cases": cases,
                "study (more / as many / fewer)": (
                    f"{sum(a > b for a, b in study)} / {sum(a == b for a, b in study)} / "
                    f"{sum(a < b for a, b in study)}"
                    if study
                    else ""
                ),
            }
        )
    return pd.DataFrame(rows)


def failures_per_class(failures: pd.DataFrame) -> pd.DataFrame:
    """How often each tester found each class (all scenarios, fields and seeds)."""
    if failures.empty or "class" not in failures:
        return pd.DataFrame(columns=["class"])
    counts = failures.pivot_table(
        index="class", columns="tester", values="episode", aggfunc="count", fill_value=0
    )
    counts = counts[sort_testers(counts.columns)]
    return counts.reset_index().rename_axis(columns=None)


def runtime_table(runs: pd.DataFrame, episodes: pd.DataFrame | None = None) -> pd.DataFrame:
    """Table II: mean wall time per run of the accumulated-reward and the maximum-reward tester
    (``STUDY_REWARDS``: ppo-acc and ppo-max) and the speedup.

    The speedup is the study's: 1 - max / acc. Beside the measured means are the same runs
    scaled to the study's 20,000 episodes, and the study's own runtimes. With the runs'
    ``episodes``, also the mean simulated hours per run and the speedup they give, which no
    load on the machine can bias (wall times of runs that shared a machine are not comparable),
    and, where every run of both testers recorded it (``cpu_time_s``, from version 0.2.0), the
    mean CPU time per run and the speedup by it.
    """
    acc, most = STUDY_REWARDS
    rows = []
    rl = runs[runs["tester"].isin([acc, most])]
    simulated = None
    if episodes is not None and {"run_id", "sim_time"} <= set(episodes.columns):
        simulated = episodes.groupby("run_id")["sim_time"].sum() / 3600.0
    for (scenario, field), group in rl.groupby(["scenario", "field"], sort=True):
        means = group.groupby("tester")["wall_time_s"].mean()
        per_episode = (group["wall_time_s"] / group["episodes"]).groupby(group["tester"]).mean()
        if not {acc, most} <= set(means.index):
            continue
        study = STUDY_RUNTIME_MINUTES.get((scenario, field))
        row: dict[str, Any] = {
            "scenario": scenario,
            "field": field,
            f"{acc} (s)": means[acc],
            f"{most} (s)": means[most],
            "speedup": 1.0 - means[most] / means[acc],
            f"{acc} per 20k (h:mm)": hours_minutes(per_episode[acc] * STUDY_EPISODES),
            f"{most} per 20k (h:mm)": hours_minutes(per_episode[most] * STUDY_EPISODES),
        }
        if "cpu_time_s" in group and group["cpu_time_s"].notna().all():
            cpu_means = group.groupby("tester")["cpu_time_s"].mean()
            row |= {
                f"{acc} CPU (s)": cpu_means[acc],
                f"{most} CPU (s)": cpu_means[most],
                "CPU speedup": 1.0 - cpu_means[most] / cpu_means[acc],
            }
        if simulated is not None:
            hours = simulated.reindex(group["run_id"]).groupby(group["tester"].to_numpy()).mean()
            row |= {
                f"{acc} simulated (h)": hours[acc],
                f"{most} simulated (h)": hours[most],
                "simulated speedup": 1.0 - hours[most] / hours[acc],
            }
        if study:
            row |= {
                f"study {acc} (h:mm)": hours_minutes(study[acc] * 60.0),
                f"study {most} (h:mm)": hours_minutes(study[most] * 60.0),
                "study speedup": 1.0 - study[most] / study[acc],
                f"faster than the study ({most})": study[most]
                * 60.0
                / (per_episode[most] * STUDY_EPISODES),
            }
        rows.append(row)
    return pd.DataFrame(rows)


def lesson_1(runs: pd.DataFrame) -> pd.DataFrame:
    """Lesson 1: in how many (scenario, field, seed) comparisons each tester found more
    failures than the baseline, random sampling, beside the study's counts."""
    rows = []
    for tester, (more, same, fewer, comparisons) in _against_baseline(
        runs, ["scenario", "field", "seed"], "failures"
    ):
        study = STUDY_LESSON_1.get(tester)
        rows.append(
            {
                "tester": tester,
                f"more failures than {STUDY_BASELINE}": more,
                "ties": same,
                "fewer": fewer,
                "comparisons": comparisons,
                "study": f"{study[0]} of {study[1]}" if study else "",
            }
        )
    return pd.DataFrame(rows)


def rate_ratio(
    own: int, own_episodes: int, baseline: int, baseline_episodes: int, confidence: float = 0.95
) -> tuple[float, float, float]:
    """How many times the baseline's failure rate one run's is, with its exact interval.

    The conditional test of two Poisson rates: given the pair's failures, the first run's share
    of them is binomial, and the Clopper-Pearson interval of that share, turned into a ratio of
    rates with the episodes played as the exposures, is the interval. It treats every episode
    of a run as an independent trial, which a tester that learns as it runs is not; read it as
    what the counts alone allow. (ratio, low, high); a ratio with nothing to divide by is
    ``inf``, and without failures on either side the ratio is undefined (nan in (0, inf)).
    """
    exposure = own_episodes / baseline_episodes
    pair = own + baseline
    if pair == 0:
        return math.nan, 0.0, math.inf
    low, high = clopper_pearson(own, pair, confidence)

    def ratio(share: float) -> float:
        return math.inf if share >= 1.0 else share / (1.0 - share) / exposure

    return ratio(own / pair), ratio(low), ratio(high)


def lesson_1_by_case(runs: pd.DataFrame, confidence: float = 0.95) -> pd.DataFrame:
    """Lesson 1 case by case: for each tester and (scenario, field) it shares a seed with the
    baseline on, the failures of both per seed, the ratio of their failure rates with its exact
    interval (:func:`rate_ratio`), and the verdict: ``ahead`` where the interval lies above 1 in
    every seed compared, ``behind`` where below 1 in every one, ``mixed`` otherwise."""
    keys = ["scenario", "field", "seed"]
    rows = []
    for tester, paired in _paired_with_baseline(runs, keys, ["failures", "episodes"]):
        for (scenario, field), group in paired.groupby(level=["scenario", "field"], sort=True):
            seeds, counts, ratios, sides = [], [], [], []
            for (_, _, seed), row in group.iterrows():
                value, low, high = rate_ratio(
                    int(row["failures"]),
                    int(row["episodes"]),
                    int(row["failures_baseline"]),
                    int(row["episodes_baseline"]),
                    confidence,
                )
                seeds.append(str(seed))
                counts.append(f"{int(row['failures']):,} / {int(row['failures_baseline']):,}")
                ratios.append(f"{value:.2f} [{low:.2f}, {high:.2f}]")
                sides.append("ahead" if low > 1.0 else "behind" if high < 1.0 else "neither")
            verdict = sides[0] if len(set(sides)) == 1 and sides[0] != "neither" else "mixed"
            rows.append(
                {
                    "scenario": scenario,
                    "field": field,
                    "tester": tester,
                    "seeds": " / ".join(seeds),
                    f"failures (tester / {STUDY_BASELINE})": "; ".join(counts),
                    f"rate ratio [{confidence:.0%}]": "; ".join(ratios),
                    "verdict": verdict,
                }
            )
    return pd.DataFrame(rows)


def _paired_with_baseline(
    table: pd.DataFrame, keys: list[str], columns: list[str]
) -> list[tuple[str, pd.DataFrame]]:
    """Per tester but the baseline that shares a case with it (a row with the same ``keys``
    as a baseline row), in tester order: its ``columns`` and the baseline's (``NAME_baseline``)
    in the cases they share, indexed by ``keys``. Without a shared case a tester is left out."""
    baseline = table.loc[table["tester"] == STUDY_BASELINE, [*keys, *columns]].set_index(keys)
    baseline.columns = [f"{name}_baseline" for name in columns]
    pairs = []
    for tester in sort_testers(table["tester"]):
        if tester == STUDY_BASELINE:
            continue
        own = table.loc[table["tester"] == tester, [*keys, *columns]].set_index(keys)
        paired = own.join(baseline, how="inner").sort_index()
        if not paired.empty:
            pairs.append((str(tester), paired))
    return pairs


def _against_baseline(
    table: pd.DataFrame, keys: list[str], value: str
) -> list[tuple[str, tuple[int, int, int, int]]]:
    """Per tester that shares a case with the baseline (:func:`_paired_with_baseline`): in how
    many cases its ``value`` is larger, equal or smaller than the baseline's, and the cases."""
    counts = []
    for tester, paired in _paired_with_baseline(table, keys, [value]):
        own, other = paired[value], paired[f"{value}_baseline"]
        more, same, fewer = (
            int((own > other).sum()),
            int((own == other).sum()),
            int((own < other).sum()),
        )
        counts.append((tester, (more, same, fewer, len(paired))))
    return counts


def reward_hacking(episodes: pd.DataFrame) -> pd.DataFrame:
    """Lesson 3, measured per tester: the human's time in the field and the stops it caused per
    episode, the share of stalls and timeouts, the risk summed over episodes without a failure
    (what the accumulated reward pays), and the episodes flagged as loitering."""
    rows = []
    for tester in sort_testers(episodes["tester"]):
        group = episodes[episodes["tester"] == tester]
        no_failure = group[group["outcome"] != "failure"]
        loitering = group["loitering"] if "loitering" in group else pd.Series(False, group.index)
        rows.append(
            {
                "tester": tester,
                "episodes": len(group),
                "time in field per episode (s)": group["time_in_field"].mean(),
                "emergency stops per episode": group["emergency_stops"].mean(),
                "stall share": (group["outcome"] == "stall").mean(),
                "timeout share": (group["outcome"] == "timeout").mean(),
                "risk sum without failure": no_failure["risk_sum"].mean(),
                "loitering episodes": int(loitering.sum()),
                "loitering share": float(loitering.mean()),
            }
        )
    return pd.DataFrame(rows)


def clopper_pearson(failures: int, trials: int, confidence: float = 0.95) -> tuple[float, float]:
    """The exact (Clopper-Pearson) confidence interval of a failure rate; (0, 1) without trials."""
    if trials <= 0:
        return 0.0, 1.0
    interval = binomtest(failures, trials).proportion_ci(
        confidence_level=confidence, method="exact"
    )
    return float(interval.low), float(interval.high)


def failure_rates(runs: pd.DataFrame, confidence: float = 0.95) -> pd.DataFrame:
    """Failures per episode by scenario, field and tester (seeds pooled), with the exact
    confidence interval."""
    totals = runs.groupby(["scenario", "field", "tester"], sort=True)[["failures", "episodes"]]
    table = totals.sum().reset_index()
    bounds = [
        clopper_pearson(int(k), int(n), confidence)
        for k, n in zip(table["failures"], table["episodes"], strict=True)
    ]
    table["rate"] = table["failures"] / table["episodes"]
    table["low"] = [low for low, _ in bounds]
    table["high"] = [high for _, high in bounds]
    return in_tester_order(table, ("scenario", "field"))


def learning_curves(episodes: pd.DataFrame, bins: int = 20, per: int = 100) -> pd.DataFrame:
    """Failures per ``per`` episodes over the course of the runs, per tester and field (mean
    over scenarios and seeds), in ``bins`` equal slices of the budget; the last column is
    named ``failures per <per> episodes``."""
    column = f"failures per {per} episodes"
    if episodes.empty:
        return pd.DataFrame(columns=["tester", "field", "episode", column])
    budget = int(episodes["episode"].max()) + 1
    width = max(1, int(np.ceil(budget / bins)))
    frame = episodes.assign(
        slice=episodes["episode"] // width, failed=episodes["outcome"] == "failure"
    )
    per_run = frame.groupby(["tester", "field", "run_id", "slice"])["failed"].mean()
    curves = per_run.groupby(["tester", "field", "slice"]).mean().reset_index()
    curves["episode"] = (curves["slice"] + 1) * width
    curves[column] = per * curves["failed"]
    return in_tester_order(curves[["tester", "field", "episode", column]])


def representatives(failures: pd.DataFrame) -> pd.DataFrame:
    """One failure per class: the one whose time to contact is the class's median (ties: the
    first in run order)."""
    if failures.empty or "class" not in failures:
        return failures.iloc[0:0]
    chosen = []
    for _, group in failures.groupby("class", sort=True):
        distance = (group["sim_time"] - group["sim_time"].median()).abs()
        chosen.append(group.loc[distance.idxmin()])
    return pd.DataFrame(chosen).reset_index(drop=True)


def typical_loitering(loitering: pd.DataFrame) -> pd.Series | None:
    """The loitering episode closest to the median time in field and number of stops."""
    if loitering.empty:
        return None
    features = loitering[["time_in_field", "emergency_stops"]].astype(float)
    spread = features.std().replace(0.0, 1.0).fillna(1.0)
    distance = (((features - features.median()) / spread) ** 2).sum(axis=1)
    return loitering.loc[distance.idxmin()]


def hours_minutes(seconds: float) -> str:
    minutes = round(seconds / 60.0)
    return f"{minutes // 60}:{minutes % 60:02d}"


def class_discovery(failures: pd.DataFrame) -> pd.DataFrame:
    """When each tester first found each class, per (scenario, field) case: the earliest
    ``episode`` over the seeds (its index in the run, as ``hazardhunt replay`` takes it) and the
    ``seed`` of that run; one row per class found, in the order found."""
    columns = ["scenario", "field", "tester", "class", "episode", "seed"]
    if failures.empty or "class" not in failures:
        return pd.DataFrame(columns=columns)
    earliest = failures.sort_values(["episode", "seed"], kind="stable")
    first = earliest.groupby(["scenario", "field", "tester", "class"], sort=False).head(1)
    first = first.sort_values(["scenario", "field", "tester", "episode", "class"])
    return first[columns].reset_index(drop=True)


def class_discovery_curves(discovery: pd.DataFrame, runs: pd.DataFrame) -> pd.DataFrame:
    """Distinct classes found against episodes played, per case and tester (seeds pooled and
    ``other`` not counted, as in Table I): one row per step of the curve, from 0 episodes to
    the budget (the longest run of the case and tester)."""
    rows = []
    for (scenario, field, tester), group in runs.groupby(["scenario", "field", "tester"]):
        keys = {"scenario": scenario, "field": field, "tester": tester}
        found = discovery[
            (discovery["scenario"] == scenario)
            & (discovery["field"] == field)
            & (discovery["tester"] == tester)
            & (discovery["class"] != OTHER)
        ]
        steps = (found["episode"].astype(int) + 1).value_counts().sort_index().cumsum()
        rows.append(keys | {"episodes": 0, "classes found": 0})
        rows += [
            keys | {"episodes": int(played), "classes found": int(count)}
            for played, count in steps.items()
        ]
        rows.append(keys | {"episodes": int(group["episodes"].max()), "classes found": len(found)})
    return pd.DataFrame(rows, columns=["scenario", "field", "tester", "episodes", "classes found"])


def class_first_found(discovery: pd.DataFrame) -> pd.DataFrame:
    """The episode at which each tester first found each class (from ``class_discovery``):
    one row per (scenario, field, class), one column per tester, blank where the tester never
    found it; the classes of a case in the order any tester first found them."""
    if discovery.empty:
        return pd.DataFrame(columns=["scenario", "field", "class"])
    wide = discovery.pivot_table(
        index=["scenario", "field", "class"], columns="tester", values="episode", aggfunc="min"
    )
    earliest = wide.min(axis=1).rename("earliest")
    wide = wide.join(earliest).reset_index()
    wide = wide.sort_values(["scenario", "field", "earliest", "class"]).drop(columns="earliest")
    testers = [c for c in wide.columns if c not in ("scenario", "field", "class")]
    for tester in testers:  # whole episode numbers, not floats with a blank as NaN
        wide[tester] = [
            "" if pd.isna(value) else int(value) for value in wide[tester].astype(float)
        ]
    return wide.reset_index(drop=True).rename_axis(columns=None)
