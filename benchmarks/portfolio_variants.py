"""Variants of the default portfolio beside it on the nine cases, from result files.

Reads a variants file (``benchmarks/results/portfolio_ambush_variants.json``: one row per
``hazardhunt run --scenario S --field F --episodes 1000 --seed N --tester-param ARMS``, with
the variant's name and its classes and failures) and the files of the default's and the other
methods' runs that ``benchmarks/peers/nine.py`` reads. Per variant and the default: classes and
failures over every (case, seed), the runs with more and fewer classes than the default's run,
and per seed the cases in which it finds at least as many classes as every other method and
all of their classes together (``nine.py``'s counts with the variant's runs as the
portfolio's). Prints Markdown; needs only the standard library.

    python benchmarks/portfolio_variants.py benchmarks/results/portfolio_ambush_variants.json \\
        benchmarks/results/peers.json benchmarks/results/peers_nine_*.json \\
        benchmarks/results/peers_crossing_seeds12.json \\
        benchmarks/results/peers_portfolio_seeds12.json \\
        benchmarks/results/aim_crossing_1.25m.json \\
        benchmarks/results/aim_clear_path_crossing_1.25m.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent / "peers"))
from nine import classes, leads, rows_of

DEFAULT = "portfolio"
SEEDS = (0, 1, 2)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("variants", type=Path)
    parser.add_argument("files", nargs="+", type=Path, help="the files nine.py reads")
    parser.add_argument("--seeds", nargs="+", type=int, default=list(SEEDS))
    args = parser.parse_args()

    runs = json.loads(args.variants.read_text())["runs"]
    names = list(dict.fromkeys(run["variant"] for run in runs))
    base = {seed: rows_of(args.files, seed) for seed in args.seeds}
    print("| | " + " | ".join([DEFAULT, *names]) + " |")
    print("|---" * (len(names) + 2) + "|")
    columns = [summary(base, {}, args.seeds)]
    for name in names:
        own = {
            (run["case"], run["seed"]): run
            for run in runs
            if run["variant"] == name and run["seed"] in args.seeds
        }
        columns.append(summary(base, own, args.seeds))
    for label in columns[0]:
        print(f"| {label} | " + " | ".join(str(column[label]) for column in columns) + " |")


def summary(
    base: dict[int, dict[tuple[str, str], dict[str, Any]]],
    own: dict[tuple[str, int], dict[str, Any]],
    seeds: list[int],
) -> dict[str, str]:
    """The default's numbers, or a variant's (``own``: its runs by case and seed) with its runs
    in place of the default's."""
    total, failures, more, fewer = 0, 0, 0, 0
    as_many, union = [], []
    for seed in seeds:
        rows = dict(base[seed])
        cases = sorted({case for case, method in rows if method == DEFAULT})
        for case in cases:
            if own and (case, seed) not in own:
                raise SystemExit(f"the variant has no run of {case}, seed {seed}")
            default_row = rows[(case, DEFAULT)]
            row = own.get((case, seed), default_row)
            found, before = len(classes(row)), len(classes(default_row))
            total, failures = total + found, failures + row["failures"]
            more, fewer = more + (found > before), fewer + (found < before)
            rows[(case, DEFAULT)] = row
        verdicts = [leads(rows, case, DEFAULT, set()) for case in cases]
        as_many.append(str(sum(v[0] for v in verdicts)))
        union.append(str(sum(v[1] for v in verdicts)))
    return {
        "classes": str(total),
        "runs with more / fewer classes than the default": f"{more} / {fewer}" if own else "",
        "failures": f"{failures:,}",
        "cases with as many classes as every method, per seed": " / ".join(as_many),
        "cases with every method's classes together, per seed": " / ".join(union),
    }


if __name__ == "__main__":
    main()
