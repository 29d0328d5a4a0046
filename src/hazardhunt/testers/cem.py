"""The cross-entropy method over a whole episode's decisions, with restarts.

The rare-event baseline of adaptive stress testing (Rubinstein's cross-entropy method, as the AST
Toolbox uses it): an episode is one point, the human's sequence of ``horizon`` decisions; a
Gaussian over those sequences (one mean and one standard deviation per decision and per number)
is sampled, the best ``elite_fraction`` of each batch refit it, smoothed. The score of an
episode is its maximum risk: 100 to 200 for an unsafe contact, otherwise exp(-clearance) while
the robot moves, so a near miss already points towards a failure.

Plain CEM converges onto one failure and then finds it again and again. Here a failure scores
by how far its descriptor (:mod:`hazardhunt.spec.descriptors`) lies from the failures found
before it, so a known mechanism earns less than a new one; and once the search has converged
(its spread below ``min_spread``) or has found nothing new for ``patience`` batches, it
restarts from a fresh random mean, away from the mechanisms it already has.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray
from pydantic import Field

from hazardhunt.sim.simulation import EpisodeResult
from hazardhunt.testers.evaluator import Plan
from hazardhunt.testers.novelty import FailureArchive
from hazardhunt.testers.search import SearchContext, SearchTester, SpaceParams
from hazardhunt.testers.spaces import DecisionSpace

MAX_BATCH = 10_000
"""The largest batch: the weights of its elites are kept in memory from the start."""

COLLISION_SCORE = 100.0
"""The score of a failure that repeats a known mechanism; a new one scores up to twice it."""


class CrossEntropyParams(SpaceParams):
    """The cross-entropy method's settings."""

    batch_size: int = Field(default=20, ge=2, le=MAX_BATCH)
    """Episodes per batch (``population`` in earlier versions)."""
    elite_fraction: float = Field(default=0.25, gt=0.0, le=1.0, allow_inf_nan=False)
    """Share of a batch that refits the Gaussian."""
    smoothing: float = Field(default=0.9, gt=0.0, le=1.0, allow_inf_nan=False)
    """Weight of the elites' mean and spread against the previous ones."""
    initial_spread: float = Field(default=0.6, gt=0.0, allow_inf_nan=False)
    """Standard deviation of every number at the start and at a restart."""
    min_spread: float = Field(default=0.03, ge=0.0, allow_inf_nan=False)
    """Mean standard deviation below which the search has converged and restarts."""
    patience: int = Field(default=8, ge=1)
    """Batches without a new failure mechanism after which it restarts."""
    novelty_radius: float = Field(default=0.4, gt=0.0, allow_inf_nan=False)
    """Descriptor distance from the known failures at which a failure counts as a new
    mechanism (1 separates opposite sides of the robot or another history of the safety
    layer)."""
    noise_exponent: float = Field(default=0.0, ge=0.0, le=4.0, allow_inf_nan=False)
    """How the sampling noise is correlated over an episode's decisions (iCEM's coloured noise,
    Pinneri et al. 2020): 0 draws every decision independently, larger exponents give smoother
    sequences (2: a random walk's spectrum), in which a human keeps to one plan for longer."""


