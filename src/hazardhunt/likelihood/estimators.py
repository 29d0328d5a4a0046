"""Failure probabilities from weighted episodes, and the proposal each estimator plays next.

Plain Monte Carlo and cross-entropy importance sampling play batches of episodes drawn from a
proposal and record each episode's exact log likelihood ratio ``log p(x) - log q(x)`` against
the model; the probability of a failure per encounter is the mean of ``w * 1[failure]`` over
the episodes counted, unbiased whatever the proposal was (each batch's proposal depends only
on the batches before it):

- ``mc``, plain Monte Carlo: the proposal is the model, every weight 1, every episode counted;
  the interval is Clopper-Pearson's (exact);
- ``ce``, cross-entropy importance sampling: the proposal moves, batch by batch, towards the
  episodes whose score (the episode's largest risk) reached a level that rises to a failure,
  and then to the failures themselves (:mod:`hazardhunt.likelihood.proposal`); the episodes
  drawn once it stopped moving are counted; the interval is log-normal on the weighted mean's
  standard error (:func:`log_normal_interval`; with no failure seen: the bound of
  :func:`zero_failure_bound`).

Multilevel splitting (:mod:`hazardhunt.likelihood.splitting`) plans its batches with the same
:class:`Planner` protocol."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any, Literal, Protocol

import numpy as np
import pandas as pd
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field
from scipy import stats

from hazardhunt.likelihood.distributions import Dimension
from hazardhunt.likelihood.encounters import Draw
from hazardhunt.likelihood.proposal import Proposal

Method = Literal["mc", "ce", "splitting"]
METHODS: tuple[Method, ...] = ("mc", "ce", "splitting")
CONFIDENCE = 0.95
"""Coverage of every interval."""
MIN_EPISODES = 100
"""The smallest budget an estimate takes: fewer give no useful interval."""
BATCH_SIZE = 200
"""Episodes per batch unless the user or a small budget says otherwise."""


class EstimatorParams(BaseModel):
    """How an estimator spends its episodes."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)

    method: Method = "mc"
    """``mc`` (plain Monte Carlo), ``ce`` (cross-entropy importance sampling) or
    ``splitting`` (multilevel splitting in the model's parameters, :mod:`.splitting`). Plain
    Monte Carlo is the default: its interval is exact whatever the failures look like, where
    the other two can miss a mechanism their proposals or chains do not reach."""
    batch_size: int = Field(default=BATCH_SIZE, ge=10, le=100_000)
    """Episodes per batch; the proposal may change between batches (``splitting``: the
    samples per level)."""
    elite_share: float = Field(default=0.1, gt=0.0, lt=1.0)
    """``ce``: the share of a batch, highest scores first, the next proposal is fitted to;
    ``splitting``: the share of a level's samples that seed the next level."""
    correlation: float = Field(default=0.8, ge=0.0, lt=1.0)
    """``splitting``: how much of a chain's state a move keeps (0: a new independent draw)."""
    smoothing: float = Field(default=0.7, gt=0.0, le=1.0)
    """``ce``: weight of a new fit against the proposal before it."""
    defensive: float = Field(default=0.1, gt=0.0, le=1.0)
    """``ce``: the model's share in every proposal (bounds each weight by 1 / defensive)."""
    fit_failures: int = Field(default=5, ge=1, le=100_000)
    """``ce``: once this many episodes so far have failed, the proposal is fitted to the
    failures alone (before, to the best ``elite_share`` of the last batch and better)."""
    adapt_share: float = Field(default=0.5, gt=0.0, lt=1.0)
    """``ce``: the largest share of the budget spent moving the proposal."""
    penalty: float = Field(default=2.0, ge=0.0, le=100.0)
    """``ce``: how much better than the model a dimension's fit must explain the elites to
    be used, in multiples of the Bayesian information criterion's price of its parameters
    (0: every dimension is fitted)."""


@dataclass(frozen=True)
class PlannedBatch:
    """The next batch an estimator plays: its draws, the columns it adds to each episode's row,
    and how it was drawn (its ``NNNNN.json``)."""

    draws: list[Draw]
    columns: dict[str, list[Any]]
    record: dict[str, Any]


class Planner(Protocol):
    """Chooses each batch from the batches played before it (so that a resumed estimate plays
    the same batches)."""

    def next_batch(self, tables: Sequence[pd.DataFrame]) -> PlannedBatch | None:
        """The next batch, or None when the estimate is complete."""
        ...


class PlannerBase:
    """What every planner is given: the estimator, the model's dimensions, the failure's
    score, the budget and the seed."""

    def __init__(
        self,
        params: EstimatorParams,
        dims: Sequence[Dimension],
        threshold: float,
        episodes: int,
        seed: int,
    ) -> None:
        self.params, self.dims, self.threshold = params, tuple(dims), threshold
        self.episodes, self.seed = episodes, seed


