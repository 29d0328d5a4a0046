"""Variants of the default portfolio beside it on the nine cases, from result files.

Reads a variants file (``benchmarks/results/portfolio_ambush_variants.json``: one row per
``hazardhunt run --scenario S --field F --episodes 1000 --seed N --tester-param ARMS``, with
the variant's name and its classes and failures) and the files of the default's and the other
methods' runs that ``benchmarks/peers/nine.py`` reads. Per variant and the default: classes and
failures over every (case, seed), the runs with more and fewer classes than the default's run,
and per seed the cases in which it finds at least as many classes as every other method and
all of their classes together (``nine.py``'s counts with the variant's runs as the
portfolio's), and the median episode of the runs' first failures. With ``--against VARIANT``
the runs with more and fewer classes are counted against that variant's runs instead of the
default's; with ``--case CASE`` (and ``--seeds``, any of the variants' seeds) it prints instead
each variant's failures, classes and first failure per seed in that case, and below them every
method of the other files (the peers, the study's testers, the first default); with ``--arms
VARIANT``, per arm of that variant over its runs: the episodes it played, its failures, the
classes it found first (``other`` left out) and how many of them at episode ``--late`` or
later, and classes per 1,000 of its episodes. Prints Markdown; needs only the standard library.

    python benchmarks/portfolio_variants.py benchmarks/results/portfolio_ambush_variants.json \\
        benchmarks/results/peers.json benchmarks/results/peers_nine_*.json \\
        benchmarks/results/peers_crossing_seeds12.json \\
        benchmarks/results/peers_portfolio_seeds12.json \\
        benchmarks/results/aim_crossing_1.25m.json \\
        benchmarks/results/aim_clear_path_crossing_1.25m.json
    python benchmarks/portfolio_variants.py benchmarks/results/portfolio_ambush_variants.json \\
        benchmarks/results/peers.json --case crossing:1.25m --seeds 0 1 2 3 4 5 6 7 8
    python benchmarks/portfolio_variants.py benchmarks/results/portfolio_ambush_variants.json \\
        benchmarks/results/peers.json --arms aim-first
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent / "peers"))
from nine import OTHER, classes, leads, rows_of

DEFAULT = "portfolio"
SEEDS = (0, 1, 2)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("variants", type=Path)
    parser.add_argument("files", nargs="+", type=Path, help="the files nine.py reads")
    parser.add_argument("--seeds", nargs="+", type=int, default=list(SEEDS))
    parser.add_argument("--against", help="count runs with more / fewer against this variant")
    parser.add_argument("--case", help="print each variant's runs of this case, seed by seed")
    parser.add_argument("--arms", help="print what each arm of this variant played and found")
    parser.add_argument(
        "--late", type=int, default=300, help="with --arms: classes found from this episode on"
    )
    args = parser.parse_args()

    runs = json.loads(args.variants.read_text())["runs"]
    names = list(dict.fromkeys(run["variant"] for run in runs))
    by_variant = {
        name: {
            (run["case"], run["seed"]): run
            for run in runs
            if run["variant"] == name and run["seed"] in args.seeds
        }
        for name in names
    }
    base = {seed: rows_of(args.files, seed) for seed in args.seeds}
    if args.case:
        print_case(by_variant, base, args.case, args.seeds)
        return
    if args.arms is not None:
        print_arms(
            args.arms, list(variant_runs(by_variant, "--arms", args.arms).values()), args.late
        )
        return
    against = (
        (args.against, variant_runs(by_variant, "--against", args.against))
        if args.against
        else ("the default", {})
    )
    print("| | " + " | ".join([DEFAULT, *names]) + " |")
    print("|---" * (len(names) + 2) + "|")
    columns = [summary(base, {}, args.seeds, against)]
    for name in names:
        columns.append(summary(base, by_variant[name], args.seeds, against))
    for label in columns[0]:
        print(f"| {label} | " + " | ".join(str(column[label]) for column in columns) + " |")


def variant_runs(
    by_variant: dict[str, dict[tuple[str, int], dict[str, Any]]], option: str, name: str
) -> dict[tuple[str, int], dict[str, Any]]:
    """The runs of the variant ``name`` that ``option`` asked for, or exit naming the others."""
    if name not in by_variant:
        raise SystemExit(f"{option}: no variant {name!r} (there are {', '.join(by_variant)})")
    return by_variant[name]


def print_case(
    by_variant: dict[str, dict[tuple[str, int], dict[str, Any]]],
    base: dict[int, dict[tuple[str, str], dict[str, Any]]],
    case: str,
    seeds: list[int],
) -> None:
    """Per variant, then per method of the files ``nine.py`` reads (``portfolio`` there is the
    first default), its runs of ``case``: failures, classes and first failure, seed by seed."""
    print(f"| {case} | " + " | ".join(f"seed {seed}" for seed in seeds) + " |")
    print("|---" * (len(seeds) + 1) + "|")
    methods = sorted({method for rows in base.values() for c, method in rows if c == case})
    listed = [*by_variant.items()] + [
        (
            method,
            {
                (case, seed): rows[(case, method)]
                for seed, rows in base.items()
                if (case, method) in rows
            },
        )
        for method in methods
    ]
    for name, own in listed:
        cells = []
        for seed in seeds:
            run = own.get((case, seed))
            cells.append(
                "-"
                if run is None
                else f"{run['failures']} ({len(classes(run))}, "
                f"{run.get('first_failure_episode', '-')})"
            )
        print(f"| {name}: failures (classes, first failure) | " + " | ".join(cells) + " |")


def print_arms(name: str, runs: list[dict[str, Any]], late: int) -> None:
    """What each arm of ``runs`` played and found first, summed over the runs."""
    totals: dict[str, dict[str, int]] = {}
    for run in runs:
        for arm, played in run["arms"].items():
            total = totals.setdefault(arm, {"episodes": 0, "failures": 0, "classes": 0, "late": 0})
            found = {c: e for c, e in played["classes_first_found"].items() if c != OTHER}
            total["episodes"] += played["episodes"]
            total["failures"] += played["failures"]
            total["classes"] += len(found)
            total["late"] += sum(episode >= late for episode in found.values())
    print(
        f"| {name}, {len(runs)} runs: arm | episodes | failures | classes found first | "
        f"of them from episode {late} on | classes per 1,000 episodes |"
    )
    print("|---" * 6 + "|")
    for arm, total in totals.items():
        rate = 1000 * total["classes"] / total["episodes"] if total["episodes"] else 0.0
        print(
            f"| {arm} | {total['episodes']:,} | {total['failures']:,} | {total['classes']} | "
            f"{total['late']} | {rate:.1f} |"
        )


def summary(
    base: dict[int, dict[tuple[str, str], dict[str, Any]]],
    own: dict[tuple[str, int], dict[str, Any]],
    seeds: list[int],
    against: tuple[str, dict[tuple[str, int], dict[str, Any]]],
) -> dict[str, str]:
    """The default's numbers, or a variant's (``own``: its runs by case and seed) with its runs
    in place of the default's; runs with more and fewer classes counted against ``against``'s
    runs (``against``: its name and runs) where it has them, else the default's."""
    against_name, against_runs = against
    total, failures, more, fewer = 0, 0, 0, 0
    as_many, union, firsts = [], [], []
    for seed in seeds:
        rows = dict(base[seed])
        cases = sorted({case for case, method in rows if method == DEFAULT})
        for case in cases:
            if own and (case, seed) not in own:
                raise SystemExit(f"the variant has no run of {case}, seed {seed}")
            default_row = rows[(case, DEFAULT)]
            row = own.get((case, seed), default_row)
            found = len(classes(row))
            before = len(classes(against_runs.get((case, seed), default_row)))
            total, failures = total + found, failures + row["failures"]
            if row.get("first_failure_episode") is not None:
                firsts.append(row["first_failure_episode"])
            more, fewer = more + (found > before), fewer + (found < before)
            rows[(case, DEFAULT)] = row
        verdicts = [leads(rows, case, DEFAULT, set()) for case in cases]
        as_many.append(str(sum(v[0] for v in verdicts)))
        union.append(str(sum(v[1] for v in verdicts)))
    return {
        "classes": str(total),
        f"runs with more / fewer classes than {against_name}": f"{more} / {fewer}"
        if own or against_runs
        else "",
        "failures": f"{failures:,}",
        "cases with as many classes as every method, per seed": " / ".join(as_many),
        "cases with every method's classes together, per seed": " / ".join(union),
        "median first failure": f"{statistics.median(firsts):g}" if firsts else "-",
    }


if __name__ == "__main__":
    main()
