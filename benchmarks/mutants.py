"""The mutation benchmark: how many planted bugs each tester finds within a budget.

The system under test is :class:`hazardhunt.benchmark.conservative.ConservativeController`, which no
human can make fail, and each of its mutants (one narrow planted bug each; see
docs/search-methods.md). For every tester x scenario x field x seed x SUT, one run of
``--episodes`` episodes; a mutant is *killed* when the run finds a failure, and the episode of
the first failure says whether within the early budget (``--early``, 100 by default) as well.
Reported per tester: mutants killed per scenario within both budgets, the mutation score (the
share of mutant x scenario pairs killed) and the false alarms (failures against the original,
which must be 0). Prints tables and writes JSON with the command and the date.

    python benchmarks/mutants.py --episodes 1000 --testers random ppo-max --workers 2

A tester is a built-in name or, where the tester registry takes them, an import path
``package.module:Class``; ``--tester-param KEY=VALUE`` sets a parameter of every tester given:

    python benchmarks/mutants.py --testers qd --seeds 0 1 2 --episodes 100 \
        --tester-param clear_path=true

``--held-out`` runs the mutants written after the testers' defaults were settled
(:mod:`hazardhunt.benchmark.held_out`): how the defaults do on bugs they were not tuned to.
"""

from __future__ import annotations

import argparse
import multiprocessing
import shlex
import statistics
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import tomllib
from pydantic import ValidationError

import hazardhunt
from hazardhunt.benchmark.conservative import MUTANTS, ConservativeController
from hazardhunt.benchmark.held_out import HELD_OUT_MUTANTS
from hazardhunt.campaign.config import PluginSpec, RunConfig
from hazardhunt.campaign.run import record_run
from hazardhunt.campaign.store import write_json_atomic
from hazardhunt.textfiles import format_validation_error
from hazardhunt.world.scenario import BUILTIN_SCENARIOS

MODULES = {
    cls.__name__: cls.__module__ for cls in (ConservativeController, *MUTANTS, *HELD_OUT_MUTANTS)
}
"""The module of the original and of each mutant, by class name."""
ORIGINAL = ConservativeController.__name__


def one_run(config: RunConfig) -> dict[str, Any]:
    """Run ``config`` in a scratch directory; what the benchmark needs from its summary."""
    with tempfile.TemporaryDirectory() as scratch:
        summary = record_run(config, Path(scratch) / "run")
    assert config.controller is not None
    return {
        "tester": config.tester,
        "scenario": config.scenario,
        "field": config.field,
        "seed": config.seed,
        "sut": config.controller.path.partition(":")[2],
        "episodes": summary["episodes"],
        "failures": summary["failures"],
        "first_failure_episode": summary["first_failure_episode"],
        "wall_time_s": summary["wall_time_s"],
    }


def configs(args: argparse.Namespace) -> list[RunConfig]:
    """Every run of the grid; exits with a message when one cannot be configured."""
    suts = [ORIGINAL, *args.mutants]
    grid = []
    for tester in args.testers:
        for field in args.fields:
            for seed in args.seeds:
                for scenario in args.scenarios:
                    for sut in suts:
                        try:
                            grid.append(
                                RunConfig(
                                    scenario=scenario,
                                    field=field,
                                    tester=tester,
                                    seed=seed,
                                    episodes=args.episodes,
                                    tester_params=args.tester_param,
                                    controller=PluginSpec(path=f"{MODULES[sut]}:{sut}"),
                                )
                            )
                        except ValidationError as error:
                            problem = format_validation_error(error)
                            sys.exit(f"error: {tester} on {scenario}/{field}: {problem}")
    return grid


def assignment(text: str) -> tuple[str, Any]:
    """A ``KEY=VALUE`` option as (key, value); the value is read as TOML."""
    key, separator, value = text.partition("=")
    if not separator or not key.strip():
        raise argparse.ArgumentTypeError(f"{text!r} is not KEY=VALUE")
    try:
        return key.strip(), tomllib.loads(f"value = {value}")["value"]
    except tomllib.TOMLDecodeError:
        return key.strip(), value


