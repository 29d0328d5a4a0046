"""The study's whole experiment projected from measured rates, on 2 cores and on a cluster.

For every (tester, scenario, field) of the study's grid, one run of ``--episodes`` (what
``hazardhunt run`` does, ``record_run``) in a fresh process, one at a time: its start-up (to the
end of the first episode) and its steady-state rate after that, in CPU time, which a busy
machine measures far more reliably than wall time, and in wall time. Each of the study's runs
(3 seeds of 20,000 episodes per configuration, 81 in all) then takes its configuration's
start-up plus 19,999 episodes at the steady CPU rate, and the runs are placed on C cores as a
campaign's workers take them, one run per core, longest first. Printed for each C: the
projected wall time, beside the study's.

What the projection leaves out: PPO's episodes change length as it learns (a tester that
learns to loiter plays longer episodes), which short runs do not see; the measured full
``ppo-max`` run (docs/performance.md) checks it. Cores are taken as independent; on this
machine two processes run 1.9 times as fast as one (``benchmarks/scaling.py``).

    python benchmarks/projection.py --episodes 40 --out benchmarks/results/projection.json
"""

from __future__ import annotations

import argparse
import heapq
import json
import multiprocessing
import platform
import tempfile
import time
from pathlib import Path
from typing import Any

from hazardhunt.analysis.study import STUDY_EPISODES, STUDY_RUNTIME_MINUTES
from hazardhunt.campaign.config import RunConfig
from hazardhunt.campaign.run import RunProgress, record_run
from hazardhunt.sut.safety_layer import FIELD_SETTINGS
from hazardhunt.world.scenario import BUILTIN_SCENARIOS

STUDY_TESTERS = ("random", "ppo-acc", "ppo-max")
STUDY_SEEDS = 3
CORES = (2, 4, 8, 16, 32, 81)
STUDY_RUN_HOURS = (19 + 41 / 60, 77 + 45 / 60)
"""The shortest and the longest of the study's runs (its text), hours."""


def measure(config: RunConfig) -> dict[str, Any]:
    """One run in this process: its start-up and its steady-state rates."""
    first: dict[str, float] = {}

    def progress(state: RunProgress) -> None:
        if state.episodes_done == 1:
            first.update(wall=time.perf_counter(), cpu=time.process_time())

    wall, cpu = time.perf_counter(), time.process_time()
    with tempfile.TemporaryDirectory() as folder:
        summary = record_run(config, Path(folder) / "run", progress)
    end_wall, end_cpu = time.perf_counter(), time.process_time()
    steady = int(summary["episodes"]) - 1
    return {
        "tester": config.tester,
        "scenario": config.scenario,
        "field": config.field,
        "episodes": int(summary["episodes"]),
        "failures": int(summary["failures"]),
        "start_up_cpu_s": first["cpu"] - cpu,
        "start_up_wall_s": first["wall"] - wall,
        "steady_episodes_per_cpu_s": steady / (end_cpu - first["cpu"]),
        "steady_episodes_per_s": steady / (end_wall - first["wall"]),
    }


def makespan(durations: list[float], cores: int) -> float:
    """Wall time of ``durations`` run one per core, longest first, each on the core that
    frees first."""
    free = [0.0] * cores
    for duration in sorted(durations, reverse=True):
        heapq.heappush(free, heapq.heappop(free) + duration)
    return max(free)


def hours(seconds: float) -> str:
    return f"{seconds / 3600:.1f} h"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=40, help="episodes per measured run")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--cores", type=int, nargs="+", default=list(CORES))
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/projection.json"))
    args = parser.parse_args()

    context = multiprocessing.get_context("spawn")
    measured = []
    for tester in STUDY_TESTERS:
        for scenario in BUILTIN_SCENARIOS:
            for field in FIELD_SETTINGS:
                config = RunConfig(
                    scenario=scenario,
                    field=field,
                    tester=tester,
                    seed=args.seed,
                    episodes=args.episodes,
                )
                with context.Pool(1) as pool:  # a fresh process: start-up included
                    row = pool.apply(measure, (config,))
                row["projected_run_s"] = (
                    row["start_up_cpu_s"] + (STUDY_EPISODES - 1) / row["steady_episodes_per_cpu_s"]
                )
                measured.append(row)
                print(
                    f"{tester:8} {scenario:11} {field:6} start-up {row['start_up_cpu_s']:5.1f} s  "
                    f"steady {row['steady_episodes_per_cpu_s']:6.2f} episodes/CPU s "
                    f"({row['steady_episodes_per_s']:6.2f}/s wall)  20,000 episodes: "
                    f"{row['projected_run_s'] / 60:5.1f} min",
                    flush=True,
                )

    runs = [row["projected_run_s"] for row in measured for _ in range(STUDY_SEEDS)]
    study_ppo_s = (
        STUDY_SEEDS * 60 * sum(sum(case.values()) for case in STUDY_RUNTIME_MINUTES.values())
    )
    ours_ppo_s = STUDY_SEEDS * sum(
        row["projected_run_s"] for row in measured if row["tester"] in ("ppo-acc", "ppo-max")
    )
    projection = {str(cores): makespan(runs, cores) for cores in args.cores}
    print(f"\nthe study's grid: {len(runs)} runs of {STUDY_EPISODES:,} episodes")
    print(f"  one core, all runs in turn: {hours(sum(runs))}")
    for cores, seconds in projection.items():
        print(f"  on {cores:>3} cores: {hours(seconds)}")
    print(f"  longest run: {hours(max(runs))}, shortest: {hours(min(runs))}")
    print(
        f"the study: runs of {STUDY_RUN_HOURS[0]:.1f} to {STUDY_RUN_HOURS[1]:.1f} h; "
        f"its 54 PPO runs (Table II) {hours(study_ppo_s)} in all, here {hours(ours_ppo_s)} "
        f"({study_ppo_s / ours_ppo_s:.0f} times faster)"
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(
        json.dumps(
            {
                "command": f"python benchmarks/projection.py --episodes {args.episodes}",
                "machine": {"python": platform.python_version(), "processor": platform.machine()},
                "episodes_per_measured_run": args.episodes,
                "seed": args.seed,
                "measured": measured,
                "study_runs": len(runs),
                "one_core_s": sum(runs),
                "projected_wall_s_by_cores": projection,
                "study_ppo_runs_s": study_ppo_s,
                "ppo_runs_s": ours_ppo_s,
            },
            indent=2,
        )
    )
    print(f"written to {args.out}")


if __name__ == "__main__":
    main()
