"""Versions of a tester side by side on the held-out mutants, from result files.

Reads files of runs (``benchmarks/results/held_out_classes_*.json``: one row per
``hazardhunt run ... --controller hazardhunt.benchmark.held_out:M``, with the version's name,
the case, the failures, the classes and the first failure) and prints, per field and version,
against ``--against``: the classes found over the runs (``other`` left out), the runs with more
and fewer classes, the failures, and the runs whose first failure came at another episode; over
every seed, or ``--seeds``.
Prints Markdown; needs only the standard library.

    python benchmarks/held_out_versions.py benchmarks/results/held_out_classes_cell_border.json \\
        benchmarks/results/held_out_classes_fit_offsets.json \\
        --against "second default (repeat_gain 0.03)"
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

OTHER = "other"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("files", nargs="+", type=Path)
    parser.add_argument("--against", required=True, help="the version the others are held to")
    parser.add_argument("--seeds", nargs="+", type=int, help="only these seeds' runs")
    args = parser.parse_args()
    runs = [run for file in args.files for run in json.loads(file.read_text())["runs"]]
    if args.seeds is not None:
        runs = [run for run in runs if run["seed"] in args.seeds]
    base = {case(r): r for r in runs if r["version"] == args.against}
    print(
        "| field | version | runs | classes (--against: same runs) | more / fewer "
        "| failures (--against: same runs) | first failure moved |"
    )
    print("|---|---|---|---|---|---|---|")
    for field in sorted({r["field"] for r in runs}):
        versions = sorted({r["version"] for r in runs if r["field"] == field} - {args.against})
        for version in [args.against, *versions]:
            rows = [r for r in runs if r["version"] == version and r["field"] == field]
            pairs = [(r, base[case(r)]) for r in rows if case(r) in base]
            classes = f"{sum(counted(r) for r, _ in pairs)}"
            failures = f"{sum(r['failures'] for r, _ in pairs):,}"
            if version != args.against:  # beside the other's over the same runs
                classes += f" ({sum(counted(b) for _, b in pairs)})"
                failures += f" ({sum(b['failures'] for _, b in pairs):,})"
            more = sum(counted(r) > counted(b) for r, b in pairs)
            fewer = sum(counted(r) < counted(b) for r, b in pairs)
            moved = sum(r["first_failure_episode"] != b["first_failure_episode"] for r, b in pairs)
            cells = [field, version, len(pairs), classes, f"{more} / {fewer}", failures]
            print("| " + " | ".join(str(c) for c in [*cells, moved]) + " |")


def case(row: dict[str, Any]) -> tuple[str, str, str, int]:
    """The controller, scenario, field and seed a run was played on."""
    return (row["controller"], row["scenario"], row["field"], row["seed"])


def counted(row: dict[str, Any]) -> int:
    """The classes a run found, ``other`` left out."""
    return len(set(row["classes"]) - {OTHER})


if __name__ == "__main__":
    main()
