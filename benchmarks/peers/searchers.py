"""Off-the-shelf search methods behind one ask/tell interface, and the loop that spends a budget.

Each method maximises an episode's maximum risk over the box [-1, 1]^d of open-loop actions.
The libraries are imported when a method is built, so a run needs only the ones it uses.

- ``cma``: ``cma.CMAEvolutionStrategy`` with its defaults (population 4 + 3 ln d), x0 = 0,
  sigma0 = 0.5, bounds [-1, 1]; it minimises, so it is told -max_risk. When it stops on one of
  its own criteria it restarts from x0 with the next seed.
- ``map-elites``: pyribs' ``GridArchive`` over (bearing, robot speed) of the contact or
  closest approach, ``GaussianEmitter`` s that mutate elites (plain MAP-Elites) and a
  ``Scheduler``; objective = max risk. The first batch is uniform in the box.
- ``verifai-ce``, ``verifai-bandit``: VerifAI's cross-entropy and multi-armed-bandit samplers
  with their default parameters. Both minimise a robustness value rho and learn only from
  samples with rho < ``thres``: they are told rho = -max_risk with thres = -50, between the
  largest risk without contact (1) and the smallest of an unsafe contact (100), so a
  failure is what they learn from, as a falsifier's counterexample.
- ``verifai-sa``: VerifAI's simulated annealing, told rho = -max_risk (it minimises).
  VerifAI 2.2.0's sampler leaves its first-sample state only on an update without a value,
  which the documented getSample/update loop never sends; as shipped it samples uniformly.
  The adapter ends that state after the first update (one attribute), so it anneals.
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable, Sequence
from typing import Any, Protocol

import numpy as np
from evaluation import Evaluation
from numpy.typing import NDArray

from hazardhunt.spec.descriptors import DESCRIPTOR_BOUNDS

Points = NDArray[np.float64]

CMA_SIGMA0 = 0.5
"""CMA-ES's initial step size, in action units (the box is 2 wide)."""

GRID_CELLS = (18, 6)
"""MAP-Elites' archive: 20-degree bearing sectors x 0.2 m/s robot-speed bands."""
EMITTERS = 2
EMITTER_BATCH = 16
MUTATION_SIGMA = 0.2
"""The Gaussian emitters' mutation, in action units."""

FAILURE_SEPARATOR = 50.0
"""A max risk above this is an unsafe contact (those are >= 100; the rest are <= 1)."""

ANNEALING = {"T": 1.0, "decay_rate": 0.9, "iterations": 100}
"""VerifAI's annealing has no defaults: start temperature (on the scale of the risk without
contact, 0 to 1; it cools by 0.8 per sample and reheats below 0.01, about every 21 samples),
the proposal box's shrink per sample within an epoch, and the longest epoch."""


class Searcher(Protocol):
    """An ask/tell search method over the action box."""

    def ask(self) -> Points:
        """The next points to evaluate, one per row."""
        ...

    def tell(self, points: Points, evaluations: Sequence[Evaluation]) -> None:
        """The evaluations of the points of the last ask, in order."""
        ...


def seeds(seed: int, count: int) -> list[int]:
    """``count`` independent non-zero 32-bit seeds derived from ``seed``."""
    return [int(s) or 1 for s in np.random.SeedSequence(seed).generate_state(count)]


class CMAES:
    """CMA-ES (package ``cma``), restarted from x0 with a new seed when it stops."""

    def __init__(self, dimension: int, seed: int) -> None:
        import cma

        self._cma = cma
        self._dimension = dimension
        self._seed = seeds(seed, 1)[0]
        self.restarts = 0
        self._strategy = self._start()

    def _start(self) -> Any:
        options = {
            "bounds": [-1.0, 1.0],
            "seed": self._seed + self.restarts,
            "verbose": -9,
            "verb_log": 0,
            "verb_disp": 0,
        }
        return self._cma.CMAEvolutionStrategy(np.zeros(self._dimension), CMA_SIGMA0, options)

    def ask(self) -> Points:
        if self._strategy.stop():
            self.restarts += 1
            self._strategy = self._start()
        return np.asarray(self._strategy.ask(), dtype=np.float64)

    def tell(self, points: Points, evaluations: Sequence[Evaluation]) -> None:
        self._strategy.tell(list(points), [-e.max_risk for e in evaluations])


