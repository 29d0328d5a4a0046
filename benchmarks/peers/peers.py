"""Off-the-shelf search methods against hazardhunt's testers, at the same budget and seeds.

Each peer treats an episode as one point (the human's open-loop actions, 15 decisions x 2 in
[-1, 1]) and maximises its maximum risk; every episode it plays counts against the budget.
hazardhunt's testers run through ``hazardhunt run --json`` in hazardhunt's own venv, on the
same source tree. For each method, case and seed: failures found, distinct failure classes
(the mechanism classifier, ``other`` not counted) and the episode of the first failure
(counted from 0, as in a run's summary). Prints a table and writes JSON.

Run with the peers' venv (benchmarks/peers/README.md):

    /work/peers-venv/bin/python benchmarks/peers/peers.py --cases crossing:1.25m \
        --episodes 200 --seeds 0 --workers 2 --hazardhunt .venv/bin/hazardhunt
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import platform
import shlex
import sys
import time
from collections import Counter
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass
from datetime import datetime, timezone
from functools import partial
from importlib import metadata
from pathlib import Path
from typing import Any

from evaluation import (
    Case,
    Evaluation,
    TesterRun,
    evaluate_batch,
    horizon,
    run_tester,
    tester_spec,
)
from searchers import BATCHED, METHODS, Points, search

import hazardhunt
from hazardhunt.spec.failure_classes import OTHER

REPOSITORY = Path(__file__).resolve().parents[2]
SCENARIOS = ("crossing", "head-on", "overtaking")
FIELDS = ("none", "1.25m", "2m")
VERSIONED = ("hazardhunt", "cma", "ribs", "verifai", "scenic", "numpy", "casadi", "pandas")


@dataclass(frozen=True)
class PeerRun:
    """One search method on one case with one seed."""

    method: str
    case: Case
    seed: int
    episodes: int
    dimension: int


def peer_row(run: PeerRun, evaluations: list[Evaluation], wall_time: float) -> dict[str, Any]:
    """The table's row of a peer's run, with the outcomes and the best risk besides."""
    classes = sorted({e.failure_class for e in evaluations if e.failure_class is not None})
    first = next((i for i, e in enumerate(evaluations) if e.failed), None)
    return {
        "method": run.method,
        "kind": "peer",
        "case": str(run.case),
        "seed": run.seed,
        "episodes": len(evaluations),
        "failures": sum(e.failed for e in evaluations),
        "classes_found": len(set(classes) - {OTHER}),
        "classes": classes,
        "first_failure_episode": first,
        "best_max_risk": max(e.max_risk for e in evaluations),
        "outcomes": dict(Counter(str(e.outcome) for e in evaluations)),
        "wall_time_s": wall_time,
    }


def run_peer_here(run: PeerRun) -> dict[str, Any]:
    """A whole run in this process (for methods that ask one point at a time)."""
    started = time.perf_counter()
    searcher = METHODS[run.method](run.dimension, run.seed)
    evaluations = search(searcher, partial(evaluate_batch, run.case), run.episodes)
    return peer_row(run, evaluations, time.perf_counter() - started)


def run_peer_spread(run: PeerRun, pool: ProcessPoolExecutor) -> dict[str, Any]:
    """A run driven from this process, each batch's episodes spread over the pool."""

    def evaluate_spread(points: Points) -> list[Evaluation]:
        futures = [pool.submit(evaluate_batch, run.case, point[None, :]) for point in points]
        return [future.result()[0] for future in futures]

    started = time.perf_counter()
    searcher = METHODS[run.method](run.dimension, run.seed)
    evaluations = search(searcher, evaluate_spread, run.episodes)
    return peer_row(run, evaluations, time.perf_counter() - started)


def tester_row(run: TesterRun) -> dict[str, Any]:
    """The table's row of a hazardhunt tester's run, from its summary.json."""
    summary = run_tester(run)
    return {
        "method": run.tester,
        "kind": "hazardhunt",
        "case": str(run.case),
        "seed": run.seed,
        "episodes": summary["episodes"],
        "failures": summary["failures"],
        "classes_found": summary["classes_found"],
        "classes": summary["classes"],
        "first_failure_episode": summary["first_failure_episode"],
        "best_max_risk": None,
        "outcomes": {
            outcome: summary[f"{outcome}s"]
            for outcome in ("failure", "safe_contact", "stall", "timeout", "goal", "sut_error")
        },
        "wall_time_s": summary["wall_time_s"],
        "source_digest": summary["source_digest"],
    }


