"""The nine (scenario, field) cases side by side, from the JSON files ``peers.py`` wrote.

Per case and method: distinct failure classes found (``other`` not counted) and failures, for
one seed; then the targets of the episode-level testers against the study's testers: whether
the best of ``--new`` finds at least as many classes as ``random`` and as ``ppo-max`` in every
case, strictly more in how many, and the union of every method's classes in how many. With
``--default``, the same two counts for that method against every other one, and, for each other
method measured in every case, against all the rest but the default: how often any single
method leads. Later files win where two give the same (case, method, seed). Prints Markdown;
needs only the standard library.

    python benchmarks/peers/nine.py benchmarks/results/peers.json \\
        benchmarks/results/peers_nine_*.json --seed 0
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

OTHER = "other"
BASELINES = ("random", "ppo-max")
ORDER = (
    "cem",
    "qd",
    "ppo-novelty",
    "random",
    "ppo-max",
    "ppo-acc",
    "cma",
    "map-elites",
    "verifai-ce",
    "verifai-sa",
    "verifai-bandit",
)


def rows_of(files: list[Path], seed: int) -> dict[tuple[str, str], dict[str, Any]]:
    """(case, method) -> row, for ``seed``."""
    rows: dict[tuple[str, str], dict[str, Any]] = {}
    for file in files:
        for row in json.loads(file.read_text())["runs"]:
            if row["seed"] == seed:
                rows[(row["case"], row["method"])] = row
    return rows


def classes(row: dict[str, Any]) -> set[str]:
    return set(row["classes"]) - {OTHER}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("files", nargs="+", type=Path)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--new", nargs="+", default=["cem", "qd"], help="the new testers")
    parser.add_argument(
        "--default",
        help="a method to hold against every other one: in how many cases it finds at least "
        "as many classes as each, and all of them together",
    )
    args = parser.parse_args()

    rows = rows_of(args.files, args.seed)
    cases = sorted({case for case, _ in rows})
    found = {method for _, method in rows}
    methods = [m for m in ORDER if m in found] + sorted(found - set(ORDER))
    print("| case | " + " | ".join(f"`{m}`" for m in methods) + " | all methods |")
    print("|---" * (len(methods) + 2) + "|")
    at_least, strictly_more, union_reached, complete = 0, 0, 0, 0
    for case in cases:
        union = set().union(*(classes(r) for (c, _), r in rows.items() if c == case))
        cells = []
        for method in methods:
            row = rows.get((case, method))
            cells.append("-" if row is None else f"{len(classes(row))} ({row['failures']})")
        print(f"| {case} | " + " | ".join(cells) + f" | {len(union)} |")
        new = [len(classes(rows[(case, m)])) for m in args.new if (case, m) in rows]
        base = [len(classes(rows[(case, m)])) for m in BASELINES if (case, m) in rows]
        if not new or len(base) < len(BASELINES):
            continue
        complete += 1
        best = max(new)
        at_least += best >= max(base)
        strictly_more += best > max(base)
        union_reached += any(
            classes(rows[(case, m)]) == union for m in args.new if (case, m) in rows
        )
    print()
    print("Cells: classes found (failures). Targets, best of " + ", ".join(args.new) + ":")
    print(f"- at least as many classes as {' and '.join(BASELINES)}: {at_least} of {complete}")
    print(f"- strictly more: {strictly_more} of {complete}")
    print(f"- the union of all methods' classes: {union_reached} of {complete}")
    if args.default:
        print_default(rows, cases, args.default)
        print_leaders(rows, cases, args.default)


def print_default(rows: dict[tuple[str, str], dict[str, Any]], cases: list[str], name: str) -> None:
    """Per case, whether ``name`` found at least as many classes as every other method, and
    every method's classes together; then the counts."""
    as_many, union_reached, complete = 0, 0, 0
    print()
    print(f"`{name}` against every other method:")
    print()
    print("| case | classes | best other (method) | all methods | >= every method | union |")
    print("|---|---|---|---|---|---|")
    for case in cases:
        if (case, name) not in rows:
            continue
        complete += 1
        own = classes(rows[(case, name)])
        others = {m: classes(r) for (c, m), r in rows.items() if c == case and m != name}
        union = set(own).union(*others.values())
        best = max(others, key=lambda m: len(others[m]), default=None)
        best_count = len(others[best]) if best else 0
        enough, complete_union = leads(rows, case, name, set())
        as_many += enough
        union_reached += complete_union
        print(
            f"| {case} | {len(own)} | {best_count} (`{best}`) | {len(union)} | "
            f"{'yes' if enough else 'no'} | {'yes' if complete_union else 'no'} |"
        )
    print()
    print(f"- at least as many classes as every other method: {as_many} of {complete}")
    print(f"- every method's classes together: {union_reached} of {complete}")


def leads(
    rows: dict[tuple[str, str], dict[str, Any]], case: str, method: str, left_out: set[str]
) -> tuple[bool, bool]:
    """Whether ``method`` found at least as many classes in ``case`` as every other method
    measured there but ``left_out``, and every class that they all found together."""
    own = classes(rows[(case, method)])
    others = [
        classes(r) for (c, m), r in rows.items() if c == case and m not in {method, *left_out}
    ]
    union = set(own).union(*others)
    return all(len(own) >= len(o) for o in others), own == union


def print_leaders(rows: dict[tuple[str, str], dict[str, Any]], cases: list[str], name: str) -> None:
    """For ``name`` and each method measured in every case: in how many cases it finds at least
    as many classes as every other method measured there but ``name``, and all of their
    classes together. A target asked of one method is hard in proportion to how often any
    method meets it."""
    methods = sorted({m for _, m in rows if all((c, m) in rows for c in cases)} - {name})
    print()
    print(f"Each method against every other one but `{name}`, over the {len(cases)} cases:")
    print()
    print("| method | >= every other method | union |")
    print("|---|---|---|")
    for method in [name, *methods] if all((c, name) in rows for c in cases) else methods:
        verdicts = [leads(rows, case, method, {name}) for case in cases]
        print(f"| `{method}` | {sum(v[0] for v in verdicts)} | {sum(v[1] for v in verdicts)} |")


if __name__ == "__main__":
    main()
