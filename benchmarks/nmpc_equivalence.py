"""Closed-loop equivalence of the NMPC's settings: today's against the previous warm start.

Both controllers play the same open-loop random human actions on every built-in scenario and
field setting (or the ``--cases`` named); per case, how many episodes end identically (outcome,
contact face, end time), each one's failure count with its 95 % Clopper-Pearson interval, and
whether each count lies in the other's interval. Prints a table and writes JSON; cases already
in ``--out`` from an earlier command with the same episodes and seed are kept, so the nine
cases can be run in slices.

    python benchmarks/nmpc_equivalence.py --episodes 1000 --cases crossing:none crossing:2m
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from scipy.stats import beta

from hazardhunt.sim.simulation import Simulation
from hazardhunt.sut.nmpc import NMPCController, NMPCParams
from hazardhunt.world.scenario import BUILTIN_SCENARIOS
from nmpc import PREVIOUS_TUNING  # benchmarks/ is the script's directory

FIELDS = ("none", "1.25m", "2m")


def clopper_pearson(failures: int, episodes: int, level: float = 0.95) -> tuple[float, float]:
    """The exact (Clopper-Pearson) interval of a failure probability, as failure counts."""
    tail = (1.0 - level) / 2.0
    low = 0.0 if failures == 0 else float(beta.ppf(tail, failures, episodes - failures + 1))
    high = (
        1.0
        if failures == episodes
        else float(beta.ppf(1 - tail, failures + 1, episodes - failures))
    )
    return low * episodes, high * episodes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=100, help="episodes per case")
    parser.add_argument("--seed", type=int, default=1000)
    parser.add_argument(
        "--cases",
        nargs="+",
        default=[f"{scenario}:{field}" for scenario in BUILTIN_SCENARIOS for field in FIELDS],
        help="scenario:field (default: all nine)",
    )
    parser.add_argument(
        "--out", type=Path, default=Path("benchmarks/results/nmpc_equivalence.json")
    )
    args = parser.parse_args()
    controllers = {
        "today": NMPCController(NMPCParams()),
        "previous": NMPCController(NMPCParams(**PREVIOUS_TUNING)),  # type: ignore[arg-type]
    }
    cases: dict[str, dict[str, object]] = {}
    if args.out.exists():
        earlier = json.loads(args.out.read_text())
        if (earlier.get("episodes_per_case"), earlier.get("seed")) == (args.episodes, args.seed):
            cases = earlier["cases"]
    print(
        f"{'case':20} {'identical':>9} {'failures today':>14} {'previous':>8} "
        f"{'95 % interval today':>19} {'previous':>13} {'agree':>5}"
    )
    for scenario, _, field in (case.partition(":") for case in args.cases):
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
        intervals = {n: clopper_pearson(f, args.episodes) for n, f in failures.items()}
        agree = all(
            intervals[other][0] <= failures[name] <= intervals[other][1]
            for name, other in (("today", "previous"), ("previous", "today"))
        )
        cases[f"{scenario}/{field}"] = {
            "identical": identical,
            "failures": failures,
            "clopper_pearson_95": intervals,
            "agree": agree,
        }
        low, high = intervals["today"]
        low_p, high_p = intervals["previous"]
        print(
            f"{scenario + '/' + field:20} {identical:9d} {failures['today']:14d} "
            f"{failures['previous']:8d} {f'{low:.1f}-{high:.1f}':>19} "
            f"{f'{low_p:.1f}-{high_p:.1f}':>13} {'yes' if agree else 'NO':>5}",
            flush=True,
        )
        args.out.parent.mkdir(parents=True, exist_ok=True)
        report = {"episodes_per_case": args.episodes, "seed": args.seed, "cases": cases}
        args.out.write_text(json.dumps(report, indent=2))
    print(f"written to {args.out}")


if __name__ == "__main__":
    main()