class SamplingPlanner(PlannerBase):
    """Plain Monte Carlo and cross-entropy importance sampling: every batch drawn from a
    proposal (:func:`next_proposal`)."""

    def next_batch(self, tables: Sequence[pd.DataFrame]) -> PlannedBatch | None:
        played = sum(len(table) for table in tables)
        if played >= self.episodes:
            return None
        schedule = next_proposal(
            self.params,
            self.dims,
            [_batch_of(table, self.dims) for table in tables],
            self.threshold,
            self.episodes,
        )
        proposal = schedule.proposal
        rng = np.random.default_rng([self.seed, len(tables)])
        count = min(self.params.batch_size, self.episodes - played)
        draws = [Draw(proposal.sample(rng), int(rng.integers(2**31))) for _ in range(count)]
        columns: dict[str, list[Any]] = {
            "log_weight": [proposal.log_weight(draw.values) for draw in draws],
            "defensive": [proposal.defensive] * count,
            "adapting": [schedule.adapting] * count,
        }
        return PlannedBatch(
            draws, columns, {"level": schedule.level, "proposal": proposal.record()}
        )


def _batch_of(table: pd.DataFrame, dims: Sequence[Dimension]) -> Batch:
    columns = table[[f"x.{dim.name}" for dim in dims]].to_numpy(float)
    values = [{dim.name: float(v) for dim, v in zip(dims, row, strict=True)} for row in columns]
    return Batch(values, table["log_weight"].to_numpy(float), table["score"].to_numpy(float))


@dataclass(frozen=True)
class Batch:
    """A played batch: what an estimator reads to choose the next proposal."""

    values: Sequence[Mapping[str, float]]
    log_weights: NDArray[np.float64]
    scores: NDArray[np.float64]
    """Each episode's score: its largest risk (a failure scores the failure threshold or more)."""


@dataclass(frozen=True)
class Schedule:
    """The proposal of the next batch, and why."""

    proposal: Proposal
    level: float | None
    """The score level the proposal was fitted to (``ce``), None for the model."""
    adapting: bool
    """Whether the proposal may still move."""


def next_proposal(
    params: EstimatorParams,
    dims: Sequence[Dimension],
    played: Sequence[Batch],
    threshold: float,
    budget: int,
) -> Schedule:
    """The proposal of the batch after ``played`` (deterministic: a resumed estimate plays
    the same proposals).

    Args:
        params: The estimator.
        dims: The model's dimensions.
        played: The batches so far, in order.
        threshold: The score at and above which an episode is a failure.
        budget: The estimate's episodes.
    """
    schedule = Schedule(Proposal.model(dims), None, params.method == "ce")
    episodes = 0
    values: list[Mapping[str, float]] = []
    log_weights: list[NDArray[np.float64]] = []
    scores: list[NDArray[np.float64]] = []
    for batch in played:
        episodes += len(batch.scores)
        values += batch.values
        log_weights.append(batch.log_weights)
        scores.append(batch.scores)
        if not schedule.adapting:
            continue
        still = episodes < params.adapt_share * budget
        level = min(threshold, float(np.quantile(batch.scores, 1.0 - params.elite_share)))
        if int(np.sum(np.concatenate(scores) >= threshold)) >= params.fit_failures:
            # Enough failures found to fit to them alone: a score that jumps at a failure (a
            # contact's risk is a hundred times a near miss's) makes the quantile rise slowly.
            level = threshold
        if level <= 0.0:  # nothing scored: the next batch looks again
            schedule = Schedule(schedule.proposal, schedule.level, still)
            continue
        # Every episode so far that reached the level, weighted by its likelihood ratio.
        elite = np.flatnonzero(np.concatenate(scores) >= level)
        weights = np.exp(np.concatenate(log_weights)[elite])
        fitted = schedule.proposal.fitted(
            [values[i] for i in elite], weights, params.smoothing, params.defensive, params.penalty
        )
        schedule = Schedule(fitted, level, still)
    return schedule


@dataclass(frozen=True)
class Estimate:
    """A probability per encounter with its interval."""

    probability: float
    low: float
    high: float
    episodes: int
    failures: int
    """Failures among the episodes (unweighted)."""
    standard_error: float
    relative_error: float | None
    """Standard error over the estimate; None when it is 0."""
    effective_sample_size: float
    """``(sum w)^2 / sum w^2`` over all episodes (the episodes count for so many of the model's)."""
    self_normalised: float
    """``sum w 1[failure] / sum w``: the estimate that needs only weights up to a constant."""
    interval: str
    """How the interval was computed."""

    def record(self) -> dict[str, Any]:
        """As JSON data."""
        return asdict(self)


