"""Closed-loop NMPC solve times per solver, and the environment's throughput.

Both solvers face the same episodes: the same scenarios and the same random human actions.
Prints a table and writes the numbers as JSON.

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


def run_solver(solver: str, episodes: int, field: str, seed: int) -> dict[str, Any]:
    # "fatrop": the compiled solver (the default); "fatrop-interpreted": CasADi's interpreted
    # fatrop; "fatrop-jit": that with the problem's functions compiled by CasADi's JIT (gcc).
    name, _, variant = solver.partition("-")
    params = NMPCParams(
        solver=name,  # type: ignore[arg-type]
        compiled=variant == "",
        jit=variant == "jit",
    )
    controller = NMPCController(params)
    iterations: list[float] = []
    control = controller.control

    def counted(*args: Any) -> Any:  # the solver's iterations of every call, retries included
        command = control(*args)
        iterations.append(command.extras.get("iterations", np.nan))
        return command

    controller.control = counted  # type: ignore[method-assign,assignment]
    solve_times: list[float] = []
    failed = decisions = physics_steps = episode_count = 0
    outcomes: dict[str, int] = {}
    started = time.perf_counter()
    for scenario in BUILTIN_SCENARIOS:
        simulation = Simulation.build(scenario, field, controller=controller)
        rng = np.random.default_rng(seed)

        def uniform(_: Simulation, rng: np.random.Generator = rng) -> np.ndarray:
            return rng.uniform(-1.0, 1.0, size=2)

        for _ in range(episodes):
            result = simulation.simulate(uniform)
            summary = result.summary
            outcomes[str(summary.outcome)] = outcomes.get(str(summary.outcome), 0) + 1
            solve_times += [row.solve_time_s for row in (result.trajectory or ())[:-1]]
            failed += summary.controller_failures
            decisions += summary.decision_steps
            physics_steps += round(summary.sim_time / simulation.physics_step)
            episode_count += 1
    wall = time.perf_counter() - started
    times_ms = 1e3 * np.array([t for t in solve_times if t > 0.0])
    return {
        "solver": solver,
        "episodes": episode_count,
        "solves": int(times_ms.size),
        "failed_solves": failed,
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
        "episodes_per_s": episode_count / wall,
        "decision_steps_per_s": decisions / wall,
        "physics_steps_per_s": physics_steps / wall,
        "outcomes": outcomes,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=10, help="episodes per scenario")
    parser.add_argument("--field", default="1.25m")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--solvers",
        nargs="+",
        default=["fatrop", "fatrop-interpreted", "ipopt"],
        help="fatrop (compiled), fatrop-interpreted, fatrop-jit, ipopt",
    )
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/nmpc.json"))
    args = parser.parse_args()

    results = [run_solver(s, args.episodes, args.field, args.seed) for s in args.solvers]
    header = (
        f"{'solver':8} {'solves':>7} {'failed':>6} {'median':>8} {'p95':>8} {'p99':>8} "
        f"{'max':>8} {'solve %':>8} {'episodes/s':>10} {'steps/s':>8}"
    )
    print(
        f"closed loop, random human, {args.episodes} episodes x {len(BUILTIN_SCENARIOS)} "
        f"scenarios, field {args.field}; solve times in ms"
    )
    print(header)
    for r in results:
        ms = r["solve_ms"]
        print(
            f"{r['solver']:8} {r['solves']:7d} {r['failed_solves']:6d} {ms['median']:8.3f} "
            f"{ms['p95']:8.3f} {ms['p99']:8.3f} {ms['max']:8.3f} "
            f"{100 * r['solve_share_of_wall']:7.1f}% {r['episodes_per_s']:10.2f} "
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