def arguments() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--cases",
        nargs="+",
        default=[f"{scenario}:{field}" for scenario in SCENARIOS for field in FIELDS],
        help="scenario:field, e.g. crossing:1.25m (default: the nine of the study)",
    )
    parser.add_argument("--episodes", type=int, default=1000, help="budget per run")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--methods", nargs="*", default=list(METHODS), choices=list(METHODS))
    parser.add_argument(
        "--testers",
        nargs="*",
        default=["random", "ppo-max"],
        help="hazardhunt testers to run beside the peers: names or package.module:Class, "
        "with parameters in brackets if any: 'cem[space=aim]'",
    )
    parser.add_argument(
        "--hazardhunt",
        type=Path,
        default=REPOSITORY / ".venv" / "bin" / "hazardhunt",
        help="the hazardhunt command of a venv with the testers' dependencies",
    )
    parser.add_argument("--workers", type=int, default=2, help="worker processes")
    parser.add_argument(
        "--out", type=Path, default=REPOSITORY / "benchmarks" / "results" / "peers.json"
    )
    args = parser.parse_args()
    if args.episodes < 1 or args.workers < 1:
        parser.error("--episodes and --workers must be at least 1")
    try:
        args.cases = [Case.parse(text) for text in args.cases]
        for tester in args.testers:
            tester_spec(tester)
    except ValueError as error:
        parser.error(str(error))
    if args.testers and not args.hazardhunt.exists():
        parser.error(f"--hazardhunt {args.hazardhunt} does not exist (or pass --testers alone)")
    return args


def run_all(args: argparse.Namespace, pool: ProcessPoolExecutor) -> list[dict[str, Any]]:
    """Every run of the grid: whole runs queued on the pool, batched peers driven from here."""
    dimensions = {case: 2 * pool.submit(horizon, case).result() for case in args.cases}
    peers = [
        PeerRun(method, case, seed, args.episodes, dimensions[case])
        for case in args.cases
        for method in args.methods
        for seed in args.seeds
    ]
    testers = [
        TesterRun(tester, case, seed, args.episodes, args.hazardhunt, REPOSITORY / "src")
        for case in args.cases
        for tester in args.testers
        for seed in args.seeds
    ]
    queued: list[Future[dict[str, Any]]] = [pool.submit(tester_row, run) for run in testers]
    queued += [pool.submit(run_peer_here, run) for run in peers if run.method not in BATCHED]
    rows = []
    for run in peers:
        if run.method in BATCHED:
            rows.append(run_peer_spread(run, pool))
            report(rows[-1])
    for future in queued:
        rows.append(future.result())
        report(rows[-1])
    order = [*args.testers, *args.methods]
    return sorted(rows, key=lambda r: (r["case"], order.index(r["method"]), r["seed"]))


def report(row: dict[str, Any]) -> None:
    print(
        f"done: {row['method']} {row['case']} seed {row['seed']}: {row['failures']} failures "
        f"({row['wall_time_s']:.0f} s)",
        file=sys.stderr,
        flush=True,
    )


def table(rows: list[dict[str, Any]]) -> str:
    """method, case, seed, failures, classes, first failure: one line per run."""
    lines = [f"{'method':16} {'case':22} {'seed':>4} {'failures':>8} {'classes':>7} {'first':>6}"]
    for r in rows:
        first = "-" if r["first_failure_episode"] is None else str(r["first_failure_episode"])
        lines.append(
            f"{r['method']:16} {r['case']:22} {r['seed']:4d} {r['failures']:8d} "
            f"{r['classes_found']:7d} {first:>6}"
        )
    return "\n".join(lines)


def versions() -> dict[str, str]:
    found = {
        "python": platform.python_version(),
        "source_digest": hazardhunt.source_digest(),
        "blas": hazardhunt.blas_kernel(),
    }
    for name in VERSIONED:
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = "not installed"
    return found


def main() -> None:
    args = arguments()
    started_at = datetime.now(timezone.utc).isoformat()
    clock = time.perf_counter()
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=args.workers, mp_context=context) as pool:
        rows = run_all(args, pool)
    wall_time = time.perf_counter() - clock
    print(table(rows))
    print(f"total wall time {wall_time:.0f} s with {args.workers} workers")
    digests = {r["source_digest"] for r in rows if "source_digest" in r}
    if digests - {hazardhunt.source_digest()}:
        print("warning: the testers ran other hazardhunt code than the peers", file=sys.stderr)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(
        json.dumps(
            {
                "command": shlex.join([sys.executable, *sys.argv]),
                "date": started_at,
                "versions": versions(),
                "settings": {
                    "cases": [str(case) for case in args.cases],
                    "episodes": args.episodes,
                    "seeds": args.seeds,
                    "methods": args.methods,
                    "testers": args.testers,
                    "workers": args.workers,
                },
                "wall_time_s": wall_time,
                "runs": rows,
            },
            indent=2,
        )
        + "\n"
    )
    print(f"written to {args.out}")


if __name__ == "__main__":
    main()
