"""Per run, the numbers behind the hand-written lessons of docs/reproduction.md.

The generated tables of docs/reproduction.md give each run's totals; the paragraphs that judge
the study's three lessons also read how a run changes over its budget. For every run kept
under ``benchmarks/results/study/`` this prints its failures and classes, failures per block
of ``--block`` episodes (2,000), and per block of ``--long-block`` (5,000) the loitering
episodes, the share of timeouts, the mean simulated episode and the risk summed by episodes
without a failure; then the simulated hours, failures per simulated hour, the share of
failures with a standing human, time in the field, stalls and timeouts; and for a portfolio run,
per arm the episodes it played and the failures it found, and the arm that found each class
first. After the runs: per class, the failures each arm of the portfolio runs found, over all of
them; and per case (scenario, field) the classes that all runs given found together and the runs
that found every one of them (give the study's and the portfolio's results together to compare
the testers on it).

    python scripts/study_numbers.py
    python scripts/study_numbers.py --results DIR [DIR ...] --block 2000 --long-block 5000
"""

from __future__ import annotations

import argparse
from pathlib import Path

import pandas as pd

from hazardhunt.analysis.results import Results, load_results_of
from hazardhunt.analysis.verdict import ARMS_FILE, episode_arms
from hazardhunt.spec.failure_classes import OTHER

REPOSITORY = Path(__file__).resolve().parents[1]


def blocks(episodes: pd.DataFrame, size: int) -> list[pd.DataFrame]:
    """The run's episodes in consecutive blocks of ``size``."""
    return [group for _, group in episodes.groupby(episodes["episode"] // size, sort=True)]


def describe_run(episodes: pd.DataFrame, failures: pd.DataFrame, block: int, long: int) -> str:
    """The lines printed for one run."""
    failed = episodes["outcome"] == "failure"
    hours = episodes["sim_time"].sum() / 3600
    classes = failures["class"].astype(str).value_counts()
    standing = classes[classes.index.str.contains("standing")].sum() / max(len(failures), 1)
    per_block = [int((b["outcome"] == "failure").sum()) for b in blocks(episodes, block)]
    longer = blocks(episodes, long)
    safe = [b[b["outcome"] != "failure"] for b in longer]
    first = int(episodes.loc[failed, "episode"].min()) if failed.any() else None
    return "\n".join(
        [
            f"  failures {int(failed.sum())}, first at episode {first}",
            f"  classes {classes.to_dict()}",
            f"  failures per {block:,}: {per_block}",
            f"  loitering per {long:,}: {[int(b['loitering'].sum()) for b in longer]}",
            f"  timeouts % per {long:,}: "
            f"{[round(100 * float((b['outcome'] == 'timeout').mean()), 1) for b in longer]}",
            f"  mean episode (s) per {long:,}: "
            f"{[round(float(b['sim_time'].mean()), 1) for b in longer]}",
            f"  risk sum without failure per {long:,}: "
            f"{[round(float(b['risk_sum'].mean()), 1) for b in safe]}",
            f"  simulated hours {hours:.1f}, failures per simulated hour "
            f"{failed.sum() / hours:.1f}, standing share of failures {standing:.3f}",
            f"  time in field per episode {episodes['time_in_field'].mean():.2f} s, "
            f"stalls {int((episodes['outcome'] == 'stall').sum())}, "
            f"timeouts {int((episodes['outcome'] == 'timeout').sum())}",
        ]
    )


def describe_arms(episodes: pd.DataFrame, failures: pd.DataFrame, directory: Path) -> str:
    """For a portfolio run, the lines on its arms; empty for any other run."""
    played = episode_arms(directory / ARMS_FILE)
    if not played:
        return ""
    arm = episodes["episode"].map(played).fillna("unknown")
    failed = episodes["outcome"] == "failure"
    counts = pd.DataFrame({"episodes": arm.value_counts(), "failures": arm[failed].value_counts()})
    counts = counts.fillna(0).astype(int).sort_values("episodes", ascending=False)
    first = failures.sort_values("episode", kind="stable").drop_duplicates("class")
    finders = {
        str(row["class"]): f"{played.get(int(row['episode']), 'unknown')} at {row['episode']}"
        for row in first.to_dict("records")
    }
    shares = ", ".join(f"{name} {row.episodes} ({row.failures})" for name, row in counts.iterrows())
    return f"  arms (episodes, failures): {shares}\n  first of each class: {finders}"


def classes_by_arm(results: Results) -> dict[str, dict[str, int]]:
    """Per class, the failures each portfolio arm found, over every portfolio run given."""
    found: dict[str, dict[str, int]] = {}
    for run_id, directory in zip(results.runs["run_id"], results.runs["directory"], strict=True):
        played = episode_arms(Path(directory) / ARMS_FILE)
        if not played:  # not a portfolio run
            continue
        own = results.failures[results.failures["run_id"] == run_id]
        for name, episode in zip(own["class"].astype(str), own["episode"], strict=True):
            per_arm = found.setdefault(name, {})
            arm = played.get(int(episode), "unknown")
            per_arm[arm] = per_arm.get(arm, 0) + 1
    return found


def union_reached(results: Results) -> list[str]:
    """Per case, the lines on the classes all runs found together and the runs that found all."""
    named = results.failures[results.failures["class"].astype(str) != OTHER]
    lines = []
    for (scenario, field), runs in results.runs.groupby(["scenario", "field"], sort=True):
        case = named[(named["scenario"] == scenario) & (named["field"] == field)]
        union = set(case["class"].astype(str))
        reached = [
            run_id
            for run_id in sorted(runs["run_id"])
            if set(case.loc[case["run_id"] == run_id, "class"].astype(str)) == union
        ]
        lines.append(f"{scenario} / {field}: {len(union)} classes; all of them: {reached}")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    default = REPOSITORY / "benchmarks" / "results" / "study"
    parser.add_argument("--results", type=Path, nargs="+", default=[default])
    parser.add_argument("--block", type=int, default=2000, help="episodes per failure count")
    parser.add_argument("--long-block", type=int, default=5000, help="episodes per trend")
    args = parser.parse_args()
    results = load_results_of(args.results)
    directories = dict(zip(results.runs["run_id"], results.runs["directory"], strict=True))
    for run_id, episodes in results.episodes.groupby("run_id", sort=True):
        print(run_id)
        failures = results.failures[results.failures["run_id"] == run_id]
        episodes = episodes.sort_values("episode")
        print(describe_run(episodes, failures, args.block, args.long_block))
        arms = describe_arms(episodes, failures, Path(directories[run_id]))
        if arms:
            print(arms)
    by_arm = classes_by_arm(results)
    if by_arm:
        print("failures per class and arm, over every portfolio run")
        for name, per_arm in sorted(by_arm.items()):
            print(f"  {name}: {dict(sorted(per_arm.items(), key=lambda item: -item[1]))}")
    print("classes per case, of every run given together")
    for line in union_reached(results):
        print(f"  {line}")


if __name__ == "__main__":
    main()