def killed_within(runs: list[dict[str, Any]], budget: int) -> int:
    """How many of ``runs`` found a failure within the first ``budget`` episodes."""
    return sum(
        r["first_failure_episode"] is not None and r["first_failure_episode"] < budget for r in runs
    )


def score(runs: list[dict[str, Any]], args: argparse.Namespace) -> list[dict[str, Any]]:
    """Per tester, field and seed: kills per scenario, mutation scores and false alarms."""
    rows = []
    for tester in args.testers:
        for field in args.fields:
            for seed in args.seeds:
                mine = [
                    r
                    for r in runs
                    if r["tester"] == tester and r["field"] == field and r["seed"] == seed
                ]
                mutants = [r for r in mine if r["sut"] != ORIGINAL]
                per_scenario = {
                    scenario: {
                        "killed_early": killed_within(
                            [r for r in mutants if r["scenario"] == scenario], args.early
                        ),
                        "killed": killed_within(
                            [r for r in mutants if r["scenario"] == scenario], args.episodes
                        ),
                        "mutants": len(args.mutants),
                    }
                    for scenario in args.scenarios
                }
                pairs = len(args.mutants) * len(args.scenarios)
                rows.append(
                    {
                        "tester": tester,
                        "field": field,
                        "seed": seed,
                        "scenarios": per_scenario,
                        "mutation_score_early": killed_within(mutants, args.early) / pairs,
                        "mutation_score": killed_within(mutants, args.episodes) / pairs,
                        "mutants_killed_in_any_scenario": len(
                            {r["sut"] for r in mutants if r["first_failure_episode"] is not None}
                        ),
                        "false_alarms": sum(r["failures"] for r in mine if r["sut"] == ORIGINAL),
                    }
                )
    return rows


def totals(runs: list[dict[str, Any]], args: argparse.Namespace) -> list[dict[str, Any]]:
    """Per tester and field, over every seed and scenario: the mutant pairs killed within both
    budgets, the median episode of the first failure over the pairs killed, and the failures
    found against the mutants."""
    rows = []
    for tester in args.testers:
        for field in args.fields:
            mutants = [
                r
                for r in runs
                if r["tester"] == tester and r["field"] == field and r["sut"] != ORIGINAL
            ]
            firsts = [r["first_failure_episode"] for r in mutants]
            found = [first for first in firsts if first is not None]
            rows.append(
                {
                    "tester": tester,
                    "field": field,
                    "pairs": len(mutants),
                    "killed_early": killed_within(mutants, args.early),
                    "killed": killed_within(mutants, args.episodes),
                    "median_first_failure": statistics.median(found) if found else None,
                    "failures": sum(r["failures"] for r in mutants),
                }
            )
    return rows