class MapElites:
    """MAP-Elites (package ``ribs``): Gaussian mutation of elites in a (bearing, speed) grid."""

    def __init__(self, dimension: int, seed: int) -> None:
        from ribs.archives import GridArchive
        from ribs.emitters import GaussianEmitter
        from ribs.schedulers import Scheduler

        archive_seed, start_seed, *emitter_seeds = seeds(seed, 2 + EMITTERS)
        self.archive = GridArchive(
            solution_dim=dimension,
            dims=GRID_CELLS,
            ranges=DESCRIPTOR_BOUNDS[:2],
            seed=archive_seed,
        )
        start = np.random.default_rng(start_seed).uniform(-1.0, 1.0, (EMITTER_BATCH, dimension))
        emitters = [
            GaussianEmitter(
                self.archive,
                sigma=MUTATION_SIGMA,
                initial_solutions=start,
                bounds=[(-1.0, 1.0)] * dimension,
                batch_size=EMITTER_BATCH,
                seed=emitter_seed,
            )
            for emitter_seed in emitter_seeds
        ]
        self._scheduler = Scheduler(self.archive, emitters)

    def ask(self) -> Points:
        return np.asarray(self._scheduler.ask(), dtype=np.float64)

    def tell(self, points: Points, evaluations: Sequence[Evaluation]) -> None:
        self._scheduler.tell(
            [e.max_risk for e in evaluations],
            [[e.bearing, e.robot_speed] for e in evaluations],
        )


class VerifAISampler:
    """One of VerifAI's feature samplers over a box feature of ``dimension`` numbers.

    VerifAI's samplers draw from numpy's and Python's global generators, which are seeded
    here: run one at a time per process.
    """

    def __init__(self, kind: str, dimension: int, seed: int) -> None:
        from dotmap import DotMap
        from verifai.features import Box, Feature, FeatureSpace
        from verifai.samplers import FeatureSampler
        from verifai.samplers.feature_sampler import default_sampler_params

        # VerifAI's samplers draw from the legacy global generators, nowhere else to seed.
        np.random.seed(seed)  # noqa: NPY002
        random.seed(seed)
        space = FeatureSpace({"actions": Feature(Box(*[(-1.0, 1.0)] * dimension))})
        if kind == "sa":
            params = DotMap(ANNEALING, num_epoch=math.inf)
            self._sampler = FeatureSampler.simulatedAnnealingSamplerFor(space, params)
        else:
            params = default_sampler_params(kind)
            params.thres = -FAILURE_SEPARATOR
            build = {
                "ce": FeatureSampler.crossEntropySamplerFor,
                "mab": FeatureSampler.multiArmedBanditSamplerFor,
            }[kind]
            self._sampler = build(space, params)
        self._annealing = kind == "sa"
        self._pending: tuple[Any, Any] | None = None

    def ask(self) -> Points:
        sample, info = self._sampler.getSample()
        self._pending = (sample, info)
        return np.asarray([sample.actions], dtype=np.float64)

    def tell(self, points: Points, evaluations: Sequence[Evaluation]) -> None:
        assert self._pending is not None, "tell without ask"
        sample, info = self._pending
        # Annealing's acceptance exp(improvement / T) overflows to inf on a large improvement
        # (a failure after near misses); min(1, inf) accepts, as it should.
        with np.errstate(over="ignore"):
            self._sampler.update(sample, info, -evaluations[0].max_risk)
        if self._annealing:
            for annealer in self._sampler.domainSampler.samplers:
                annealer.is_first_sample = False
        self._pending = None


METHODS: dict[str, Callable[[int, int], Searcher]] = {
    "cma": CMAES,
    "map-elites": MapElites,
    "verifai-ce": lambda dimension, seed: VerifAISampler("ce", dimension, seed),
    "verifai-sa": lambda dimension, seed: VerifAISampler("sa", dimension, seed),
    "verifai-bandit": lambda dimension, seed: VerifAISampler("mab", dimension, seed),
}
"""Each method's constructor, ``(dimension, seed) -> Searcher``."""

BATCHED = frozenset({"cma", "map-elites"})
"""Methods whose ask gives a batch: its episodes are spread over the worker processes. The
others ask one point at a time and run whole in one worker."""


def search(
    searcher: Searcher,
    evaluate_batch: Callable[[Points], list[Evaluation]],
    episodes: int,
) -> list[Evaluation]:
    """Ask, evaluate, tell until ``episodes`` episodes are played; the evaluations in order.

    A last batch larger than what is left of the budget is cut, and not told.
    """
    evaluations: list[Evaluation] = []
    while len(evaluations) < episodes:
        points = searcher.ask()
        played = evaluate_batch(points[: episodes - len(evaluations)])
        evaluations.extend(played)
        if len(played) == len(points):
            searcher.tell(points, played)
    return evaluations
