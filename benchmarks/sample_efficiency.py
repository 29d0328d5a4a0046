"""How fast each tester finds failures: random vs. ppo-acc vs. ppo-max on one configuration.

For every tester and seed, one run of ``--episodes`` episodes; reports failures found, the
episode of the first failure, failures per quarter of the budget (is it learning?) and
episodes per second. Runs execute two at a time (one per core). Prints a table, writes JSON.

    python benchmarks/sample_efficiency.py --episodes 2000 --seeds 0 1 2
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import statistics
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import pandas as pd

from hazardhunt.campaign.config import RunConfig
from hazardhunt.campaign.run import record_run


def one_run(config: RunConfig) -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as scratch:
        directory = Path(scratch) / "run"
        summary = record_run(config, directory)
        episodes = pd.read_parquet(directory / "episodes.parquet")
    size = max(len(episodes) // 4, 1)
    quarters = [
        int((episodes["outcome"].iloc[i * size : (i + 1) * size] == "failure").sum())
        for i in range(4)
    ]
    outcome_counts = episodes["outcome"].value_counts().to_dict()
    return summary | {"failures_per_quarter": quarters, "outcomes": outcome_counts}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="crossing")
    parser.add_argument("--field", default="1.25m")
    parser.add_argument("--episodes", type=int, default=2000)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--testers", nargs="+", default=["random", "ppo-acc", "ppo-max"])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument(
        "--out", type=Path, default=Path("benchmarks/results/sample_efficiency.json")
    )
    args = parser.parse_args()

    configs = [
        RunConfig(
            scenario=args.scenario,
            field=args.field,
            tester=tester,
            seed=seed,
            episodes=args.episodes,
        )
        for tester in args.testers
        for seed in args.seeds
    ]
    started = time.perf_counter()
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=args.workers, mp_context=context) as pool:
        results = list(pool.map(one_run, configs))
    wall = time.perf_counter() - started

    print(f"{args.scenario} / {args.field}, {args.episodes} episodes per run, seeds {args.seeds}")
    print(
        f"{'tester':8} {'seed':>4} {'failures':>8} {'first':>6} {'per quarter':>22} "
        f"{'stalls':>6} {'episodes/s':>10}"
    )
    for r in results:
        first = "-" if r["first_failure_episode"] is None else str(r["first_failure_episode"])
        quarters = str(r["failures_per_quarter"])
        print(
            f"{r['tester']:8} {r['seed']:4d} {r['failures']:8d} {first:>6} {quarters:>22} "
            f"{r['stalls']:6d} {r['episodes_per_s']:10.2f}"
        )
    aggregate = {}
    for tester in args.testers:
        runs = [r for r in results if r["tester"] == tester]
        failures = [r["failures"] for r in runs]
        firsts = [
            r["first_failure_episode"] for r in runs if r["first_failure_episode"] is not None
        ]
        aggregate[tester] = {
            "failures_mean": statistics.mean(failures),
            "failures_std": statistics.pstdev(failures),
            "first_failure_median": statistics.median(firsts) if firsts else None,
            "runs_without_failure": len(runs) - len(firsts),
            "episodes_per_s_mean": statistics.mean(r["episodes_per_s"] for r in runs),
        }
        a = aggregate[tester]
        print(
            f"{tester:8} mean failures {a['failures_mean']:.1f} +- {a['failures_std']:.1f}, "
            f"median first failure {a['first_failure_median']}, "
            f"{a['episodes_per_s_mean']:.2f} episodes/s"
        )
    print(f"total wall time {wall:.0f} s with {args.workers} workers")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(
        json.dumps(
            {
                "arguments": {k: str(v) for k, v in vars(args).items()},
                "wall_time_s": wall,
                "aggregate": aggregate,
                "runs": results,
            },
            indent=2,
            default=str,
        )
    )
    print(f"written to {args.out}")


if __name__ == "__main__":
    main()
