"""What an estimate found: the probability of a failure per encounter, overall and per class,
how it converged, the most likely failures, and what plain Monte Carlo would have needed.

Everything here is computed from the episode table alone (each episode's failure, class, log
likelihood and log likelihood ratio), so an estimate is recomputed from stored results.

An episode that ended in a SUT error tested nothing: the estimate and its interval are over the
tested episodes alone, and ``untested`` says what the others leave open (:data:`LEFT_OUT`).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from pydantic import TypeAdapter, ValidationError
from typing_extensions import NotRequired, TypedDict  # which pydantic validates on Python 3.11

from hazardhunt.file_writes import file_written
from hazardhunt.likelihood.estimators import Estimate, either_of, episodes_for, estimate
from hazardhunt.likelihood.people import DEFAULT_MODEL, ModelError
from hazardhunt.likelihood.run import (
    EstimateConfig,
    EstimateError,
    first_sut_error,
    nothing_tested,
)
from hazardhunt.likelihood.splitting import (
    SplittingPlanner,
    level_records,
    splitting_estimate,
    untested_share,
)
from hazardhunt.textfiles import format_validation_error

TARGET_RELATIVE_ERROR = 0.3
"""The relative error the comparison with plain Monte Carlo is stated at."""
CAVEATS = {
    "ce": "importance sampling: the estimate and its interval cover the ways of failing its "
    "episodes found; one its proposal seldom draws is mostly missing from both (docs/risk.md, "
    "'How far one proposal can go'). Compare with plain Monte Carlo (--method mc) before "
    "relying on it.",
    "splitting": "splitting: the levels' chains explore from the episodes that seeded them; a "
    "way of failing that none of them reaches is missing from the estimate (docs/risk.md). "
    "Compare with plain Monte Carlo (--method mc) before relying on it.",
}
"""What an estimator's interval does not cover, said beside its estimate (plain Monte Carlo's
interval is exact: nothing to say)."""
LEFT_OUT = {
    "mc": "plain Monte Carlo over the tested episodes estimates the probability of a failure "
    "among the encounters the SUT plays: per encounter if its errors have nothing to do with "
    "the encounter, and within the range above whatever they do.",
    "ce": "importance sampling over the tested episodes, each weighted by its likelihood ratio, "
    "is unbiased only if the SUT's errors have nothing to do with the encounter drawn; where "
    "they do (errors where the proposal looks, say), the estimate can be off either way and "
    "the method has no correction for it: rely on the range above, or mend the SUT.",
    "splitting": "splitting takes each level's share over its tested samples: the probability "
    "of a failure among the encounters the SUT plays (per encounter if its errors have nothing "
    "to do with the encounter). The levels after the first follow high scores, which an "
    "encounter the SUT could not play may never reach, so the range above adds the probability "
    "of such an encounter, from the first level (plain Monte Carlo), to that of a failure.",
}
"""How each method leaves out the episodes that ended in a SUT error, and what that assumes."""
CHAIN_ERRORS = (
    " {errors:,} samples of the levels beyond the first ended in a SUT error: the correlation "
    "along the chains, which widens the interval, counts them as misses, which Au and Beck's "
    "interval has no correction for; compare with plain Monte Carlo (--method mc)."
)
"""Said besides :data:`LEFT_OUT` when a splitting chain's samples erred."""
NOTES = ("caveat", "levels_warning")
"""The keys of ``estimate.json`` that hold what to say beside the estimate (None: nothing)."""
STUCK_CHAINS = 0.1
"""A splitting level whose chains kept fewer of their moves than this is said to have mostly
stood still."""


