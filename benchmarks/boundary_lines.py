"""What bisection lines from a run's failures land in: the measurement behind the boundary arm.

Reads a run directory's failures (``failures.parquet``: scenario, field, each failure's actions),
replays them, and follows ``--lines`` bisection lines as the portfolio's boundary arm does
(:mod:`hazardhunt.testers.boundary`), the starts taken from the failures' descriptor cells in
turn. Prints the class of every episode the lines played (``safe`` for one that did not fail),
so that one sees which classes lie on the border of the run's failure regions. Against the
built-in NMPC and laser field (the run's controller is not read: a run directory is data).

    python benchmarks/boundary_lines.py RUN --lines 30
"""

from __future__ import annotations

import argparse
import collections
import json
from pathlib import Path

import numpy as np
import pandas as pd

from hazardhunt.sim.simulation import Simulation
from hazardhunt.spec.failure_classes import MechanismClassifier
from hazardhunt.testers.boundary import BoundaryParams, BoundarySampler
from hazardhunt.testers.evaluator import Plan
from hazardhunt.testers.search import SearchContext
from hazardhunt.testers.spaces import DecisionSpace


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="a run directory")
    parser.add_argument("--lines", type=int, default=30, help="bisection lines to follow")
    parser.add_argument("--seed", type=int, default=2)
    parser.add_argument("--out", type=Path, help="also write the counts as JSON here")
    args = parser.parse_args()

    failures = pd.read_parquet(args.run / "failures.parquet")
    if failures.empty:
        raise SystemExit(f"{args.run}: the run has no failures to start lines from")
    sim = Simulation.build(str(failures["scenario"].iloc[0]), str(failures["field"].iloc[0]))
    classifier = MechanismClassifier(robot=sim.robot_params)
    params = BoundaryParams(batch_size=1)
    sampler = BoundarySampler(params, SearchContext(sim, seed=args.seed))
    open_space = DecisionSpace("open")

    def play(plans: list[Plan]) -> list:
        return [open_space.play(sim, plan.decisions, True) for plan in plans]

    starts = [Plan(open_space, np.array(list(actions))) for actions in failures["actions"]]
    sampler.observe(starts, play(starts))
    counts: collections.Counter[str] = collections.Counter()
    played = 0
    while sampler.lines_done < args.lines:
        plans = sampler.ask()
        if not plans:
            raise SystemExit(f"{args.run}: none of its failures fails when replayed here")
        results = play(plans)
        sampler.tell(plans, results)
        played += len(results)
        for result in results:
            if result.outcome == "failure":
                counts[classifier.classify(result.trajectory or (), result.summary, sim.field)] += 1
            else:
                counts["safe"] += 1
    row = {"run": str(args.run), "lines": args.lines, "episodes": played, "classes": dict(counts)}
    print(json.dumps(row, indent=2))
    if args.out:
        args.out.write_text(json.dumps(row, indent=2) + "\n")


if __name__ == "__main__":
    main()
