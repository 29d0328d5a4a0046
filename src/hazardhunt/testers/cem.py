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
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from hazardhunt.spec.episode import EpisodeSummary
from hazardhunt.testers.aim import AIM_SIZE
from hazardhunt.testers.base import MAX_WORKER_PROCESSES, EpisodeRecorder, check_parameters
from hazardhunt.testers.novelty import FailureArchive

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
        aim: bool = False,
    ) -> None:
        """Args:
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
        aim: Whether each decision is aimed at the robot (speed, bearing around it, stand-off:
            three numbers, :mod:`hazardhunt.testers.aim`) instead of an open-loop (speed, turn
            rate).

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
            "aim": (aim, "true or false", isinstance(aim, bool)),
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
        self.aim = aim
        self.restarts = 0

    def explore(self, env: EpisodeRecorder, episodes: int) -> None:
        rng = np.random.default_rng(self.seed)
        shape = (env.horizon, AIM_SIZE if self.aim else 2)
        mean, std = np.zeros(shape), np.full(shape, self.initial_std)
        archive = FailureArchive(neighbours=1)
        stale = 0
        while env.episodes_done < episodes:
            count = min(self.population, episodes - env.episodes_done)
            samples = np.clip(mean + std * rng.standard_normal((count, *shape)), -1.0, 1.0)
            results = env.evaluate_batch(list(samples), self.n_workers, self.clear_path, self.aim)
            if env.episodes_done >= episodes:
                break  # the budget is spent: nothing left to refit the Gaussian for
            scores, novel = self._scores([r.summary for r in results], archive)
            # The elites, best first, weighted by rank as CMA-ES weights its parents.
            elite = samples[np.argsort(scores, kind="stable")[::-1][: self.elites]]
            elite_mean = np.tensordot(self.weights, elite, axes=1)
            elite_std = np.sqrt(np.tensordot(self.weights, (elite - elite_mean) ** 2, axes=1))
            mean = self.smoothing * elite_mean + (1 - self.smoothing) * mean
            std = self.smoothing * elite_std + (1 - self.smoothing) * std
            stale = 0 if novel else stale + 1
            if std.mean() < self.min_std or stale >= self.patience:
                # Away from what it has: a fresh mean, and known failures score less.
                mean, std = rng.uniform(-0.6, 0.6, shape), np.full(shape, self.initial_std)
                stale, self.restarts = 0, self.restarts + 1

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
            "aim": self.aim,
            "restarts": self.restarts,
        }
        (directory / "cem.json").write_text(json.dumps(settings, indent=2) + "\n")
