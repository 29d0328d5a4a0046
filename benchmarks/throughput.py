"""Throughput of real runs per tester and scenario, and the NMPC's solve times per solver.

Each run is ``record_run`` (what ``hazardhunt run`` does) in a fresh process, one at a time, so
that its peak memory is its own and nothing else competes for the cores. For every run: episodes
and env steps per second, the share of wall time spent outside the NMPC solver's call
(overhead), the share spent outside the controller altogether (its solver call and the Python
that prepares it: references, obstacle half-planes, the human's prediction, the warm start), and
the peak resident memory. The solver part is ``benchmarks/nmpc.py``'s closed loop. Prints tables
and writes JSON.

    python benchmarks/throughput.py --episodes 100 --out benchmarks/results/throughput.json
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import platform
import resource
import tempfile
import time
from pathlib import Path
from typing import Any

import pandas as pd

from hazardhunt.campaign.config import RunConfig
from hazardhunt.campaign.run import RunProgress, record_run
from hazardhunt.sut.nmpc import NMPCController
from hazardhunt.testers import TESTERS
from hazardhunt.world.scenario import BUILTIN_SCENARIOS
from nmpc import run_solver  # benchmarks/ is the script's directory


def measure_run(config: RunConfig) -> dict[str, Any]:
    """Execute one run in this process and measure it."""
    controller_s = [0.0]
    control = NMPCController.control

    def timed_control(self: NMPCController, *args: Any) -> Any:
        started = time.perf_counter()
        try:
            return control(self, *args)
        finally:
            controller_s[0] += time.perf_counter() - started

    NMPCController.control = timed_control  # type: ignore[method-assign,assignment]
    # Steady state: from the end of the first episode on, without the start-up (imports, the
    # tester's and the NMPC's construction) that a long run amortises.
    first: dict[str, float] = {}

    def progress(state: RunProgress) -> None:
        if state.episodes_done == 1:
            first.update(time=time.perf_counter(), controller_s=controller_s[0])

    with tempfile.TemporaryDirectory() as folder:
        started = time.perf_counter()
        directory = Path(folder) / "run"
        summary = record_run(config, directory, progress)
        ended = time.perf_counter()
        wall = ended - started
        episodes = pd.read_parquet(directory / "episodes.parquet")
        physics_step = json.loads((directory / "config.json").read_text())["physics_step"]
    solve_per_episode = episodes["controller_calls"] * episodes["solve_time_mean_s"]
    solve_s = float(solve_per_episode.sum())
    steady_wall = ended - first["time"]
    steady_solve_s = float(solve_per_episode.iloc[1:].sum())
    steady_controller_s = controller_s[0] - first["controller_s"]
    return {
        "scenario": config.scenario,
        "field": config.field,
        "tester": config.tester,
        "episodes": int(summary["episodes"]),
        "failures": int(summary["failures"]),
        "wall_s": wall,
        "episodes_per_s": summary["episodes"] / wall,
        "decision_steps_per_s": float(episodes["decision_steps"].sum()) / wall,
        "physics_steps_per_s": float((episodes["sim_time"] / physics_step).sum()) / wall,
        "solves": int(episodes["controller_calls"].sum()),
        "solve_s": solve_s,
        "overhead_share": 1.0 - solve_s / wall,
        "controller_s": controller_s[0],
        "outside_controller_share": 1.0 - controller_s[0] / wall,
        "steady_episodes_per_s": (summary["episodes"] - 1) / steady_wall,
        "steady_overhead_share": 1.0 - steady_solve_s / steady_wall,
        "steady_outside_controller_share": 1.0 - steady_controller_s / steady_wall,
        "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=100, help="episodes per run")
    parser.add_argument("--field", default="1.25m")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--testers", nargs="+", default=list(TESTERS))
    parser.add_argument("--scenarios", nargs="+", default=list(BUILTIN_SCENARIOS))
    parser.add_argument(
        "--solvers",
        nargs="+",
        default=["fatrop", "fatrop-interpreted", "ipopt"],
        help="fatrop (compiled), fatrop-interpreted, fatrop-jit, ipopt",
    )
    parser.add_argument(
        "--solver-episodes", type=int, default=10, help="episodes per scenario and solver"
    )
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/throughput.json"))
    args = parser.parse_args()

    context = multiprocessing.get_context("spawn")
    runs = []
    for tester in args.testers:
        for scenario in args.scenarios:
            config = RunConfig(
                scenario=scenario,
                field=args.field,
                tester=tester,
                seed=args.seed,
                episodes=args.episodes,
            )
            with context.Pool(1) as pool:  # a fresh process: its own peak memory
                runs.append(pool.apply(measure_run, (config,)))
    print(f"runs of {args.episodes} episodes, field {args.field}, one process at a time")
    print("overhead: outside the solver call; no ctrl: outside the controller; steady: after")
    print("the first episode (without start-up)")
    print(
        f"{'tester':8} {'scenario':11} {'episodes/s':>10} {'steady':>7} {'decisions/s':>11} "
        f"{'physics/s':>9} {'overhead':>8} {'steady':>7} {'no ctrl':>8} {'steady':>7} "
        f"{'peak MiB':>8} {'failures':>8}"
    )
    for r in runs:
        print(
            f"{r['tester']:8} {r['scenario']:11} {r['episodes_per_s']:10.2f} "
            f"{r['steady_episodes_per_s']:7.2f} "
            f"{r['decision_steps_per_s']:11.1f} {r['physics_steps_per_s']:9.0f} "
            f"{100 * r['overhead_share']:7.1f}% {100 * r['steady_overhead_share']:6.1f}% "
            f"{100 * r['outside_controller_share']:7.1f}% "
            f"{100 * r['steady_outside_controller_share']:6.1f}% "
            f"{r['peak_rss_mib']:8.0f} {r['failures']:8d}"
        )

    solvers = [
        run_solver(name, args.solver_episodes, args.field, args.seed) for name in args.solvers
    ]
    print(f"\nNMPC in closed loop, random human, {args.solver_episodes} episodes x scenario (ms)")
    print(
        f"{'solver':18} {'solves':>7} {'median':>7} {'p95':>7} {'p99':>7} {'max':>7} "
        f"{'iterations':>10} {'ms/iter':>7}"
    )
    for r in solvers:
        ms = r["solve_ms"]
        print(
            f"{r['solver']:18} {r['solves']:7d} {ms['median']:7.3f} {ms['p95']:7.3f} "
            f"{ms['p99']:7.3f} {ms['max']:7.2f} {r['iterations']['median']:10.0f} "
            f"{r['ms_per_iteration']:7.3f}"
        )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(
        json.dumps(
            {
                "machine": {"python": platform.python_version(), "processor": platform.machine()},
                "episodes_per_run": args.episodes,
                "field": args.field,
                "seed": args.seed,
                "runs": runs,
                "solvers": solvers,
            },
            indent=2,
        )
    )
    print(f"written to {args.out}")


if __name__ == "__main__":
    main()
