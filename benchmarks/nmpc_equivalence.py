"""Closed-loop equivalence of the NMPC's settings: today's against the previous warm start.

Both controllers play the same open-loop random human actions on every built-in scenario and
field setting; per case, how many episodes end identically (outcome, contact face, end time)
and each one's failure count. Prints a table and writes JSON.

    python benchmarks/nmpc_equivalence.py --episodes 100
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from hazardhunt.sim.simulation import Simulation
from hazardhunt.sut.nmpc import NMPCController, NMPCParams
from hazardhunt.world.scenario import BUILTIN_SCENARIOS
from nmpc import PREVIOUS_TUNING  # benchmarks/ is the script's directory

FIELDS = ("none", "1.25m", "2m")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=100, help="episodes per case")
    parser.add_argument("--seed", type=int, default=1000)
    parser.add_argument(
        "--out", type=Path, default=Path("benchmarks/results/nmpc_equivalence.json")
    )
    args = parser.parse_args()
    controllers = {
        "today": NMPCController(NMPCParams()),
        "previous": NMPCController(NMPCParams(**PREVIOUS_TUNING)),  # type: ignore[arg-type]
    }
    cases = {}
    print(f"{'case':20} {'identical':>9} {'failures today':>14} {'previous':>8}")
    for scenario in BUILTIN_SCENARIOS:
        for field in FIELDS:
            simulations = {
                name: Simulation.build(scenario, field, controller=controller)
                for name, controller in controllers.items()
            }
            endings: dict[str, list[tuple[str, str | None, float]]] = {n: [] for n in controllers}
            for episode in range(args.episodes):
                rng = np.random.default_rng(args.seed + episode)
                actions = rng.uniform(-1.0, 1.0, (simulations["today"].horizon, 2))
                for name, simulation in simulations.items():
                    summary = simulation.simulate(actions, keep_trajectory=False).summary
                    ending = (str(summary.outcome), summary.contact_face, summary.sim_time)
                    endings[name].append(ending)
            identical = sum(a == b for a, b in zip(*endings.values(), strict=True))
            failures = {n: sum(e[0] == "failure" for e in v) for n, v in endings.items()}
            cases[f"{scenario}/{field}"] = {"identical": identical, "failures": failures}
            print(
                f"{scenario + '/' + field:20} {identical:9d} {failures['today']:14d} "
                f"{failures['previous']:8d}"
            )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    report = {"episodes_per_case": args.episodes, "seed": args.seed, "cases": cases}
    args.out.write_text(json.dumps(report, indent=2))
    print(f"written to {args.out}")


if __name__ == "__main__":
    main()
