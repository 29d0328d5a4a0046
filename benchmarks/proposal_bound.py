"""How far can importance sampling over a model's tilts go on a case? A bound from plain Monte
Carlo's own failures.

Reads a plain Monte Carlo estimate (``hazardhunt estimate --method mc``: every episode a draw
from the model), fits the cross-entropy estimator's proposal
(:mod:`hazardhunt.likelihood.proposal`, with and without its penalty) to its failures, and a
mixture of one such proposal per failure class (which the estimator does not have: what
proposals per mechanism would gain), and reports the efficiency over plain
Monte Carlo per counted episode that each proposal would give, ``(1 - p) / (E_p[w | failure]
- p)`` with ``w`` the failure's likelihood ratio (the estimator's variance is ``p E_p[w |
failure] - p^2`` per episode, plain Monte Carlo's ``p (1 - p)``):

- *in-sample*: fitted to every failure, each weighed by that proposal (an upper bound: the
  proposal has seen every mechanism there is);
- *leave-one-out*: each failure weighed by the proposal fitted to the others (a mechanism
  seen once is one the proposal has not seen).

The efficiency an estimate reaches is lower still: its proposal is fitted to the few
failures its own adaptation finds, and those episodes are spent, not counted.

    python benchmarks/proposal_bound.py ESTIMATE_DIR \\
        --out benchmarks/results/proposal_bound_crossing_2m.json
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

import numpy as np
import pandas as pd

from hazardhunt.likelihood.distributions import Dimension
from hazardhunt.likelihood.estimators import EstimatorParams
from hazardhunt.likelihood.proposal import Proposal
from hazardhunt.likelihood.run import (
    EstimateConfig,
    encounters_of,
    load_config,
    played_batches,
)


def monte_carlo_table(
    parser: argparse.ArgumentParser, directory: Path
) -> tuple[EstimateConfig, pd.DataFrame]:
    """The configuration of the plain Monte Carlo estimate in ``directory`` and its episodes
    that tested something (no SUT error); a usage error through ``parser`` for an estimate of
    another method."""
    config = load_config(directory)
    if config.estimator.method != "mc":
        parser.error(f"{directory}: a {config.estimator.method} estimate, not plain Monte Carlo")
    table = pd.concat(played_batches(directory))
    return config, table[~table["sut_error"]]


def result_header(note: str, config: EstimateConfig, table: pd.DataFrame) -> dict[str, Any]:
    """What a bound's result file opens with: how it was made, and the estimate it read."""
    return {
        "command": " ".join([Path(sys.executable).name, *sys.argv]),
        "note": note,
        "date": datetime.now(UTC).isoformat(),
        "scenario": config.scenario,
        "field": config.field,
        "episodes": len(table),
        "failures": int(table["failure"].sum()),
        "probability": float(table["failure"].mean()),
    }


def efficiency(weights: list[float], p: float) -> float:
    """Plain Monte Carlo's variance over the estimator's, per episode."""
    return (1.0 - p) / max(float(np.mean(weights)) - p, 1e-300)


def _fitted(
    dims: Sequence[Dimension],
    elites: list[dict[str, float]],
    classes: list[str],
    family: str,
    penalty: float,
    defensive: float,
) -> list[tuple[float, Proposal]]:
    """The proposal fitted to ``elites`` as (share, tilts) pairs: the estimator's one proposal,
    or one per failure class, each with its class's share of the elites."""
    groups = (
        [elites]
        if family == "one"
        else [
            [e for e, c in zip(elites, classes, strict=True) if c == name]
            for name in sorted(set(classes))
        ]
    )
    return [
        (
            len(group) / len(elites),
            Proposal.model(dims).fitted(group, np.ones(len(group)), 1.0, defensive, penalty),
        )
        for group in groups
    ]


def _weight(mixture: list[tuple[float, Proposal]], x: dict[str, float], defensive: float) -> float:
    """The likelihood ratio of ``x`` under the mixture, with the model's ``defensive`` share."""
    tilt = sum(share * math.exp(proposal.log_ratio(x)) for share, proposal in mixture)
    return 1.0 / (defensive + (1.0 - defensive) * tilt)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("estimate", type=Path, help="A plain Monte Carlo estimate's directory.")
    parser.add_argument("--out", type=Path)
    parser.add_argument("--note", default="", help="Recorded with the result.")
    args = parser.parse_args()
    config, table = monte_carlo_table(parser, args.estimate)
    dims = encounters_of(config).dimensions
    failures = [
        {dim.name: float(row[f"x.{dim.name}"]) for dim in dims}
        for _, row in table[table["failure"]].iterrows()
    ]
    p = len(failures) / len(table)
    if len(failures) < 3:
        parser.error(f"{args.estimate}: {len(failures)} failures; the bound needs at least 3")
    classes = table.loc[table["failure"], "failure_class"].tolist()
    defaults = EstimatorParams()
    rows = []
    for family in ("one", "per class"):
        for penalty in (0.0, defaults.penalty):

            def fitted(train: list[int], family: str = family, penalty: float = penalty):
                elites = [failures[i] for i in train]
                names = [classes[i] for i in train]
                return _fitted(dims, elites, names, family, penalty, defaults.defensive)

            everyone = fitted(list(range(len(failures))))
            in_sample = [_weight(everyone, f, defaults.defensive) for f in failures]
            left_out = [
                _weight(fitted([j for j in range(len(failures)) if j != i]), f, defaults.defensive)
                for i, f in enumerate(failures)
            ]
            row = {
                "proposal": family,
                "penalty": penalty,
                "in_sample": efficiency(in_sample, p),
                "leave_one_out": efficiency(left_out, p),
                "in_sample_weights": in_sample,
                "leave_one_out_weights": left_out,
            }
            rows.append(row)
            print(
                f"{family:9s} penalty {penalty:g}: in-sample {row['in_sample']:.1f}x, "
                f"leave-one-out {row['leave_one_out']:.1f}x (largest weight left out "
                f"{max(left_out):.2f})",
                flush=True,
            )
    if args.out:
        result = {
            **result_header(args.note, config, table),
            "failure_classes": table.loc[table["failure"], "failure_class"].tolist(),
            "defensive": defaults.defensive,
            "fits": rows,
        }
        args.out.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
