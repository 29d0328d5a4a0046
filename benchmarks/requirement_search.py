"""Does searching on a requirement's robustness find its violations sooner than the same search
scored by the contact rule's risk? Runs one tester with the same seeds and budget both ways
(``--search-on`` or not) and reports, per requirement and seed, the first violating episode
and the violations found.

    python benchmarks/requirement_search.py --tester cem --episodes 200 --seeds 0 1 2 \\
        --requirements slow-near-people no-restart-in-field \\
        --out benchmarks/results/requirement_search_cem.json
    python benchmarks/requirement_search.py --tester cem --episodes 200 --seeds 0 1 2 \
        --requirements benchmarks/requirements_hard.toml:near-while-moving \
        --out benchmarks/results/requirement_search_cem_hard.json
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from hazardhunt.campaign.config import EnvOptions, RunConfig
from hazardhunt.campaign.run import record_run


def played(
    scenario: str, field: str, tester: str, requirement: str, seed: int, episodes: int, on: bool
) -> dict[str, Any]:
    """One run judged by ``requirement`` (a library name or ``FILE.toml:NAME``), searching on
    it when ``on``."""
    name = requirement.rpartition(":")[2]
    config = RunConfig(
        scenario=scenario,
        field=field,
        tester=tester,
        seed=seed,
        episodes=episodes,
        env=EnvOptions(),
        requirements=[requirement],
        search_on=name if on else None,
    )
    with tempfile.TemporaryDirectory() as directory:
        started = time.perf_counter()
        summary = record_run(config, Path(directory) / "run")
    counted = summary["requirements"][name]
    return {
        "first_violation_episode": counted["first_violation_episode"],
        "violations": counted["violations"],
        "min_robustness": counted["min_robustness"],
        "failures": summary["failures"],
        "wall_s": time.perf_counter() - started,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="crossing")
    parser.add_argument("--field", default="2m")
    parser.add_argument("--tester", default="cem")
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--requirements", nargs="+", default=["slow-near-people"])
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    rows = []
    for requirement in args.requirements:
        for seed in args.seeds:
            for on in (False, True):
                row = played(
                    args.scenario, args.field, args.tester, requirement, seed, args.episodes, on
                )
                row |= {"requirement": requirement, "seed": seed, "search_on": on}
                rows.append(row)
                print(
                    f"{requirement:22s} seed {seed} "
                    f"{'robustness' if on else 'risk':10s}: first violation "
                    f"{row['first_violation_episode']}, {row['violations']} violations, "
                    f"lowest robustness {row['min_robustness']:.3g}",
                    flush=True,
                )
    medians = {}
    for requirement in args.requirements:
        for on in (False, True):
            mine = [r for r in rows if r["requirement"] == requirement and r["search_on"] == on]
            firsts = [
                r["first_violation_episode"]
                if r["first_violation_episode"] is not None
                else args.episodes
                for r in mine
            ]
            key = f"{requirement} / {'robustness' if on else 'risk'}"
            medians[key] = {
                "median_first_violation": statistics.median(firsts),
                "median_violations": statistics.median(r["violations"] for r in mine),
            }
            print(key, medians[key])
    if args.out:
        result = {
            "command": " ".join([Path(sys.executable).name, *sys.argv]),
            "date": datetime.now(UTC).isoformat(),
            "scenario": args.scenario,
            "field": args.field,
            "tester": args.tester,
            "episodes": args.episodes,
            "note": "a run without a violation counts its budget as its first violation",
            "runs": rows,
            "medians": medians,
        }
        args.out.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