def print_tables(
    runs: list[dict[str, Any]], rows: list[dict[str, Any]], args: argparse.Namespace
) -> None:
    early, budget = args.early, args.episodes
    print(f"\nmutants killed within {early} / {budget} episodes (of {len(args.mutants)})")
    header = "".join(f"{s:>14}" for s in args.scenarios)
    print(f"{'tester':14} {'field':6} {'seed':>4}{header} {'score':>12} {'false alarms':>13}")
    for row in rows:
        cells = "".join(
            f"{row['scenarios'][s]['killed_early']:>8d} / {row['scenarios'][s]['killed']:<3d}"
            for s in args.scenarios
        )
        scores = f"{row['mutation_score_early']:.2f} / {row['mutation_score']:.2f}"
        print(
            f"{row['tester']:14} {row['field']:6} {row['seed']:4d}{cells} {scores:>12} "
            f"{row['false_alarms']:13d}"
        )
    print(f"\npairs killed within {early} / {budget} episodes over every seed and scenario")
    for row in totals(runs, args):
        median = row["median_first_failure"]
        print(
            f"{row['tester']:14} {row['field']:6} {row['killed_early']:>4d} / "
            f"{row['killed']:<3d} of {row['pairs']:<4d} median first failure "
            f"{'-' if median is None else f'{median:g}'}, {row['failures']} failures"
        )
    print("\nepisode of the first failure per SUT ('-': none within the budget)")
    columns = [
        (tester, field, seed, scenario)
        for tester in args.testers
        for field in args.fields
        for seed in args.seeds
        for scenario in args.scenarios
    ]
    labels = [
        " ".join(
            [tester, scenario]
            + ([field] if len(args.fields) > 1 else [])
            + ([f"seed {seed}"] if len(args.seeds) > 1 else [])
        )
        for tester, field, seed, scenario in columns
    ]
    width = max(len(label) for label in labels) + 2
    print(f"{'SUT':30}" + "".join(f"{label:>{width}}" for label in labels))
    by_key = {(r["tester"], r["field"], r["seed"], r["scenario"], r["sut"]): r for r in runs}
    for sut in [ORIGINAL, *args.mutants]:
        firsts = [by_key[(*column, sut)]["first_failure_episode"] for column in columns]
        print(f"{sut:30}" + "".join(f"{'-' if f is None else f:>{width}}" for f in firsts))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--testers",
        nargs="+",
        default=["random", "ppo-max"],
        help="built-in tester names or package.module:Class import paths",
    )
    parser.add_argument("--scenarios", nargs="+", default=list(BUILTIN_SCENARIOS))
    parser.add_argument(
        "--fields",
        nargs="+",
        default=["none", "1.25m"],
        help="field settings; with 'none' the controller alone stands between human and robot",
    )
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--episodes", type=int, default=1000, help="budget per run")
    parser.add_argument("--early", type=int, default=100, help="the early budget, in episodes")
    parser.add_argument(
        "--mutants",
        nargs="+",
        default=[m.__name__ for m in MUTANTS],
        choices=[name for name in MODULES if name != ORIGINAL],
        help="mutant class names",
    )
    parser.add_argument(
        "--held-out",
        action="store_true",
        help="the mutants written after the defaults were settled (HELD_OUT_MUTANTS), instead",
    )
    parser.add_argument(
        "--tester-param",
        type=assignment,
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a parameter of every tester given (repeatable), as `hazardhunt run` takes it",
    )
    parser.add_argument("--workers", type=int, default=2, help="runs executed at once")
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/mutants.json"))
    args = parser.parse_args()
    args.tester_param = dict(args.tester_param)
    if args.held_out:
        args.mutants = [m.__name__ for m in HELD_OUT_MUTANTS]
    if args.early > args.episodes:
        parser.error("--early must not exceed --episodes")

    grid = configs(args)
    print(f"{len(grid)} runs of {args.episodes} episodes, {args.workers} at a time")
    started = time.perf_counter()
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=args.workers, mp_context=context) as pool:
        runs = []
        for run in pool.map(one_run, grid):
            runs.append(run)
            print(
                f"[{len(runs)}/{len(grid)}] {run['tester']} {run['scenario']} {run['field']} "
                f"seed {run['seed']} {run['sut']}: {run['failures']} failures "
                f"({run['wall_time_s']:.0f} s)",
                flush=True,
            )
    wall = time.perf_counter() - started
    rows = score(runs, args)
    print_tables(runs, rows, args)
    alarms = sum(row["false_alarms"] for row in rows)
    if alarms:
        print(f"\nWARNING: {alarms} failures against the original: the benchmark is invalid")
    print(f"\ntotal wall time {wall:.0f} s with {args.workers} workers")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(
        args.out,
        {
            "command": shlex.join([Path(sys.executable).name, *sys.argv]),
            "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "blas": hazardhunt.blas_kernel(),
            "arguments": {k: str(v) for k, v in vars(args).items()},
            "wall_time_s": wall,
            "scores": rows,
            "totals": totals(runs, args),
            "runs": runs,
        },
    )
    print(f"written to {args.out}")
    if alarms:
        sys.exit(1)


if __name__ == "__main__":
    main()
