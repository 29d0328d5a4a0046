"""Closed-loop NMPC solve times per solver, and the environment's throughput.

Every solver faces the same episodes: the same scenarios and the same random human actions,
played episode by episode in turn. Prints a table and writes the numbers as JSON.

    python benchmarks/nmpc.py --episodes 10 --out benchmarks/results/nmpc.json
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path
from typing import Any

import numpy as np

from hazardhunt.sim.simulation import Simulation
from hazardhunt.sut.nmpc import NMPCController, NMPCParams
from hazardhunt.world.scenario import BUILTIN_SCENARIOS

PREVIOUS_TUNING = {"barrier_decrease_power": 1.5, "bound_push": 1e-6}
"""The warm-start settings of the compiled fatrop before its barrier decrease was tuned."""


def make_controller(solver: str) -> NMPCController:
    """The NMPC of a solver name: "fatrop" (compiled, the default), "fatrop-previous" (compiled,
    with the warm-start settings before the tuning), "fatrop-interpreted" (CasADi's interpreted
    fatrop), "fatrop-jit" (that with the problem's functions compiled by CasADi's JIT) or
    "ipopt"."""
    name, _, variant = solver.partition("-")
    params = NMPCParams(
        solver=name,  # type: ignore[arg-type]
        compiled=variant in ("", "previous"),
        jit=variant == "jit",
        **(PREVIOUS_TUNING if variant == "previous" else {}),  # type: ignore[arg-type]
    )
    return NMPCController(params)


class Recorder:
    """One solver's controller and what its episodes measured."""

    def __init__(self, solver: str) -> None:
        self.solver = solver
        self.controller = make_controller(solver)
        self.iterations: list[float] = []
        self.solve_times: list[float] = []
        self.failed = self.decisions = self.physics_steps = self.episodes = 0
        self.wall = 0.0
        self.outcomes: dict[str, int] = {}
        control = self.controller.control

        def counted(*args: Any) -> Any:  # the solver's iterations of every call, retries included
            command = control(*args)
            self.iterations.append(command.extras.get("iterations", np.nan))
            return command

        self.controller.control = counted  # type: ignore[method-assign,assignment]

    def play(self, simulation: Simulation, policy: Any) -> None:
        started = time.perf_counter()
        result = simulation.simulate(policy)
        self.wall += time.perf_counter() - started
        summary = result.summary
        self.outcomes[str(summary.outcome)] = self.outcomes.get(str(summary.outcome), 0) + 1
        self.solve_times += [row.solve_time_s for row in (result.trajectory or ())[:-1]]
        self.failed += summary.controller_failures
        self.decisions += summary.decision_steps
        self.physics_steps += round(summary.sim_time / simulation.physics_step)
        self.episodes += 1

    def report(self) -> dict[str, Any]:
        times_ms = 1e3 * np.array([t for t in self.solve_times if t > 0.0])
        iterations, wall = self.iterations, self.wall
        return {
            "solver": self.solver,
            "episodes": self.episodes,
            "solves": int(times_ms.size),
            "failed_solves": self.failed,
            "solve_ms": {
                "median": float(np.median(times_ms)),
                "p95": float(np.percentile(times_ms, 95)),
                "p99": float(np.percentile(times_ms, 99)),
                "max": float(times_ms.max()),
                "mean": float(times_ms.mean()),
            },
            "iterations": {
                "median": float(np.nanmedian(iterations)),
                "mean": float(np.nanmean(iterations)),
                "p99": float(np.nanpercentile(iterations, 99)),
            },
            "ms_per_iteration": float(times_ms.sum() / np.nansum(iterations)),
            "solve_share_of_wall": float(times_ms.sum() / 1e3 / wall),
            "wall_s": wall,
            "episodes_per_s": self.episodes / wall,
            "decision_steps_per_s": self.decisions / wall,
            "physics_steps_per_s": self.physics_steps / wall,
            "outcomes": self.outcomes,
        }


def run_solvers(solvers: list[str], episodes: int, field: str, seed: int) -> list[dict[str, Any]]:
    """Every solver plays the same episodes (the same random human actions), interleaved episode
    by episode so that a change in the machine's load touches all of them alike."""
    recorders = [Recorder(solver) for solver in solvers]
    for scenario in BUILTIN_SCENARIOS:
        simulations = [
            Simulation.build(scenario, field, controller=r.controller) for r in recorders
        ]
        generators = [np.random.default_rng(seed) for _ in recorders]
        for _ in range(episodes):
            for recorder, simulation, rng in zip(recorders, simulations, generators, strict=True):

                def uniform(_: Simulation, rng: np.random.Generator = rng) -> np.ndarray:
                    return rng.uniform(-1.0, 1.0, size=2)

                recorder.play(simulation, uniform)
    return [r.report() for r in recorders]


def run_solver(solver: str, episodes: int, field: str, seed: int) -> dict[str, Any]:
    """:func:`run_solvers` for one solver."""
    return run_solvers([solver], episodes, field, seed)[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=10, help="episodes per scenario")
    parser.add_argument("--field", default="1.25m")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--solvers",
        nargs="+",
        default=["fatrop", "fatrop-previous", "fatrop-interpreted", "ipopt"],
        help="fatrop (compiled), fatrop-previous, fatrop-interpreted, fatrop-jit, ipopt",
    )
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/nmpc.json"))
    args = parser.parse_args()

    results = run_solvers(args.solvers, args.episodes, args.field, args.seed)
    header = (
        f"{'solver':18} {'solves':>7} {'failed':>6} {'median':>8} {'p95':>8} {'p99':>8} "
        f"{'max':>8} {'iter':>5} {'solve %':>8} {'episodes/s':>10} {'steps/s':>8}"
    )
    print(
        f"closed loop, random human, {args.episodes} episodes x {len(BUILTIN_SCENARIOS)} "
        f"scenarios, field {args.field}; solve times in ms"
    )
    print(header)
    for r in results:
        ms = r["solve_ms"]
        print(
            f"{r['solver']:18} {r['solves']:7d} {r['failed_solves']:6d} {ms['median']:8.3f} "
            f"{ms['p95']:8.3f} {ms['p99']:8.3f} {ms['max']:8.3f} "
            f"{r['iterations']['mean']:5.2f} {100 * r['solve_share_of_wall']:7.1f}% "
            f"{r['episodes_per_s']:10.2f} "
            f"{r['decision_steps_per_s']:8.1f}"
        )
    if len(results) > 1:
        base = results[0]["solve_ms"]["median"]
        for r in results[1:]:
            print(
                f"median ratio {r['solver']} / {results[0]['solver']}: "
                f"{r['solve_ms']['median'] / base:.2f}"
            )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    report = {
        "machine": {"python": platform.python_version(), "processor": platform.machine()},
        "episodes_per_scenario": args.episodes,
        "field": args.field,
        "seed": args.seed,
        "results": results,
    }
    args.out.write_text(json.dumps(report, indent=2))
    print(f"written to {args.out}")


if __name__ == "__main__":
    main()