def summarise(config: EstimateConfig, table: pd.DataFrame, threshold: float) -> dict[str, Any]:
    """The estimate of ``table``'s episodes, as ``estimate.json`` holds it; ``threshold`` is the
    score of a failure (the encounters' ``threshold``). The probability, its interval, the
    classes' and the convergence are over the episodes the SUT played.

    Raises:
        EstimateError: No episode the estimate counts was tested (each ended in a SUT error),
            every sample of a splitting level did, or a weight overflows.
        ModelError: An episode's log-likelihood under the model is not finite.
    """
    untested = nothing_tested(config, table)
    if untested is not None:
        raise EstimateError(untested)
    _check_likelihoods(config, table)
    classes_found = sorted(set(table.loc[table["failure"], "failure_class"]))
    if config.estimator.method == "splitting":
        overall, classes, points, counted = _splitting(config, table, classes_found, threshold)
    else:
        overall, classes, points, counted = _weighted(table, classes_found)
    levels = _levels(config, table, threshold)
    errors = int(table["sut_error"].sum())
    return {
        "scenario": config.scenario,
        "field": config.field,
        "method": config.estimator.method,
        "episodes": len(table),
        "episodes_counted": counted,
        "episodes_tested": len(table) - errors,
        "sut_errors": errors,
        "first_sut_error": first_sut_error(table),
        "probability": overall.record(),
        "untested": _untested(config, table, threshold, levels) if errors else None,
        "classes": classes,
        "monte_carlo_equivalent": monte_carlo_equivalent(overall, len(table)),
        "caveat": CAVEATS.get(config.estimator.method),
        "convergence": points,
        "levels": levels,
        "levels_warning": _stuck(levels, table),
        "most_likely": most_likely(table),
    }


def _check_likelihoods(config: EstimateConfig, table: pd.DataFrame) -> None:
    """Raises ModelError if an episode's log-likelihood under the model is not finite (a
    batch played before such a draw was refused): no estimate is given from it."""
    log_p = table["log_p"].to_numpy(float)
    bad = ~np.isfinite(log_p)
    if bad.any():
        first = int(np.argmax(bad))
        raise ModelError(
            f"people model {config.people or DEFAULT_MODEL}: log_prob is {log_p[first]} on "
            f"the draw of episode {int(table['episode'].iloc[first])}: no estimate is given "
            "from a likelihood that is not a number; mend the model and estimate anew"
        )


def _untested(
    config: EstimateConfig, table: pd.DataFrame, threshold: float, levels: Any
) -> dict[str, Any]:
    """What the episodes that ended in a SUT error leave open: how likely such an encounter
    is, and the probability of a failure with them counted as safe (the low end of where it
    lies, whatever they would have done) and as failures (the high end), by the estimate's
    method; and what leaving them out assumes."""
    errored = table["sut_error"].to_numpy(bool)
    failed = table["failure"].to_numpy(bool)
    note = LEFT_OUT[config.estimator.method]
    in_chains = sum(level["sut_errors"] for level in (levels or [])[1:])
    if in_chains:
        note += CHAIN_ERRORS.format(errors=in_chains)
    failure_and_tested = _event(config, table, failed, threshold)
    if config.estimator.method == "splitting":
        # The levels follow high scores, which an encounter the SUT could not play may never
        # reach: its probability is the first level's, added to the failures'.
        untested = untested_share(_splitting_planner(config, threshold), table)
        marked = int((failed | errored).sum())
        either = either_of(failure_and_tested, untested, len(table), marked)
    else:
        untested = _event(config, table, errored, threshold)
        either = _event(config, table, failed | errored, threshold)
    return {
        "probability": untested.record(),
        "failure_and_tested": failure_and_tested.record(),
        "failure_or_untested": either.record(),
        "note": note,
    }


def _levels(config: EstimateConfig, table: pd.DataFrame, threshold: float) -> Any:
    """Multilevel splitting's levels, to see how its chains went (None for the others)."""
    if config.estimator.method != "splitting":
        return None
    planner = _splitting_planner(config, threshold)
    try:
        records, _ = level_records(planner, table, table["failure"].to_numpy(bool))
    except ValueError as error:
        raise EstimateError(f"splitting: {error}: no probability can be given") from None
    return [asdict(record) for record in records]


def _splitting_planner(config: EstimateConfig, threshold: float) -> SplittingPlanner:
    """The planner that recomputes a splitting estimate's levels from its stored scores (it
    needs no model: it plans no batch here)."""
    return SplittingPlanner(config.estimator, (), threshold, config.episodes, config.seed)


