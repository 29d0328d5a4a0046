"""How far can multilevel splitting go on a case? Its efficiency over plain Monte Carlo from Au
and Beck's error formula, ideal and as measured.

Subset simulation (:mod:`hazardhunt.likelihood.splitting`) with ``N`` samples per level and
conditional shares ``p_1 ... p_m`` has per level a squared coefficient of variation
``d_i^2 = (1 - p_i) / (N p_i) (1 + g_i)`` (``g_i``: the correlation along the level's chains,
0 for the first level, which is plain Monte Carlo) and plays ``N + (m - 1) N (1 - p0)``
episodes. Plain Monte Carlo needs ``(1 - p) / (p d^2)`` episodes for a relative error ``d``.
The efficiency is the ratio of the two at the same error, with ``d^2`` either the sum of the
levels' (independent levels: Au and Beck's estimate) or ``(sum of d_i)^2`` (fully correlated:
the upper bound hazardhunt reports, whose intervals cover).

Prints, at the probability ``p`` of a case (a plain Monte Carlo estimate's):

- the ideal: every level's share exactly ``p0`` (a score that leads straight to the
  failures, the last level taking what is left) for ``p0`` of 0.1, 0.2, 0.3 and chain
  correlations ``g`` of 0 (independent samples), 1 and 3; and, per ``g``, the number of
  levels of equal share whose upper bound is largest;
- for each splitting estimate given: its levels (share, correlation, moves kept) as
  ``estimate.json`` records them, and the efficiency they give.

    python benchmarks/splitting_bound.py --monte-carlo MC_DIR SPLITTING_DIR ... \\
        --out benchmarks/results/splitting_bound_crossing_2m.json
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

P0 = (0.1, 0.2, 0.3)
CORRELATIONS = (0.0, 1.0, 3.0)


def efficiency(shares: Sequence[float], gammas: Sequence[float], p0: float, p: float) -> dict:
    """Plain Monte Carlo's episodes over splitting's, at the same relative error, per ``N``
    (it cancels): with the levels' errors added as independent and as fully correlated."""
    terms = [(1.0 - s) / s * (1.0 + g) for s, g in zip(shares, gammas, strict=True)]
    cost = 1.0 + (len(shares) - 1) * (1.0 - p0)
    monte_carlo = (1.0 - p) / p
    independent = sum(terms)
    correlated = sum(math.sqrt(t) for t in terms) ** 2
    return {
        "independent_levels": monte_carlo / (cost * independent),
        "upper_bound": monte_carlo / (cost * correlated),
    }


def ideal(p: float, p0: float, gamma: float) -> dict[str, Any]:
    """Every level's share ``p0`` but the last, which takes what is left."""
    levels = max(1, math.ceil(math.log(p) / math.log(p0) - 1e-9))
    last = p / p0 ** (levels - 1)
    shares = [p0] * (levels - 1) + [last]
    gammas = [0.0] + [gamma] * (levels - 1)
    return {"p0": p0, "gamma": gamma, "levels": levels, **efficiency(shares, gammas, p0, p)}


def best(p: float, gamma: float) -> dict[str, Any]:
    """The ideal whose upper bound is largest: ``m`` levels of the same share ``p ** (1 / m)``
    (a first level of plain Monte Carlo and ``m - 1`` more), ``m`` from 2 to 12."""
    rows = []
    for levels in range(2, 13):
        share = p ** (1.0 / levels)
        gammas = [0.0] + [gamma] * (levels - 1)
        row = efficiency([share] * levels, gammas, share, p)
        rows.append({"p0": share, "gamma": gamma, "levels": levels, **row})
    return max(rows, key=lambda row: row["upper_bound"])


def measured(directory: Path, p: float) -> dict[str, Any]:
    """A splitting estimate's levels, from its ``estimate.json`` and ``config.json``."""
    summary = json.loads((directory / "estimate.json").read_text())
    config = json.loads((directory / "config.json").read_text())
    if summary["method"] != "splitting" or not summary.get("levels"):
        raise SystemExit(f"{directory}: not a splitting estimate with its levels recorded")
    levels = summary["levels"]
    p0 = config["estimator"]["elite_share"]
    shares = [level["share"] for level in levels]
    gammas = [level["correlation"] for level in levels]
    found = shares[-1] > 0.0  # else no failure at the last level: no error to compare
    return {
        "estimate": str(directory),
        "seed": config["seed"],
        "episodes": summary["episodes"],
        "probability": summary["probability"]["probability"],
        "interval": [summary["probability"]["low"], summary["probability"]["high"]],
        "relative_error": summary["probability"]["relative_error"],
        "levels": levels,
        **(efficiency(shares, gammas, p0, p) if found else {}),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("splitting", type=Path, nargs="*", help="Splitting estimates' directories.")
    parser.add_argument(
        "--monte-carlo", type=Path, required=True, help="A plain Monte Carlo estimate's directory."
    )
    parser.add_argument("--out", type=Path)
    parser.add_argument("--note", default="", help="Recorded with the result.")
    args = parser.parse_args()
    reference = json.loads((args.monte_carlo / "estimate.json").read_text())
    if reference["method"] != "mc":
        parser.error(f"{args.monte_carlo}: a {reference['method']} estimate, not plain Monte Carlo")
    p = reference["probability"]["probability"]
    if not 0.0 < p < 1.0:
        parser.error(f"{args.monte_carlo}: probability {p}: the bound needs 0 < p < 1")
    print(f"p = {p:.3g} ({reference['scenario']}, {reference['field']}, plain Monte Carlo)")
    ideals = [ideal(p, p0, gamma) for p0 in P0 for gamma in CORRELATIONS]
    for row in ideals:
        print(
            f"ideal p0 {row['p0']:.1f}, correlation {row['gamma']:g}, {row['levels']} levels: "
            f"{row['independent_levels']:.1f}x (levels independent), "
            f"{row['upper_bound']:.1f}x (upper bound)"
        )
    bests = [best(p, gamma) for gamma in CORRELATIONS]
    for row in bests:
        print(
            f"best: {row['levels']} levels of share {row['p0']:.3f}, correlation "
            f"{row['gamma']:g}: {row['upper_bound']:.1f}x (upper bound), "
            f"{row['independent_levels']:.1f}x (levels independent)"
        )
    runs = [measured(directory, p) for directory in args.splitting]
    for run in runs:
        shown = ", ".join(
            f"{level['share']:.2f}/{level['correlation']:.1f}/"
            + ("-" if level["accepted"] is None else f"{level['accepted']:.0%}")
            for level in run["levels"]
        )
        low, high = run["interval"]
        gain = (
            f"{run['independent_levels']:.1f}x (levels independent), "
            f"{run['upper_bound']:.1f}x (upper bound)"
            if "upper_bound" in run
            else "no failure at the last level"
        )
        print(
            f"{run['estimate']}: {run['probability']:.3g} [{low:.2g}, {high:.2g}]; levels "
            f"(share/correlation/moves kept) {shown}: {gain}"
        )
    if args.out:
        result = {
            "command": " ".join([Path(sys.executable).name, *sys.argv]),
            "note": args.note,
            "date": datetime.now(UTC).isoformat(),
            "monte_carlo": {
                "estimate": str(args.monte_carlo),
                "scenario": reference["scenario"],
                "field": reference["field"],
                "episodes": reference["episodes"],
                "probability": p,
            },
            "ideal": ideals,
            "best": bests,
            "measured": runs,
        }
        args.out.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
