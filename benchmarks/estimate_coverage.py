"""Do the estimators' 95 % intervals cover a probability known in closed form?

Repeats each estimator on the closed-form test system (:mod:`hazardhunt.likelihood.toy`) with
seeds 0, 1, ... and reports, per estimator and case, how often the interval covered the true
probability, the estimates' mean and spread relative to it, the median reported relative
error, the episodes played, and the episodes plain Monte Carlo would need for the spread
measured (``(1 - p) / (p * spread^2)``).

    python benchmarks/estimate_coverage.py --repetitions 200 \\
        --out benchmarks/results/estimate_coverage.json
    python benchmarks/estimate_coverage.py --repetitions 200 --methods splitting
    python benchmarks/estimate_coverage.py --repetitions 200 --idle-only --penalty 0
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from hazardhunt.likelihood.estimators import EstimatorParams, episodes_for
from hazardhunt.likelihood.results import summarise
from hazardhunt.likelihood.run import EstimateConfig, EstimateRun
from hazardhunt.likelihood.toy import ClosedFormEncounters

CASES = (
    # (name, threshold, p_looks, idle variables, method, episodes, batch size)
    ("common, mc", 0.0, 0.5, 0, "mc", 1000, 100),
    ("rare with a discrete cause, ce", 3.5, 0.9, 0, "ce", 1000, 100),
    ("rare with a discrete cause, ce", 4.0, 0.9, 0, "ce", 1000, 100),
    ("rare, ce", 5.0, 0.0, 0, "ce", 1000, 100),
    ("rare with a discrete cause, 9 idle, ce", 4.0, 0.9, 9, "ce", 1000, 100),
    ("rare, 9 idle, ce", 5.0, 0.0, 9, "ce", 1000, 100),
    ("rare, splitting", 5.0, 0.0, 0, "splitting", 2000, 300),
    ("rarer, splitting", 5.5, 0.0, 0, "splitting", 3000, 500),
)


def repeat(
    threshold: float,
    p_looks: float,
    idle: int,
    method: str,
    episodes: int,
    size: int,
    reps: int,
    penalty: float = 2.0,
):
    toy = ClosedFormEncounters(threshold=threshold, p_looks=p_looks, idle=idle)
    truth = toy.probability
    estimates, covered, reported, played = [], 0, [], []
    for seed in range(reps):
        config = EstimateConfig(
            episodes=episodes,
            seed=seed,
            estimator=EstimatorParams(
                method=method,  # type: ignore[arg-type]
                batch_size=size,
                penalty=penalty,
            ),
        )
        with tempfile.TemporaryDirectory() as directory:
            table = EstimateRun(config, Path(directory), source=toy).run()
        result = summarise(config, table, toy.threshold)["probability"]
        estimates.append(result["probability"])
        covered += result["low"] <= truth <= result["high"]
        reported.append(result["relative_error"] or 0.0)
        played.append(len(table))
    spread = float(np.std(estimates) / truth)
    return {
        "probability": truth,
        "method": method,
        "threshold": threshold,
        "p_looks": p_looks,
        "idle": idle,
        "penalty": penalty if method == "ce" else None,
        "budget": episodes,
        "repetitions": reps,
        "coverage": covered / reps,
        "mean_over_truth": float(np.mean(estimates) / truth),
        "relative_spread": spread,
        "median_reported_relative_error": float(np.median(reported)),
        "median_episodes": float(np.median(played)),
        "monte_carlo_episodes_for_spread": episodes_for(truth, spread) if spread > 0 else None,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repetitions", type=int, default=100)
    parser.add_argument("--out", type=Path)
    parser.add_argument("--methods", nargs="*", default=None, help="Only these estimators.")
    parser.add_argument(
        "--penalty", type=float, default=2.0, help="ce: the estimator's penalty (0: no selection)."
    )
    parser.add_argument("--idle-only", action="store_true", help="Only the cases with idle ones.")
    args = parser.parse_args()
    started = time.perf_counter()
    rows = []
    for name, threshold, p_looks, idle, method, episodes, size in CASES:
        if (args.methods and method not in args.methods) or (args.idle_only and not idle):
            continue
        played = repeat(
            threshold, p_looks, idle, method, episodes, size, args.repetitions, args.penalty
        )
        row = {"case": name, **played}
        rows.append(row)
        print(
            f"{name:40s} p={row['probability']:.3g} {method:9s} coverage {row['coverage']:.2f} "
            f"mean/p {row['mean_over_truth']:.2f} spread {row['relative_spread']:.2f} "
            f"reported {row['median_reported_relative_error']:.2f} "
            f"episodes {row['median_episodes']:.0f} "
            f"(plain Monte Carlo: {row['monte_carlo_episodes_for_spread'] or 0:,.0f})",
            flush=True,
        )
    if args.out:
        result = {
            "command": " ".join([Path(sys.executable).name, *sys.argv]),
            "date": datetime.now(UTC).isoformat(),
            "wall_time_s": time.perf_counter() - started,
            "cases": rows,
        }
        args.out.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
