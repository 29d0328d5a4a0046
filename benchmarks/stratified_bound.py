"""How far can stratifying on a model's discrete variables go on a case? A bound from plain
Monte Carlo's own failures.

Reads a plain Monte Carlo estimate (``hazardhunt estimate --method mc``) and, for each discrete
variable of the model (or those named), splits its episodes into strata by the variable's
value. A stratum's probability is the model's (exact); its failure rate is Monte Carlo's count
in it. Stratified sampling estimates ``p = sum_i P_i p_i``; with ``n_i`` episodes in stratum
``i``, each drawn by a sampler ``e_i`` times as efficient as plain Monte Carlo within it, its
variance is ``sum_i c_i / n_i`` with ``c_i = P_i^2 p_i (1 - p_i) / e_i``, least for ``n_i``
in proportion to ``sqrt(c_i)`` (Neyman's allocation): ``(sum_i sqrt(c_i))^2 / n``. Printed per
variable:

- the efficiency over plain Monte Carlo of plain Monte Carlo in every stratum with Neyman's
  allocation (the strata's rates known beforehand, which an estimate would have to learn);
- for each stratum, the episodes plain Monte Carlo inside it needs for its share of the error
  alone (the whole at ``--relative-error``, the other strata exact), and how much more efficient
  than plain Monte Carlo the sampler inside it would have to be, the others plain Monte Carlo,
  for the whole to need ``--ratio`` times fewer episodes than plain Monte Carlo at
  ``--relative-error`` (``impossible``: not even a sampler of no variance there would do: the
  other strata's own plain Monte Carlo takes more; a stratum without a failure has nothing to
  gain).

The rates come from the failures Monte Carlo saw: a stratum with one failure has a rate known
to within a factor of several, and so has everything computed from it.

    python benchmarks/stratified_bound.py ESTIMATE_DIR \\
        --out benchmarks/results/stratified_bound_crossing_2m.json
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

import pandas as pd

from hazardhunt.likelihood.run import encounters_of

sys.path.insert(0, str(Path(__file__).resolve().parent))
from proposal_bound import monte_carlo_table, result_header


def strata(table: pd.DataFrame, name: str, pmf: dict[float, float]) -> list[dict[str, Any]]:
    """Each value of the variable ``name``: its model probability, episodes, failures, rate."""
    rows = []
    for value, probability in sorted(pmf.items()):
        inside = table[table[f"x.{name}"] == value]
        failures = int(inside["failure"].sum())
        rows.append(
            {
                "value": value,
                "probability": probability,
                "episodes": len(inside),
                "failures": failures,
                "rate": failures / len(inside) if len(inside) else 0.0,
            }
        )
    return rows


def bound(rows: list[dict[str, Any]], p: float, error: float, ratio: float) -> dict[str, Any]:
    """Neyman's plain stratified efficiency, and the least efficiency inside each stratum that
    gives ``ratio`` times plain Monte Carlo at relative error ``error``."""
    costs = [r["probability"] ** 2 * r["rate"] * (1.0 - r["rate"]) for r in rows]
    monte_carlo = (1.0 - p) / (p * error**2)
    allowed = monte_carlo / ratio
    variance = (error * p) ** 2
    neyman = sum(math.sqrt(c) for c in costs) ** 2 / variance
    needed = []
    for i, row in enumerate(rows):
        rest = sum(math.sqrt(c) for j, c in enumerate(costs) if j != i)
        room = math.sqrt(variance * allowed) - rest
        need: float | str
        if costs[i] == 0.0:
            need = "no failure seen in it: a better sampler there gains nothing"
        elif room <= 0.0:
            need = "impossible: the other strata's plain Monte Carlo alone takes more"
        else:
            need = costs[i] / room**2
        needed.append(
            {
                "value": row["value"],
                "efficiency_needed": need,
                "episodes_for_its_share": costs[i] / variance,
            }
        )
    return {
        "monte_carlo_episodes": monte_carlo,
        "episodes_allowed": allowed,
        "neyman_episodes": neyman,
        "neyman_efficiency": monte_carlo / neyman if neyman else math.inf,
        "needed": needed,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("estimate", type=Path, help="A plain Monte Carlo estimate's directory.")
    parser.add_argument("--out", type=Path)
    parser.add_argument("--note", default="", help="Recorded with the result.")
    parser.add_argument("--variables", nargs="*", help="Discrete variables (default: every one).")
    parser.add_argument("--relative-error", type=float, default=0.3)
    parser.add_argument("--ratio", type=float, default=10.0)
    args = parser.parse_args()
    config, table = monte_carlo_table(parser, args.estimate)
    p = float(table["failure"].mean())
    if p == 0.0:
        parser.error(f"{args.estimate}: no failure; nothing to stratify")
    dims = {d.name: d for d in encounters_of(config).dimensions if d.discrete}
    names = args.variables or list(dims)
    if unknown := [n for n in names if n not in dims]:
        parser.error(f"not a discrete variable of the model: {', '.join(unknown)}")
    print(f"{len(table)} episodes, {int(table['failure'].sum())} failures, p = {p:.3g}")
    results = {}
    for name in names:
        dim = dims[name]
        pmf = {float(v): float(dim.distribution.pmf(v)) for v in dim.support}
        rows = strata(table, name, pmf)
        found = bound(rows, p, args.relative_error, args.ratio)
        results[name] = {"strata": rows, **found}
        print(
            f"{name}: plain Monte Carlo per stratum, Neyman's allocation "
            f"{found['neyman_efficiency']:.1f}x; {args.ratio:g}x needs "
            f"{found['episodes_allowed']:.0f} episodes"
        )
        for row, need in zip(rows, found["needed"], strict=True):
            wanted = need["efficiency_needed"]
            said = wanted if isinstance(wanted, str) else f"{wanted:.1f}x"
            print(
                f"  {name} = {row['value']:g}: probability {row['probability']:.3g}, "
                f"{row['failures']} failures in {row['episodes']} episodes; plain Monte Carlo "
                f"inside it needs {need['episodes_for_its_share']:.0f} episodes for its share "
                f"of the error alone; a sampler inside it for {args.ratio:g}x: {said}"
            )
    if args.out:
        result = {
            **result_header(args.note, config, table),
            "relative_error": args.relative_error,
            "ratio": args.ratio,
            "variables": results,
        }
        args.out.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
