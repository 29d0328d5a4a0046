"""How a campaign scales from one local worker to two, beside what the machine's cores allow.

Two measurements in one command:

1. The machine's parallel capacity: the same CPU-bound pure-Python loop in one process, then
   in two processes at once. On a machine whose two vCPUs share a physical core (or a busy
   host), each of the two runs slower than the one alone, and no campaign can scale better.
2. A 4-run campaign (``--scenario`` x ``--field`` x random and ppo-max x 2 seeds, ``--episodes``
   each) executed with ``--workers 1`` and then with ``--workers 2`` into fresh directories;
   the ratio of their wall times is the campaign's scaling.

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
from pathlib import Path
from typing import Any

from rich.console import Console

from hazardhunt.campaign.campaign import run_campaign
from hazardhunt.campaign.config import load_campaign


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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=150, help="episodes per run")
    parser.add_argument("--scenario", default="crossing")
    parser.add_argument("--field", default="1.25m")
    parser.add_argument("--spin", type=int, default=20_000_000, help="iterations of the loop")
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/scaling.json"))
    args = parser.parse_args()

    capacity = parallel_capacity(args.spin)
    with tempfile.TemporaryDirectory() as folder:
        path = campaign_file(Path(folder), args.scenario, args.field, args.episodes)
        walls: dict[int, float] = {}
        for workers in (1, 2):
            walls[workers] = time_campaign(path, workers, Path(folder) / f"workers-{workers}")
    ratio = walls[2] / walls[1]
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
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2))
    print(f"written to {args.out}")


if __name__ == "__main__":
    main()
