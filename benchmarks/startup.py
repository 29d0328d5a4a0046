"""What a short run costs before its first episode: ``hazardhunt run`` timed from the outside.

Each measurement is one ``hazardhunt run`` process against the conservative controller of the
mutation benchmark (which solves no optimisation, so that the episodes cost little and the
process's own start shows): importing, building the SUT and the tester, numba compiling
pyribs' CMA-ES helpers (``qd`` and the portfolio), the episodes, writing the results. Two
settings, alternating, in one session so that the ratio compares:

- ``cold``: every process gets an empty numba cache (``NUMBA_CACHE_DIR``), as a machine's first
  run does: numba compiles pyribs' helpers, and the functions other libraries keep in its cache;
- ``warm``: every process shares one cache, filled by an untimed first run, as every later run
  on the machine does.

(Before hazardhunt kept pyribs' helpers in numba's cache, every run compiled them: about 3 s,
``docs/search-methods.md``.)

Prints the median wall time per tester and setting, and the ratio; writes JSON with the
command and the date.

    python benchmarks/startup.py --testers portfolio cem --episodes 200 --repeats 3
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

CONTROLLER = "hazardhunt.benchmark.conservative:ConservativeController"
HAZARDHUNT = Path(sys.executable).with_name("hazardhunt")


def timed_run(tester: str, args: argparse.Namespace, cache: Path) -> float:
    """Wall time of one ``hazardhunt run`` whose numba cache is ``cache``, in s."""
    with tempfile.TemporaryDirectory() as scratch:
        command = [
            str(HAZARDHUNT), "run", "--controller", CONTROLLER, "--tester", tester,
            "--scenario", args.scenario, "--field", args.field, "--seed", str(args.seed),
            "--episodes", str(args.episodes), "--out", str(Path(scratch) / "run"), "--json",
        ]  # fmt: skip
        environment = os.environ | {"NUMBA_CACHE_DIR": str(cache)}
        start = time.perf_counter()
        subprocess.run(command, env=environment, check=True, capture_output=True)
        return time.perf_counter() - start


def measure(tester: str, args: argparse.Namespace) -> dict[str, Any]:
    times: dict[str, list[float]] = {"cold": [], "warm": []}
    with tempfile.TemporaryDirectory() as shared:
        timed_run(tester, args, Path(shared))  # fills the shared cache, untimed
        for _ in range(args.repeats):
            with tempfile.TemporaryDirectory() as empty:
                times["cold"].append(timed_run(tester, args, Path(empty)))
            times["warm"].append(timed_run(tester, args, Path(shared)))
    cold, warm = (statistics.median(times[setting]) for setting in ("cold", "warm"))
    return {
        "tester": tester,
        "times_s": times,
        "cold_s": cold,
        "warm_s": warm,
        "ratio": cold / warm,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--testers", nargs="+", default=["portfolio", "cem"])
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--scenario", default="crossing")
    parser.add_argument("--field", default="1.25m")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/startup.json"))
    args = parser.parse_args()
    rows = []
    for tester in args.testers:
        row = measure(tester, args)
        rows.append(row)
        print(
            f"{tester:>10}: {row['cold_s']:.2f} s with an empty numba cache, "
            f"{row['warm_s']:.2f} s with a filled one ({row['ratio']:.2f}x; medians of "
            f"{args.repeats})",
            flush=True,
        )
    record = {
        "command": shlex.join(["python", *sys.argv]),
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "episodes": args.episodes,
        "results": rows,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(record, indent=2) + "\n")


if __name__ == "__main__":
    main()
