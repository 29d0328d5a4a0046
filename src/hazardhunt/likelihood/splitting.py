"""Multilevel splitting in the model's parameters: subset simulation (Au and Beck 2001).

A rare failure is reached through levels of the episode's score (its largest risk): the first
level is plain Monte Carlo; the share ``p0`` of its episodes with the highest scores seeds
Markov chains that explore, conditioned on reaching that score, the next level; and so on until
the share ``p0`` of a level fails. The probability is the product of the levels' shares:

    P(failure) = P(score >= l_1) * P(score >= l_2 | score >= l_1) * ... * P(failure | score >= l_m)

The chains move in the model's standard-normal coordinates (each dimension's quantile ``u``
as ``z = Phi^-1(u)``; a discrete dimension's value is its quantile function at ``u``), by the
preconditioned Crank-Nicolson step ``z' = rho z + sqrt(1 - rho^2) xi``, which leaves the model
unchanged; a move is kept when its episode reaches the level. Each move is one episode; a
batch is one move of every chain. The interval is the log-normal one on the coefficient of
variation of Au and Beck (their eq. 27-29: the levels' binomial variances, inflated by the
correlation along each chain), taken at its upper bound (the levels' coefficients added, as if
fully correlated): conservative where the root of their sum of squares covered the truth in
only 92-93 % of repetitions (benchmarks/estimate_coverage.py).

The draw of every episode (its values and noise seed) is stored like any other's, so a
failure replays from its row; the levels are recomputed from the stored scores.

An episode that ended in a SUT error tested nothing. A chain's move to one is kept only if its
score (the risk before the error) reached the level, as any move is; each level's share is
taken over its tested samples alone, so that the product is the probability of a failure
among the encounters the SUT plays: ``P(score >= l_1 | tested) * P(score >= l_2 | score >= l_1,
tested) * ...``. The correlation along the chains is still measured with such samples as
misses; a level beyond the first that holds some says so (``sut_errors`` of its record).
How likely such an encounter is comes from the first level alone (:func:`untested_share`).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray
from scipy import stats

from hazardhunt.likelihood.distributions import Dimension
from hazardhunt.likelihood.encounters import Draw
from hazardhunt.likelihood.estimators import (
    Estimate,
    EstimatorParams,
    PlannedBatch,
    PlannerBase,
    estimate,
    log_normal_interval,
)

EDGE = 1e-12
"""Quantiles are kept this far inside (0, 1)."""


def values_at(dims: Sequence[Dimension], z: NDArray[np.float64]) -> dict[str, float]:
    """The model's values at standard-normal coordinates ``z``."""
    u = np.clip(stats.norm.cdf(z), EDGE, 1.0 - EDGE)
    return {dim.name: float(dim.distribution.ppf(q)) for dim, q in zip(dims, u, strict=True)}


@dataclass
class Level:
    """The samples of one level: each chain's states, in order."""

    threshold: float
    """The score every sample of the level reached (-inf for the first)."""
    states: list[list[int]]
    """Per chain, the row of each of its states (a rejected move repeats the row)."""

    def rows(self) -> list[int]:
        return [row for chain in self.states for row in chain]


@dataclass
class Progress:
    """Where a splitting estimate stands, recomputed from its played episodes."""

    levels: list[Level]
    next_threshold: float | None
    """The level the running chains must reach; None before the first level is complete."""
    done: bool
    converged: bool
    """The last level's share of failures reached ``p0`` (else the budget ran out first)."""