class CrossEntropySampler:
    """One Gaussian per decision space, their batches taking turns; failures found in one
    space count as known in the others."""

    def __init__(
        self,
        params: CrossEntropyParams,
        context: SearchContext,
        archive: FailureArchive | None = None,
    ) -> None:
        """Args:
        params: The settings.
        context: The run's seed and episodes.
        archive: The failures that count as known (shared with other samplers); a new one
            by default.
        """
        self.params = params
        self.objective = context.objective
        self.rng = np.random.default_rng(context.seed)
        self.horizon = context.horizon
        self.searches = [
            _Search(space, context.horizon, params.initial_spread)
            for space in params.space.decision_spaces
        ]
        self.archive = archive if archive is not None else FailureArchive(neighbours=1)
        elites = max(1, round(params.elite_fraction * params.batch_size))
        ranks = np.log(elites + 0.5) - np.log(np.arange(1, elites + 1))
        self.weights = ranks / ranks.sum()
        self.batches = 0
        self.restarts = 0
        self._samples: NDArray[np.float64] | None = None

    @property
    def search(self) -> _Search:
        """The Gaussian whose turn it is."""
        return self.searches[self.batches % len(self.searches)]

    def ask(self) -> list[Plan]:
        search, count = self.search, self.params.batch_size
        noise = coloured_noise(self.rng, (count, *search.mean.shape), self.params.noise_exponent)
        samples = np.clip(search.mean + search.std * noise, -1.0, 1.0)
        if self.params.space.plain_attacks and self.batches < len(self.searches):
            plans = search.space.plain_attacks(self.horizon)[:count]
            samples[: len(plans)] = plans
        self._samples = samples
        return [Plan(search.space, decisions) for decisions in samples]

    def tell(self, plans: list[Plan], results: list[EpisodeResult]) -> None:
        assert self._samples is not None, "tell() before ask()"
        search, samples = self.search, self._samples[: len(results)]
        self.batches += 1
        scores, novel = self._scores(results)
        # The elites, best first, weighted by rank as CMA-ES weights its parents.
        weights = self.weights[: len(samples)] / self.weights[: len(samples)].sum()
        elite = samples[np.argsort(scores, kind="stable")[::-1][: len(weights)]]
        elite_mean = np.tensordot(weights, elite, axes=1)
        elite_std = np.sqrt(np.tensordot(weights, (elite - elite_mean) ** 2, axes=1))
        smoothing = self.params.smoothing
        search.mean = smoothing * elite_mean + (1 - smoothing) * search.mean
        search.std = smoothing * elite_std + (1 - smoothing) * search.std
        search.stale = 0 if novel else search.stale + 1
        if search.std.mean() < self.params.min_spread or search.stale >= self.params.patience:
            # Away from what it has: a fresh mean, and known failures score less.
            search.mean = self.rng.uniform(-0.6, 0.6, search.mean.shape)
            search.std = np.full(search.mean.shape, self.params.initial_spread)
            search.stale = 0
            self.restarts += 1

    def _scores(self, results: list[EpisodeResult]) -> tuple[NDArray[np.float64], bool]:
        """Each episode's score, and whether the batch found a new failure mechanism (or a
        violation of the requirement searched on, in a new place)."""
        scores, novel, radius = [], False, self.params.novelty_radius
        for result in results:
            summary = result.summary
            if not self.objective.hit(result):
                scores.append(self.objective.score(result))
                continue
            distance = self.archive.novelty(summary)
            novel = novel or distance >= radius
            scores.append(COLLISION_SCORE * (1.0 + min(1.0, distance / radius)))
            self.archive.add(summary)
        return np.asarray(scores), novel

    def record(self) -> dict[str, Any]:
        return {"restarts": self.restarts}


class CrossEntropyTester(SearchTester):
    """The cross-entropy method with novelty-scored failures and restarts."""

    name = "cem"
    params_model = CrossEntropyParams
    params: CrossEntropyParams

    def make_sampler(self, context: SearchContext) -> CrossEntropySampler:
        return CrossEntropySampler(self.params, context)


def coloured_noise(
    rng: np.random.Generator, shape: tuple[int, ...], exponent: float
) -> NDArray[np.float64]:
    """Normal noise of ``shape`` (samples, decisions, numbers per decision), zero mean and unit
    spread at every decision, whose power over the decisions falls with frequency f as
    1 / f**exponent; exponent 0 is plain white noise. The lowest frequency, a constant over
    the whole episode, gets the power of the next one. The noise is drawn over twice the
    decisions and cut, so that the end of an episode is not tied to its start."""
    if exponent == 0.0:
        return rng.standard_normal(shape)
    samples, decisions, numbers = shape
    length = 2 * decisions
    frequencies = np.fft.rfftfreq(length)
    frequencies[0] = frequencies[1]
    scale = frequencies ** (-exponent / 2.0)
    # The spread each decision gets from unit normal real and imaginary parts of the spectrum.
    basis = np.eye(len(frequencies))
    spread = np.sqrt(
        (np.fft.irfft(basis * scale, n=length) ** 2).sum(axis=0)
        + (np.fft.irfft(1j * basis * scale, n=length) ** 2).sum(axis=0)
    )[:decisions]
    spectrum = rng.standard_normal((samples, numbers, len(frequencies), 2))
    noise = np.fft.irfft(scale * (spectrum[..., 0] + 1j * spectrum[..., 1]), n=length)
    return np.moveaxis(noise[..., :decisions] / spread, 1, 2)


class _Search:
    """One Gaussian over a decision space's sequences, and how long it found nothing new."""

    def __init__(self, space: DecisionSpace, horizon: int, spread: float) -> None:
        self.space = space
        self.mean = np.zeros((horizon, space.size))
        self.std = np.full((horizon, space.size), spread)
        self.stale = 0
