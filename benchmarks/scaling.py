"""How a campaign scales from one local worker to two, beside what the machine's cores allow.

Three measurements in one command:

1. The machine's parallel capacity: the same CPU-bound pure-Python loop in one process, then
   in two processes at once. On a machine whose two vCPUs share a physical core (or a busy
   host), each of the two runs slower than the one alone, and no campaign can scale better.
2. A 4-run campaign (``--scenario`` x ``--field`` x random and ppo-max x 2 seeds, ``--episodes``
   each) executed with ``--workers 1`` and then with ``--workers 2`` into fresh directories;
   the ratio of their wall times is the campaign's scaling.
3. One run of each episode-level searcher (``--searchers``, ``--searcher-episodes`` each) with
   ``n_workers=1`` and then ``n_workers=2``, each in a fresh process: its steady-state rate
   after the first batch (without the start of the worker processes) and the speedup of two.

Prints a table and writes JSON.

    python benchmarks/scaling.py --episodes 150 --out benchmarks/results/scaling.json
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import platform
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from rich.console import Console

from hazardhunt.campaign.campaign import run_campaign
from hazardhunt.campaign.config import RunConfig, load_campaign
from hazardhunt.campaign.run import RunProgress, record_run


def spin(iterations: int) -> float:
    """Seconds a pure-Python loop of ``iterations`` takes in this process."""
    started = time.perf_counter()
    total = 0
    for i in range(iterations):
        total += i * i
    return time.perf_counter() - started


def parallel_capacity(iterations: int) -> dict[str, float]:
    """Seconds of the loop alone and of each of two copies at once; the speedup two give."""
    context = multiprocessing.get_context("spawn")
    with context.Pool(1) as pool:
        alone = pool.apply(spin, (iterations,))
    with context.Pool(2) as pool:
        together = pool.map(spin, [iterations, iterations])
    slowest = max(together)
    return {
        "alone_s": alone,
        "two_at_once_s": slowest,
        "speedup_of_two": 2 * alone / slowest,
        "best_time_ratio": slowest / (2 * alone),
    }


def campaign_file(folder: Path, scenario: str, field: str, episodes: int) -> Path:
    path = folder / "scaling.toml"
    path.write_text(
        f'scenarios = ["{scenario}"]\n'
        f'fields = ["{field}"]\n'
        'testers = ["random", "ppo-max"]\n'
        "seeds = [0, 1]\n"
        f"episodes = {episodes}\n"
        "[tester.ppo-max]\nn_steps = 256\n",
        encoding="utf-8",
    )
    return path


def time_campaign(path: Path, workers: int, out: Path) -> float:
    config = load_campaign(path)
    started = time.perf_counter()
    run_campaign(config, out, workers=workers, console=Console(quiet=True))
    return time.perf_counter() - started


def searcher_rate(config: RunConfig, after: int) -> dict[str, float]:
    """A run in this process: wall time in all and its rate after ``after`` episodes."""
    marks: dict[str, float] = {}

    def progress(state: RunProgress) -> None:
        if state.episodes_done >= after and "steady" not in marks:
            marks.update(steady=time.perf_counter(), done=state.episodes_done)

    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as folder:
        record_run(config, Path(folder) / "run", progress)
    ended = time.perf_counter()
    return {
        "wall_s": ended - started,
        "steady_episodes_per_s": (config.episodes - marks["done"]) / (ended - marks["steady"]),
    }


def searcher_scaling(tester: str, scenario: str, field: str, episodes: int) -> dict[str, Any]:
    """The searcher's steady rate with one and with two worker processes."""
    context = multiprocessing.get_context("spawn")
    rates = {}
    for workers in (1, 2):
        config = RunConfig(
            scenario=scenario,
            field=field,
            tester=tester,
            seed=0,
            episodes=episodes,
            tester_params={"n_workers": workers},
        )
        # a fresh process that may start the run's own workers (a Pool's may not)
        with ProcessPoolExecutor(1, mp_context=context) as pool:
            rates[str(workers)] = pool.submit(searcher_rate, config, 40).result()
    speedup = rates["2"]["steady_episodes_per_s"] / rates["1"]["steady_episodes_per_s"]
    return {"tester": tester, "episodes": episodes, "n_workers": rates, "speedup_of_two": speedup}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=150, help="episodes per run")
    parser.add_argument("--scenario", default="crossing")
    parser.add_argument("--field", default="1.25m")
    parser.add_argument("--spin", type=int, default=20_000_000, help="iterations of the loop")
    parser.add_argument("--searchers", nargs="*", default=["cem", "qd"])
    parser.add_argument("--searcher-episodes", type=int, default=240)
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/scaling.json"))
    args = parser.parse_args()

    capacity = parallel_capacity(args.spin)
    with tempfile.TemporaryDirectory() as folder:
        path = campaign_file(Path(folder), args.scenario, args.field, args.episodes)
        walls: dict[int, float] = {}
        for workers in (1, 2):
            walls[workers] = time_campaign(path, workers, Path(folder) / f"workers-{workers}")
    ratio = walls[2] / walls[1]
    searchers = [
        searcher_scaling(tester, args.scenario, args.field, args.searcher_episodes)
        for tester in args.searchers
    ]
    print(
        f"pure-Python loop: alone {capacity['alone_s']:.2f} s, two at once "
        f"{capacity['two_at_once_s']:.2f} s each: two processes give "
        f"{capacity['speedup_of_two']:.2f}x (best possible time ratio "
        f"{capacity['best_time_ratio']:.2f})"
    )
    print(
        f"4-run campaign, {args.episodes} episodes per run: 1 worker {walls[1]:.1f} s, "
        f"2 workers {walls[2]:.1f} s, ratio {ratio:.2f}"
    )
    for row in searchers:
        one, two = row["n_workers"]["1"], row["n_workers"]["2"]
        print(
            f"{row['tester']}, {row['episodes']} episodes: steady "
            f"{one['steady_episodes_per_s']:.2f} episodes/s with 1 worker, "
            f"{two['steady_episodes_per_s']:.2f} with 2: "
            f"{row['speedup_of_two']:.2f}x"
        )
    result: dict[str, Any] = {
        "machine": {
            "python": platform.python_version(),
            "processor": platform.machine(),
            "cpus": multiprocessing.cpu_count(),
        },
        "parallel_capacity": capacity,
        "campaign": {
            "runs": 4,
            "scenario": args.scenario,
            "field": args.field,
            "testers": ["random", "ppo-max"],
            "seeds": [0, 1],
            "episodes_per_run": args.episodes,
            "wall_s": {"1": walls[1], "2": walls[2]},
            "time_ratio_2_over_1": ratio,
        },
        "searchers": searchers,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2))
    print(f"written to {args.out}")


if __name__ == "__main__":
    main()