def _stuck(levels: list[dict[str, Any]] | None, table: pd.DataFrame) -> str | None:
    """What to say of splitting levels whose chains mostly stood still (None if none did)."""
    stuck = [
        (index, level["accepted"])
        for index, level in enumerate(levels or [])
        if level["accepted"] is not None and level["accepted"] < STUCK_CHAINS
    ]
    if not stuck:
        return None
    shown = ", ".join(f"level {index} kept {accepted:.0%}" for index, accepted in stuck)
    distinct = int(table["failure"].sum())
    return (
        f"splitting: the chains mostly stood still ({shown} of their moves), so the levels' "
        f"shares rest on few distinct episodes ({distinct} distinct "
        f"failure{'' if distinct == 1 else 's'}) and neither the estimate nor its interval "
        "can be relied on, nor what plain Monte Carlo would need for its error; more "
        "episodes per level (--batch-size) give the chains more starts (docs/risk.md, 'How "
        "far splitting can go')."
    )


def _weighted(
    table: pd.DataFrame, classes_found: list[str]
) -> tuple[Estimate, dict[str, Any], list[dict[str, float]], int]:
    """Monte Carlo and importance sampling: the weighted mean over the episodes drawn once the
    proposal stopped moving that the SUT played (each keeps its weight: the ones that ended in
    a SUT error are left out, :data:`LEFT_OUT`)."""
    counted = table[~table["adapting"]]
    if counted.empty:
        raise EstimateError(
            "every batch was spent moving the proposal; give more episodes (or a larger "
            "adapt_share) so that some are drawn from the final one"
        )
    tested = counted[~counted["sut_error"]]
    failed = tested["failure"].to_numpy(bool)
    log_w = tested["log_weight"].to_numpy(float)
    defensive = tested["defensive"].to_numpy(float)
    try:
        overall = estimate(failed, log_w, defensive)
        classes = {
            name: estimate(tested["failure_class"].to_numpy() == name, log_w, defensive).record()
            for name in classes_found
        }
    except OverflowError as error:
        raise EstimateError(f"the estimate cannot be computed: {error}") from None
    return overall, classes, convergence(table), len(counted)


def _event(
    config: EstimateConfig, table: pd.DataFrame, event: np.ndarray, threshold: float
) -> Estimate:
    """The probability of the episodes ``event`` marks, by the estimate's own method, over
    every episode it counts (those that ended in a SUT error too)."""
    if config.estimator.method == "splitting":
        planner = _splitting_planner(config, threshold)
        return splitting_estimate(planner, table, event, tested_only=False)[0]
    counted = ~table["adapting"].to_numpy(bool)
    try:
        return estimate(
            event[counted],
            table["log_weight"].to_numpy(float)[counted],
            table["defensive"].to_numpy(float)[counted],
        )
    except OverflowError as error:
        raise EstimateError(f"the estimate cannot be computed: {error}") from None


def _splitting(
    config: EstimateConfig, table: pd.DataFrame, classes_found: list[str], threshold: float
) -> tuple[Estimate, dict[str, Any], list[dict[str, float]], int]:
    """Multilevel splitting: the product of the levels' shares (over their tested samples)."""
    planner = _splitting_planner(config, threshold)
    failed = table["failure"].to_numpy(bool)
    try:
        overall, progress = splitting_estimate(planner, table, failed)
    except ValueError as error:
        raise EstimateError(f"splitting: {error}: no probability can be given") from None
    classes = {
        name: splitting_estimate(planner, table, table["failure_class"].to_numpy() == name)[
            0
        ].record()
        for name in classes_found
    }
    points = []
    for level in range(1, len(progress.levels) + 1):
        end = planner.per_level + (level - 1) * planner.chains * planner.moves
        part = table.iloc[:end]
        try:
            result, _ = splitting_estimate(planner, part, part["failure"].to_numpy(bool))
        except ValueError:  # a level of it with no tested sample
            continue
        points.append(
            {
                "episodes": float(end),
                "probability": result.probability,
                "low": result.low,
                "high": result.high,
            }
        )
    return overall, classes, points, len(table)


