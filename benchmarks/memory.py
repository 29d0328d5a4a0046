"""Resident memory of one worker along a long run: does it grow with the number of episodes?

Executes one real run (``record_run``, what ``hazardhunt run`` and a campaign worker do) in a
fresh process and samples its resident set size every ``--every`` episodes. Reports the
memory after warm-up, at the end, the growth per 1,000 episodes fitted over the second half
of the run, and that growth extrapolated to a 20,000-episode run. Prints a table and writes
JSON with every sample.

    python benchmarks/memory.py --tester ppo-max --episodes 4000 \\
        --out benchmarks/results/memory.json
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import platform
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from hazardhunt.campaign.config import RunConfig
from hazardhunt.campaign.run import RunProgress, record_run

_PAGE = os.sysconf("SC_PAGE_SIZE")


def resident_mib() -> float:
    """This process's resident set size now, in MiB."""
    with open("/proc/self/statm", encoding="ascii") as statm:
        return int(statm.read().split()[1]) * _PAGE / 2**20


def sample_run(config: RunConfig, every: int) -> list[tuple[int, float]]:
    """Execute ``config`` in this process; (episodes done, RSS in MiB) every ``every``."""
    samples = [(0, resident_mib())]

    def progress(state: RunProgress) -> None:
        if state.episodes_done % every == 0:
            samples.append((state.episodes_done, resident_mib()))

    with tempfile.TemporaryDirectory() as folder:
        record_run(config, Path(folder) / "run", progress)
    return samples


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tester", default="ppo-max")
    parser.add_argument("--scenario", default="crossing")
    parser.add_argument("--field", default="1.25m")
    parser.add_argument("--episodes", type=int, default=4000)
    parser.add_argument("--every", type=int, default=250, help="episodes between samples")
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/memory.json"))
    args = parser.parse_args()

    config = RunConfig(
        scenario=args.scenario,
        field=args.field,
        tester=args.tester,
        seed=0,
        episodes=args.episodes,
    )
    with multiprocessing.get_context("spawn").Pool(1) as pool:
        samples = pool.apply(sample_run, (config, args.every))
    episodes = np.array([s[0] for s in samples], dtype=float)
    rss = np.array([s[1] for s in samples])
    second_half = episodes >= episodes[-1] / 2
    slope = float(np.polyfit(episodes[second_half], rss[second_half], 1)[0])
    warm = float(rss[episodes >= args.every][0])
    result: dict[str, Any] = {
        "machine": {"python": platform.python_version(), "processor": platform.machine()},
        "run": config.model_dump(),
        "samples": [{"episodes": int(e), "rss_mib": float(r)} for e, r in samples],
        "rss_after_warm_up_mib": warm,
        "rss_end_mib": float(rss[-1]),
        "peak_sampled_mib": float(rss.max()),
        "growth_mib_per_1000_episodes": 1000 * slope,
        "extrapolated_rss_at_20000_mib": float(rss[-1] + slope * (20_000 - episodes[-1])),
    }
    print(f"{args.tester} on {args.scenario} / {args.field}, {args.episodes} episodes")
    print(f"{'episodes':>8} {'RSS MiB':>8}")
    for e, r in samples:
        print(f"{e:8d} {r:8.1f}")
    print(
        f"after {args.every} episodes {warm:.0f} MiB, at the end {rss[-1]:.0f} MiB; growth "
        f"{result['growth_mib_per_1000_episodes']:.1f} MiB per 1,000 episodes (second half), "
        f"extrapolated to 20,000 episodes: {result['extrapolated_rss_at_20000_mib']:.0f} MiB"
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2))
    print(f"written to {args.out}")


if __name__ == "__main__":
    main()