class SplittingPlanner(PlannerBase):
    """Plays the levels of subset simulation."""

    def __init__(
        self,
        params: EstimatorParams,
        dims: Sequence[Dimension],
        threshold: float,
        episodes: int,
        seed: int,
    ) -> None:
        super().__init__(params, dims, threshold, episodes, seed)
        self.per_level = params.batch_size
        self.chains = max(1, round(params.batch_size * params.elite_share))
        self.moves = max(1, math.ceil(params.batch_size / self.chains) - 1)
        """Moves of each chain per level: a level has chains * (moves + 1) samples."""

    def progress(self, table: pd.DataFrame) -> Progress:
        """The levels of the episodes played so far (``table``, in order)."""
        scores = table["score"].to_numpy(float) if len(table) else np.zeros(0)
        if len(table) < self.per_level:
            return Progress([], None, False, False)
        levels = [Level(-math.inf, [[row] for row in range(self.per_level)])]
        row = self.per_level
        while True:
            level = levels[-1]
            rows = level.rows()
            ranked = sorted(rows, key=lambda r: -scores[r])
            cut = min(float(scores[ranked[self.chains - 1]]), self.threshold)
            if float(np.mean(scores[rows] >= self.threshold)) >= self.params.elite_share:
                return Progress(levels, None, True, True)
            if row + self.chains * self.moves > self.episodes or cut <= level.threshold:
                # No budget for another level, or the scores stopped rising.
                return Progress(levels, None, True, False)
            states = [[r] for r in ranked[: self.chains]]
            for _ in range(self.moves):
                if row + self.chains > len(table):
                    return Progress([*levels, Level(cut, states)], cut, False, False)
                for chain, proposed in zip(states, range(row, row + self.chains), strict=True):
                    chain.append(proposed if scores[proposed] >= cut else chain[-1])
                row += self.chains
            levels.append(Level(cut, states))

    def next_batch(self, tables: Sequence[pd.DataFrame]) -> PlannedBatch | None:
        table = pd.concat(tables, ignore_index=True) if tables else pd.DataFrame()
        rng = np.random.default_rng([self.seed, len(tables)])
        names = [dim.name for dim in self.dims]
        if len(table) < self.per_level:  # the first level: plain Monte Carlo
            z = rng.standard_normal((self.per_level, len(self.dims)))
            return self._batch(z, rng, level=0, chains=[-1] * self.per_level, threshold=None)
        state = self.progress(table)
        if state.done:
            return None
        current = state.levels[-1]
        z_now = table[[f"z.{name}" for name in names]].to_numpy(float)
        rho = self.params.correlation
        starts = np.array([z_now[chain[-1]] for chain in current.states])
        moved = rho * starts + math.sqrt(1.0 - rho * rho) * rng.standard_normal(starts.shape)
        return self._batch(
            moved,
            rng,
            level=len(state.levels) - 1,
            chains=list(range(len(current.states))),
            threshold=state.next_threshold,
        )

    def _batch(
        self,
        z: NDArray[np.float64],
        rng: np.random.Generator,
        level: int,
        chains: list[int],
        threshold: float | None,
    ) -> PlannedBatch:
        draws = [Draw(values_at(self.dims, row), int(rng.integers(2**31))) for row in z]
        columns: dict[str, list[Any]] = {
            **{f"z.{dim.name}": z[:, i].tolist() for i, dim in enumerate(self.dims)},
            "level": [level] * len(draws),
            "chain": chains,
        }
        return PlannedBatch(draws, columns, {"level": level, "threshold": threshold})


@dataclass(frozen=True)
class LevelRecord:
    """How one level of a splitting estimate went (``levels`` in ``estimate.json``)."""

    threshold: float
    """The score every sample of the level reached (-inf for the first)."""
    samples: int
    share: float
    """The share of the level's samples that reached the next level (the last level's:
    that the event marks)."""
    correlation: float
    """Au and Beck's ``gamma``: how much the correlation along the chains inflates the
    share's variance (0: independent samples; 0 for the first level, plain Monte Carlo)."""
    accepted: float | None
    """The share of the chains' moves that reached the level and were kept (None for the
    first level). Few: the chains mostly stand still, and ``correlation`` is large."""
    sut_errors: int = 0
    """The level's samples that ended in a SUT error, left out of ``samples`` and ``share``."""

    @property
    def squared_cv(self) -> float:
        """The share's squared coefficient of variation (Au and Beck, eq. 28)."""
        return (1.0 - self.share) / (self.samples * self.share) * (1.0 + self.correlation)