def monte_carlo_equivalent(result: Estimate, spent: int) -> dict[str, Any] | None:
    """How many episodes plain Monte Carlo would need for this estimate's relative error (and
    how many times the ``spent`` episodes, those that moved the proposal included), and for
    :data:`TARGET_RELATIVE_ERROR`, at the estimated probability."""
    p, relative = result.probability, result.relative_error
    if p <= 0.0 or relative is None or relative <= 0.0:
        return None
    same = episodes_for(p, relative)
    return {
        "relative_error": relative,
        "episodes_for_same_error": same,
        "ratio": same / spent,
        "episodes_for_target": episodes_for(p, TARGET_RELATIVE_ERROR),
        "target_relative_error": TARGET_RELATIVE_ERROR,
    }


def convergence(table: pd.DataFrame) -> list[dict[str, float]]:
    """The estimate after each batch: episodes (played), probability, interval (over the
    tested episodes)."""
    points = []
    counted = table[~table["adapting"] & ~table["sut_error"]]
    for batch in sorted(set(counted["batch"])):
        part = counted[counted["batch"] <= batch]
        try:
            result = estimate(
                part["failure"].to_numpy(bool),
                part["log_weight"].to_numpy(float),
                part["defensive"].to_numpy(float),
            )
        except OverflowError:
            continue
        points.append(
            {
                "episodes": float(int(table.loc[table["batch"] <= batch].shape[0])),
                "probability": result.probability,
                "low": result.low,
                "high": result.high,
            }
        )
    return points


def most_likely(table: pd.DataFrame) -> dict[str, Any]:
    """The failure of highest likelihood under the model, overall and per class: its episode,
    class and log-likelihood (replayable from its row)."""
    failures = table[table["failure"]]
    if failures.empty:
        return {}
    found: dict[str, Any] = {}
    for name, group in [("all", failures), *failures.groupby("failure_class")]:
        row = group.loc[group["log_p"].idxmax()]
        found[str(name)] = {
            "episode": int(row["episode"]),
            "failure_class": str(row["failure_class"]),
            "log_p": float(row["log_p"]),
        }
    return found


def write_summary(directory: Path, summary: dict[str, Any]) -> Path:
    """Write ``estimate.json`` (renamed into place once complete)."""
    path = directory / "estimate.json"
    partial = path.with_suffix(".json.partial")
    with file_written(partial, named=path):
        partial.write_text(json.dumps(_finite(summary), indent=1) + "\n")
        partial.replace(path)
    return path


def _finite(value: Any) -> Any:
    """JSON has no infinities: they become None."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_finite(v) for v in value]
    if isinstance(value, np.generic):
        return _finite(value.item())
    return value


class _Probability(TypedDict):
    probability: float
    low: float
    high: float
    failures: int
    interval: str
    episodes: NotRequired[int]


class _ConvergencePoint(TypedDict):
    episodes: float
    probability: float | None
    low: float | None
    high: float | None


class _Likeliest(TypedDict):
    episode: int
    log_p: float


class _MonteCarloEquivalent(TypedDict):
    relative_error: float
    episodes_for_same_error: float
    ratio: float
    episodes_for_target: float
    target_relative_error: float


class _EstimateRecord(TypedDict):
    """What a report reads of ``estimate.json`` (:func:`summarise` writes more)."""

    method: str
    episodes: int
    probability: _Probability
    classes: dict[str, _Probability]
    convergence: list[_ConvergencePoint]
    sut_errors: NotRequired[int]
    most_likely: NotRequired[dict[str, _Likeliest] | None]
    monte_carlo_equivalent: NotRequired[_MonteCarloEquivalent | None]
    caveat: NotRequired[str | None]
    levels_warning: NotRequired[str | None]
    untested: NotRequired[dict[str, Any] | None]


_ESTIMATE_RECORD = TypeAdapter(_EstimateRecord)


def estimate_record_problem(stored: object) -> str | None:
    """What is wrong with ``stored`` as an estimate's ``estimate.json`` (``key: problem``), or
    None: a key a report reads is missing or holds a value of another type than
    :func:`summarise` writes. An estimate received from anyone is read as data."""
    try:
        _ESTIMATE_RECORD.validate_python(stored, strict=True)
    except ValidationError as error:
        return format_validation_error(error)
    return None