def clopper_pearson(failures: int, episodes: int) -> tuple[float, float]:
    """The exact binomial interval of coverage :data:`CONFIDENCE`."""
    tail = (1.0 - CONFIDENCE) / 2.0
    low = 0.0 if failures == 0 else float(stats.beta.ppf(tail, failures, episodes - failures + 1))
    high = (
        1.0
        if failures == episodes
        else float(stats.beta.ppf(1 - tail, failures + 1, episodes - failures))
    )
    return low, high


def zero_failure_bound(defensive: NDArray[np.float64]) -> float:
    """An upper bound on the probability when no episode failed: each episode's proposal gives
    a failure at least ``defensive`` times its model probability ``p``, so seeing none has
    probability at most ``exp(-p * sum(defensive))``; the bound is the ``p`` at which that is
    the interval's tail."""
    tail = (1.0 - CONFIDENCE) / 2.0
    return min(1.0, math.log(1.0 / tail) / float(np.sum(defensive)))


def estimate(
    failed: NDArray[np.bool_],
    log_weights: NDArray[np.float64],
    defensive: NDArray[np.float64],
) -> Estimate:
    """The probability of the event ``failed`` marks, from episodes with these log likelihood
    ratios, drawn from proposals with these defensive shares.

    Raises:
        OverflowError: A weight overflows a float (the proposal is too far from the model).
    """
    failed = np.asarray(failed, dtype=bool)
    n, k = len(failed), int(failed.sum())
    with np.errstate(over="raise"):
        try:
            weights = np.exp(np.asarray(log_weights, dtype=np.float64))
        except FloatingPointError:
            worst = float(np.max(log_weights))
            raise OverflowError(f"a likelihood ratio overflows: log weight {worst:.1f}") from None
    ess = float(weights.sum() ** 2 / np.sum(weights**2)) if n else 0.0
    normalised = float(weights[failed].sum() / weights.sum()) if n else 0.0
    if np.all(log_weights == 0.0):  # plain Monte Carlo
        low, high = clopper_pearson(k, n)
        p = k / n
        se = math.sqrt(p * (1 - p) / n)
        return Estimate(
            p, low, high, n, k, se, se / p if p else None, ess, normalised, "clopper-pearson"
        )
    terms = np.where(failed, weights, 0.0)
    p = float(terms.mean())
    if k == 0:
        return Estimate(
            0.0, 0.0, zero_failure_bound(defensive), n, 0, 0.0, None, ess, 0.0, "no failure: bound"
        )
    se = float(terms.std(ddof=1) / math.sqrt(n)) if n > 1 else math.inf
    low, high = log_normal_interval(p, se / p)
    return Estimate(p, low, high, n, k, se, se / p, ess, normalised, "log-normal")


def either_of(first: Estimate, second: Estimate, episodes: int, marked: int) -> Estimate:
    """The probability of either of two events that never happen together (a failure, an
    encounter the SUT could not play), from estimates of each over the same ``episodes``
    (``marked`` of which are either): the sum of the two, and each end of the interval the sum
    of theirs. Whatever the two estimates' correlation, the upper end is exceeded with at most
    the sum of their upper tails' risks (5 % for two 95 % intervals), and so is the lower end;
    the standard error is the sum of theirs, an upper bound."""
    probability = first.probability + second.probability
    error = first.standard_error + second.standard_error
    return Estimate(
        probability,
        min(first.low + second.low, 1.0),
        min(first.high + second.high, 1.0),
        episodes,
        marked,
        error,
        error / probability if probability else None,
        math.nan,
        probability,
        f"sum of two: {first.interval}; {second.interval}",
    )


def log_normal_interval(probability: float, relative_error: float) -> tuple[float, float]:
    """The interval of coverage :data:`CONFIDENCE` of a log-normal with this mean and
    coefficient of variation: skewed upwards as an estimate of a small probability from few
    large weights is (a symmetric normal interval covers the truth less often than it says)."""
    z = float(stats.norm.ppf(0.5 + CONFIDENCE / 2.0))
    spread = math.sqrt(math.log1p(relative_error**2))
    centre = math.log(probability) - 0.5 * spread**2
    return math.exp(centre - z * spread), min(math.exp(centre + z * spread), 1.0)


def episodes_for(probability: float, relative_error: float) -> float:
    """Plain Monte Carlo's episodes for ``relative_error`` at ``probability``:
    ``(1 - p) / (p * relative_error^2)``."""
    return (1.0 - probability) / (probability * relative_error**2)