def level_records(
    planner: SplittingPlanner,
    table: pd.DataFrame,
    event: NDArray[np.bool_],
    tested_only: bool = True,
) -> tuple[list[LevelRecord], Progress]:
    """The levels of a splitting estimate's episodes (``table``, in order); the last level's
    share is that of the episodes ``event`` marks, each level's over its samples that did not
    end in a SUT error (``tested_only``; else over all of them). The records end at the first
    level of share 0 (none of its samples reached the next level, or, the last, was marked).

    Raises:
        ValueError: The first level is not complete, or every sample of a level ended in a
            SUT error.
    """
    state = planner.progress(table)
    scores = table["score"].to_numpy(float)
    erred = table["sut_error"].to_numpy(bool) & tested_only
    if not state.levels:
        raise ValueError("the first level is not complete")
    records = []
    for index, level in enumerate(state.levels):
        if index == len(state.levels) - 1:
            marks = [[bool(event[r]) for r in chain] for chain in level.states]
        else:
            cut = state.levels[index + 1].threshold
            marks = [[bool(scores[r] >= cut) for r in chain] for chain in level.states]
        rows = level.rows()
        tested = [m for m, r in zip(itertools.chain(*marks), rows, strict=True) if not erred[r]]
        if not tested:
            raise ValueError(
                f"every one of the {len(rows)} samples of level {index} ended in a SUT error"
            )
        share = float(np.mean(tested))
        samples = len(tested)
        accepted = None
        if index > 0:
            moves = [(a, b) for chain in level.states for a, b in itertools.pairwise(chain)]
            accepted = float(np.mean([a != b for a, b in moves])) if moves else None
        gamma = 0.0 if index == 0 or share <= 0.0 else _chain_correlation(marks, share)
        errors = len(rows) - samples
        records.append(LevelRecord(level.threshold, samples, share, gamma, accepted, errors))
        if share <= 0.0:
            break
    return records, state


def splitting_estimate(
    planner: SplittingPlanner,
    table: pd.DataFrame,
    event: NDArray[np.bool_],
    tested_only: bool = True,
) -> tuple[Estimate, Progress]:
    """The probability of ``event`` (a mark per row: failures, or failures of one class) from a
    splitting estimate's episodes, with the log-normal interval on Au and Beck's coefficient of
    variation: among the encounters the SUT played (``tested_only``, :func:`level_records`),
    or among all.

    Raises:
        ValueError: The first level is not complete, or every sample of a level ended in a
            SUT error.
    """
    records, state = level_records(planner, table, event, tested_only)
    episodes = int((~(table["sut_error"].to_numpy(bool) & tested_only)).sum())
    failures = int(table["failure"].sum())
    if records[-1].share <= 0.0:
        # A failure reaches every level: the probability is at most that of reaching the
        # last, whose estimate (the levels before) has the upper end of its interval here.
        reached = records[:-1]
        bound = math.exp(sum(math.log(record.share) for record in reached))
        bound = log_normal_interval(bound, sum(math.sqrt(r.squared_cv) for r in reached))[1]
        kind = "no failure at the last level: bound by the levels reached"
        return Estimate(0.0, 0.0, bound, episodes, failures, 0.0, None, 0.0, 0.0, kind), state
    p = math.exp(sum(math.log(record.share) for record in records))
    # The levels' estimates are correlated (each level's chains start from the last level's
    # samples): their coefficients of variation add up, Au and Beck's upper bound.
    cv = sum(math.sqrt(record.squared_cv) for record in records)
    low, high = log_normal_interval(p, cv)
    kind = "log-normal (Au and Beck, upper bound)"
    if not state.converged:
        kind = "log-normal; not converged: the budget ran out before the failure level"
    return Estimate(p, low, high, episodes, failures, p * cv, cv, math.nan, p, kind), state


def untested_share(planner: SplittingPlanner, table: pd.DataFrame) -> Estimate:
    """The probability of an encounter the SUT could not play: the share of the first level's
    samples that ended in a SUT error, with its exact interval. The first level is plain Monte
    Carlo over the model; the levels after it are drawn towards high scores and say nothing of
    how often the SUT errs (an error early in an episode leaves its score low, and such an
    encounter never reaches them).

    Raises:
        ValueError: The first level is not complete.
    """
    state = planner.progress(table)
    if not state.levels:
        raise ValueError("the first level is not complete")
    rows = state.levels[0].rows()
    erred = table["sut_error"].to_numpy(bool)[rows]
    return estimate(erred, np.zeros(len(rows)), np.ones(len(rows)))


def _chain_correlation(marks: list[list[bool]], share: float) -> float:
    """Au and Beck's factor ``gamma``: twice the weighted sum of the marks' autocorrelation
    along the chains (all chains of a level have the same length)."""
    indicator = np.array(marks, dtype=float)  # chains x length
    chains, length = indicator.shape
    total = chains * length
    variance = share * (1.0 - share)
    if variance <= 0.0 or length < 2:
        return 0.0
    gamma = 0.0
    for lag in range(1, length):
        products = indicator[:, :-lag] * indicator[:, lag:]
        covariance = float(products.mean()) - share * share
        gamma += 2.0 * (1.0 - lag * chains / total) * covariance / variance
    return max(gamma, 0.0)
