"""The cross-entropy method over a whole episode's action sequence, with restarts.

The rare-event baseline of adaptive stress testing (Rubinstein's cross-entropy method, as the AST
Toolbox uses it): an episode is one point, the human's open-loop sequence of ``horizon``
decisions; a Gaussian over those sequences (one mean and one standard deviation per decision
and per action entry) is sampled, the best ``elite_fraction`` of each batch refit it, smoothed.
The score of an episode is its maximum risk: 100 to 200 for an unsafe contact, otherwise
exp(-clearance) while the robot moves, so a near miss already points towards a failure.

Plain CEM converges onto one failure and then finds it again and again. Here a failure scores
by how far its descriptor (:mod:`hazardhunt.spec.descriptors`) lies from the failures found
before it, so a known mechanism earns less than a new one; and once the search has converged
(its spread below ``min_std``) or has found nothing new for ``patience`` batches, it restarts
from a fresh random mean, away from the mechanisms it already has.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from hazardhunt.spec.episode import EpisodeSummary
from hazardhunt.testers.base import MAX_WORKER_PROCESSES, EpisodeRecorder, check_parameters
from hazardhunt.testers.novelty import FailureArchive
from hazardhunt.testers.spaces import (
    DECISION_SIZES,
    SPACE_CHOICES,
    boundary_plans,
    searched_spaces,
)

MAX_POPULATION = 10_000
"""The largest batch: the weights of its elites are kept in memory from the start."""

COLLISION_SCORE = 100.0
"""The score of a failure that repeats a known mechanism; a new one scores up to twice it."""


class CrossEntropyTester:
    """The cross-entropy method with novelty-scored failures and restarts."""

    name = "cem"

    def __init__(
        self,
        seed: int,
        population: int = 20,
        elite_fraction: float = 0.25,
        smoothing: float = 0.9,
        initial_std: float = 0.6,
        min_std: float = 0.03,
        patience: int = 8,
        novelty_radius: float = 0.4,
        n_workers: int = 1,
        clear_path: bool = False,
        space: str = "open",
        noise_exponent: float = 0.0,
        probes: bool = False,
    ) -> None:
        """This is long because it checks every parameter, so that an error names the one at fault.

        Args:
        seed: Seeds the sampling.
        population: Episodes per batch.
        elite_fraction: Share of a batch that refits the Gaussian.
        smoothing: Weight of the elites' mean and spread against the previous ones.
        initial_std: Standard deviation of every action entry at the start and at a restart.
        min_std: Mean standard deviation below which the search has converged and restarts.
        patience: Batches without a new failure mechanism after which it restarts.
        novelty_radius: Descriptor distance from the known failures at which a failure counts
            as a new mechanism (1 separates opposite sides of the robot or another history of
            the safety layer).
        n_workers: Processes that play each batch (1: in the run's own process).
        clear_path: Whether an action that would walk the human into a wall or shelf is
            played as the nearest one that does not (:mod:`hazardhunt.testers.clear_path`).
        space: What a decision's numbers mean (:mod:`hazardhunt.testers.spaces`): ``open``
            (speed, turn rate), ``aim`` (at the robot), ``route`` (at a point of its route),
            or ``mixed``: one Gaussian per space, their batches taking turns, the failures
            found in one space scoring the others' as known.
        noise_exponent: How the sampling noise is correlated over an episode's decisions
            (iCEM's coloured noise, Pinneri et al. 2020): 0 draws every decision
            independently, larger exponents give smoother sequences (2: a random walk's
            spectrum), in which a human keeps to one plan for longer.
        probes: Whether each space's first batch starts with the space's boundary values
            (:func:`~hazardhunt.testers.spaces.boundary_plans`: 3, 12 and 9 episodes).

        Raises:
            TesterParameterError: A parameter out of its range.
        """
        checks = {
            "population": (
                population,
                f"from 2 to {MAX_POPULATION:,}",
                2 <= population <= MAX_POPULATION,
            ),
            "elite_fraction": (elite_fraction, "in (0, 1]", 0.0 < elite_fraction <= 1.0),
            "smoothing": (smoothing, "in (0, 1]", 0.0 < smoothing <= 1.0),
            "initial_std": (initial_std, "> 0", initial_std > 0.0),
            "min_std": (min_std, ">= 0", min_std >= 0.0),
            "patience": (patience, ">= 1", patience >= 1),
            "novelty_radius": (novelty_radius, "> 0", novelty_radius > 0.0),
            "n_workers": (
                n_workers,
                f"from 1 to {MAX_WORKER_PROCESSES}",
                1 <= n_workers <= MAX_WORKER_PROCESSES,
            ),
            "clear_path": (clear_path, "true or false", isinstance(clear_path, bool)),
            "space": (space, f"one of {', '.join(SPACE_CHOICES)}", space in SPACE_CHOICES),
            "probes": (probes, "true or false", isinstance(probes, bool)),
            "noise_exponent": (
                noise_exponent,
                "a number from 0 to 4",
                isinstance(noise_exponent, int | float)
                and not isinstance(noise_exponent, bool)
                and 0.0 <= noise_exponent <= 4.0,
            ),
        }
        check_parameters(self.name, checks)
        self.seed = seed
        self.population = population
        self.elites = max(1, round(elite_fraction * population))
        ranks = np.log(self.elites + 0.5) - np.log(np.arange(1, self.elites + 1))
        self.weights = ranks / ranks.sum()
        self.smoothing = smoothing
        self.initial_std = initial_std
        self.min_std = min_std
        self.patience = patience
        self.novelty_radius = novelty_radius
        self.n_workers = n_workers
        self.clear_path = clear_path
        self.space = space
        self.noise_exponent = float(noise_exponent)
        self.probes = probes
        self.restarts = 0

    def explore(self, env: EpisodeRecorder, episodes: int) -> None:
        rng = np.random.default_rng(self.seed)
        spaces = searched_spaces(self.space)
        shapes = {space: (env.horizon, DECISION_SIZES[space]) for space in spaces}
        searches = {
            space: _Search(np.zeros(shape), np.full(shape, self.initial_std))
            for space, shape in shapes.items()
        }
        archive = FailureArchive(neighbours=1)
        turn = 0
        while env.episodes_done < episodes:
            space = spaces[turn % len(spaces)]
            search, shape, turn = searches[space], shapes[space], turn + 1
            count = min(self.population, episodes - env.episodes_done)
            noise = coloured_noise(rng, (count, *shape), self.noise_exponent)
            samples = np.clip(search.mean + search.std * noise, -1.0, 1.0)
            if self.probes and turn <= len(spaces):
                plans = boundary_plans(space, env.horizon)[:count]
                samples[: len(plans)] = plans
            results = env.evaluate_batch(list(samples), self.n_workers, self.clear_path, space)
            if env.episodes_done >= episodes:
                break  # the budget is spent: nothing left to refit the Gaussian for
            scores, novel = self._scores([r.summary for r in results], archive)
            # The elites, best first, weighted by rank as CMA-ES weights its parents.
            elite = samples[np.argsort(scores, kind="stable")[::-1][: self.elites]]
            elite_mean = np.tensordot(self.weights, elite, axes=1)
            elite_std = np.sqrt(np.tensordot(self.weights, (elite - elite_mean) ** 2, axes=1))
            search.mean = self.smoothing * elite_mean + (1 - self.smoothing) * search.mean
            search.std = self.smoothing * elite_std + (1 - self.smoothing) * search.std
            search.stale = 0 if novel else search.stale + 1
            if search.std.mean() < self.min_std or search.stale >= self.patience:
                # Away from what it has: a fresh mean, and known failures score less.
                search.mean = rng.uniform(-0.6, 0.6, shape)
                search.std, search.stale = np.full(shape, self.initial_std), 0
                self.restarts += 1

    def _scores(
        self, summaries: list[EpisodeSummary], archive: FailureArchive
    ) -> tuple[NDArray[np.float64], bool]:
        """Each episode's score, and whether the batch found a new failure mechanism."""
        scores, novel = [], False
        for summary in summaries:
            if summary.outcome != "failure":
                scores.append(summary.max_risk)
                continue
            distance = archive.novelty(summary)
            novel = novel or distance >= self.novelty_radius
            scores.append(COLLISION_SCORE * (1.0 + min(1.0, distance / self.novelty_radius)))
            archive.add(summary)
        return np.asarray(scores), novel

    def save(self, directory: Path) -> None:
        """The sampler's settings and how often it restarted."""
        directory.mkdir(parents=True, exist_ok=True)
        settings = {
            "tester": self.name,
            "seed": self.seed,
            "population": self.population,
            "elites": self.elites,
            "smoothing": self.smoothing,
            "initial_std": self.initial_std,
            "min_std": self.min_std,
            "patience": self.patience,
            "novelty_radius": self.novelty_radius,
            "clear_path": self.clear_path,
            "space": self.space,
            "noise_exponent": self.noise_exponent,
            "probes": self.probes,
            "restarts": self.restarts,
        }
        (directory / "cem.json").write_text(json.dumps(settings, indent=2) + "\n")


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


@dataclass
class _Search:
    """One Gaussian over a search space's decision sequences, and how long it found nothing
    new."""

    mean: NDArray[np.float64]
    std: NDArray[np.float64]
    stale: int = 0
