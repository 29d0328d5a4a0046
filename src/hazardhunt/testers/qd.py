"""Quality-diversity search over whole episodes (pyribs: CMA-ME, or CMA-MAE).

An episode is one point, the human's open-loop sequence of ``horizon`` decisions; its quality
is its maximum risk (100 to 200 for an unsafe contact, otherwise exp(-clearance) while the robot
moves) and its measures describe how it met the robot (:mod:`hazardhunt.spec.descriptors`): by
default the bearing of the contact (or closest approach) around the robot's body, the robot's
speed there and the safety layer's history. An archive keeps the best episode of every cell of
that grid, so the search is rewarded for filling cells it has not reached, that is for new
mechanisms, rather than for finding one failure again. CMA-ME (Fontaine et al. 2020) drives
CMA-ES emitters by archive improvement; CMA-MAE (Fontaine and Nikolaidis 2023) anneals the
acceptance threshold of each cell.

The run keeps the archive (``tester/archive.parquet``); the report draws it as a heat map.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from hazardhunt.sim.simulation import EpisodeResult
from hazardhunt.spec.descriptors import MEASURE_NAMES, MEASURE_RANGES, measures_of
from hazardhunt.testers.base import (
    MAX_WORKER_PROCESSES,
    EpisodeRecorder,
    TesterParameterError,
    check_parameters,
)
from hazardhunt.testers.spaces import (
    DECISION_SIZES,
    SPACE_CHOICES,
    boundary_plans,
    searched_spaces,
)

ALGORITHMS = ("cma-me", "cma-mae", "map-elites")

MAX_CELLS = 1_000_000
"""The most cells of the archive, which allocates them all at the start."""
MAX_EMITTERS = 100
"""The most emitters (each keeps a CMA-ES state over the whole action sequence)."""
MAX_BATCH = 10_000
"""The most episodes an emitter asks for at once."""
EVOLUTION_STRATEGIES = ("cma_es", "sep_cma_es", "lm_ma_es")
"""The emitters' evolution strategies (pyribs' names): full covariance, diagonal, limited
memory."""
DEFAULT_MEASURES = ("bearing", "robot_speed", "emergency_stop")
"""The archive's axes unless ``measures`` says otherwise."""
MAX_STATE_BYTES = 2 * 1024**3
"""The most memory the emitters' states and the archive may take; beyond it a run is refused
before it starts rather than killed for memory once it has."""


class QualityDiversityTester:
    """CMA-ME / CMA-MAE emitters over an archive of failure descriptors."""

    name = "qd"

    def __init__(
        self,
        seed: int,
        measures: Sequence[str] = DEFAULT_MEASURES,
        bins: Sequence[int] = (8, 3, 3),
        algorithm: str = "cma-me",
        emitters: int = 2,
        batch_size: int = 10,
        sigma0: float = 0.6,
        learning_rate: float = 0.02,
        es: str = "cma_es",
        n_workers: int = 1,
        clear_path: bool = False,
        space: str = "open",
        probes: bool = False,
    ) -> None:
        """This is long because it checks every parameter, so that an error names the one at fault.

        Args:
        seed: Seeds the archive and the emitters.
        measures: The entries that span the archive (of ``bearing``, ``robot_speed``,
            ``emergency_stop``, ``route_share``, ``human_speed``;
            :mod:`hazardhunt.spec.descriptors`).
        bins: Cells along each measure.
        algorithm: ``cma-me``, ``cma-mae``, or ``map-elites`` (Gaussian mutation of archive
            elites, started from uniformly random sequences).
        emitters: Emitters (CMA-ES ones, or Gaussian ones for ``map-elites``).
        batch_size: Episodes each emitter asks for per iteration.
        sigma0: The emitters' initial step size, or the mutation's spread for ``map-elites``
            (actions are in [-1, 1]).
        learning_rate: CMA-MAE's archive learning rate (``cma-mae`` only).
        es: The emitters' evolution strategy: ``cma_es`` (a full covariance over the whole
            action sequence, memory growing with its square), ``sep_cma_es`` (diagonal) or
            ``lm_ma_es`` (limited memory), for long episodes with many decisions.
        n_workers: Processes that play each batch (1: in the run's own process).
        clear_path: Whether an action that would walk the human into a wall or shelf is
            played as the nearest one that does not (:mod:`hazardhunt.testers.clear_path`).
        space: What a decision's numbers mean (:mod:`hazardhunt.testers.spaces`): ``open``
            (speed, turn rate), ``aim`` (at the robot), ``route`` (at a point of its route),
            or ``mixed``: the emitters take the spaces in turn (the first ``open``, the
            second ``aim``, the third ``route``, ...) and fill one archive.
        probes: Whether the search starts with its spaces' boundary values, into the archive
            (:func:`~hazardhunt.testers.spaces.boundary_plans`: 3, 12 and 9 episodes).

        Raises:
            TesterParameterError: An unknown measure or algorithm, or a setting out of its
                range.
        """
        measures, bins = list(measures), list(bins)
        known = set(measures) <= set(MEASURE_NAMES)
        checks = {
            "measures": (
                measures,
                f"distinct names of {', '.join(MEASURE_NAMES)}",
                known and len(set(measures)) == len(measures) > 0,
            ),
            "bins": (
                bins,
                f"one whole number >= 1 per measure, at most {MAX_CELLS:,} cells in all",
                len(bins) == len(measures)
                and all(b >= 1 for b in bins)
                and math.prod(bins) <= MAX_CELLS,
            ),
            "algorithm": (algorithm, f"one of {', '.join(ALGORITHMS)}", algorithm in ALGORITHMS),
            "es": (es, f"one of {', '.join(EVOLUTION_STRATEGIES)}", es in EVOLUTION_STRATEGIES),
            "emitters": (emitters, f"from 1 to {MAX_EMITTERS}", 1 <= emitters <= MAX_EMITTERS),
            "batch_size": (batch_size, f"from 1 to {MAX_BATCH:,}", 1 <= batch_size <= MAX_BATCH),
            "sigma0": (sigma0, "> 0", sigma0 > 0),
            "learning_rate": (learning_rate, "in (0, 1]", 0 < learning_rate <= 1),
            "n_workers": (
                n_workers,
                f"from 1 to {MAX_WORKER_PROCESSES}",
                1 <= n_workers <= MAX_WORKER_PROCESSES,
            ),
            "clear_path": (clear_path, "true or false", isinstance(clear_path, bool)),
            "space": (space, f"one of {', '.join(SPACE_CHOICES)}", space in SPACE_CHOICES),
            "probes": (probes, "true or false", isinstance(probes, bool)),
        }
        check_parameters(self.name, checks)
        self.seed = seed
        self.measures = measures
        self.bins = [int(b) for b in bins]
        self.algorithm = algorithm
        self.emitters = emitters
        self.batch_size = batch_size
        self.sigma0 = sigma0
        self.learning_rate = learning_rate
        self.es = es
        self.n_workers = n_workers
        self.clear_path = clear_path
        self.space = space
        self.probes = probes
        self.archive: Any = None

    @property
    def decision_size(self) -> int:
        """Numbers per decision in a searched sequence (with ``mixed`` the largest space's; an
        open-loop decision reads the first two)."""
        if self.space == "mixed":
            return max(DECISION_SIZES.values())
        return DECISION_SIZES[self.space]

    def explore(self, env: EpisodeRecorder, episodes: int) -> None:
        scheduler = self._scheduler(env)
        if self.probes:
            self._probe(env, scheduler, episodes)
        while env.episodes_done < episodes:
            solutions = scheduler.ask()
            left = episodes - env.episodes_done
            results = self._play(env, solutions[:left])
            objective = [result.summary.max_risk for result in results]
            measures = [measures_of(result.summary, self.measures) for result in results]
            if len(results) < len(solutions):
                # The budget ends within this batch: the archive keeps what it played.
                self.archive.add(solutions[: len(results)], objective, measures)
                break
            scheduler.tell(objective, measures)

    def _probe(self, env: EpisodeRecorder, scheduler: Any, episodes: int) -> None:
        """Play the boundary values of every space searched into the archive(s)."""
        for space in searched_spaces(self.space):
            plans = boundary_plans(space, env.horizon)[: episodes - env.episodes_done]
            if len(plans) == 0:
                return
            results = env.evaluate_batch(list(plans), self.n_workers, self.clear_path, space)
            solutions = np.zeros((len(plans), env.horizon, self.decision_size))
            solutions[:, :, : plans.shape[2]] = plans
            objective = [result.summary.max_risk for result in results]
            measures = [measures_of(result.summary, self.measures) for result in results]
            archives = [scheduler.archive]
            if scheduler.result_archive is not scheduler.archive:
                archives.append(scheduler.result_archive)  # CMA-MAE's
            for archive in archives:
                archive.add(solutions.reshape(len(plans), -1), objective, measures)

    def _play(self, env: EpisodeRecorder, solutions: NDArray[np.float64]) -> list[EpisodeResult]:
        """Play the emitters' solutions, in order, each emitter's batch in its space."""
        if self.space != "mixed":
            decisions = solutions.reshape(len(solutions), env.horizon, self.decision_size)
            return env.evaluate_batch(list(decisions), self.n_workers, self.clear_path, self.space)
        results: list[EpisodeResult] = []
        spaces = searched_spaces(self.space)
        for start in range(0, len(solutions), self.batch_size):
            emitter = start // self.batch_size
            space = spaces[emitter % len(spaces)]
            batch = solutions[start : start + self.batch_size]
            decisions = batch.reshape(len(batch), env.horizon, self.decision_size)
            decisions = decisions[:, :, : DECISION_SIZES[space]]
            results += env.evaluate_batch(list(decisions), self.n_workers, self.clear_path, space)
        return results

    def _scheduler(self, env: EpisodeRecorder) -> Any:
        from ribs.archives import GridArchive
        from ribs.emitters import EvolutionStrategyEmitter
        from ribs.schedulers import Scheduler

        ranges = {
            **MEASURE_RANGES,
            "robot_speed": (0.0, env.simulation.robot_params.max_speed),
            "human_speed": (0.0, env.simulation.human_params.max_speed),
        }
        dimension = env.horizon * self.decision_size
        self.check_horizon(env.horizon)
        grid: dict[str, Any] = {"dims": self.bins, "ranges": [ranges[m] for m in self.measures]}
        self.archive = GridArchive(solution_dim=dimension, seed=self.seed, **grid)
        archive, ranker = self.archive, "2imp"
        if self.algorithm == "cma-mae":
            archive = GridArchive(
                solution_dim=dimension,
                learning_rate=self.learning_rate,
                threshold_min=0.0,
                seed=self.seed,
                **grid,
            )
            ranker = "imp"
        if self.algorithm == "map-elites":
            return Scheduler(archive, self._gaussian_emitters(archive, dimension))
        emitters = [
            EvolutionStrategyEmitter(
                archive,
                x0=np.zeros(dimension),
                sigma0=self.sigma0,
                ranker=ranker,
                es=self.es,
                # No bounds: CMA-ES would resample until a whole sequence lies in [-1, 1]; the
                # simulation clips every action instead, as it does for any tester.
                batch_size=self.batch_size,
                seed=self.seed * 1000 + index,
            )
            for index in range(self.emitters)
        ]
        result_archive = self.archive if archive is not self.archive else None
        return Scheduler(archive, emitters, result_archive=result_archive)

    def check_horizon(self, horizon: int) -> None:
        """Refuse episodes of ``horizon`` decisions when the emitters and the archive over
        their action sequences would not fit in :data:`MAX_STATE_BYTES` (a full covariance
        grows with the square of the sequence's length). A run's configuration calls it before
        the run starts.

        Raises:
            TesterParameterError: Naming the setting to change.
        """
        dimension = self.decision_size * horizon
        archives = 2 if self.algorithm == "cma-mae" else 1
        archive = archives * math.prod(self.bins) * (dimension + 8) * 8
        if self.algorithm == "map-elites" or self.es != "cma_es":
            per_emitter = 20 * dimension * 8  # a few vectors (lm_ma_es: a few dozen)
        else:
            per_emitter = 3 * dimension * dimension * 8  # covariance, eigenbasis, its inverse
        needed = archive + self.emitters * per_emitter
        if needed > MAX_STATE_BYTES:
            raise TesterParameterError(
                self.name,
                "es" if per_emitter > archive else "bins",
                f"episodes of {horizon:,} decisions make action sequences of "
                f"{dimension:,} numbers, for which {self.emitters} emitter(s) with "
                f"es={self.es!r} and {math.prod(self.bins):,} cells need "
                f"{needed / 1024**3:.1f} GiB (at most {MAX_STATE_BYTES / 1024**3:.0f}): use "
                "es='sep_cma_es', fewer cells, a longer decision period or shorter episodes",
            )

    def _gaussian_emitters(self, archive: Any, dimension: int) -> list[Any]:
        from ribs.emitters import GaussianEmitter

        rng = np.random.default_rng(self.seed)
        return [
            GaussianEmitter(
                archive,
                sigma=self.sigma0,
                initial_solutions=rng.uniform(-1.0, 1.0, (self.batch_size, dimension)),
                bounds=[(-1.0, 1.0)] * dimension,
                batch_size=self.batch_size,
                seed=self.seed * 1000 + index,
            )
            for index in range(self.emitters)
        ]

    def archive_table(self) -> pd.DataFrame:
        """The archive: one row per filled cell, its measures, objective (the episode's maximum
        risk) and the cell's index."""
        if self.archive is None:
            raise RuntimeError("tester 'qd': explore() before reading the archive")
        data = self.archive.data(["index", "objective", "measures"], return_type="pandas")
        table: pd.DataFrame = data.rename(
            columns={f"measures_{i}": name for i, name in enumerate(self.measures)}
        )
        return table

    def save(self, directory: Path) -> None:
        """The archive (``archive.parquet``) and the settings (``qd.json``)."""
        directory.mkdir(parents=True, exist_ok=True)
        self.archive_table().to_parquet(directory / "archive.parquet", index=False)
        settings = {
            "tester": self.name,
            "seed": self.seed,
            "algorithm": self.algorithm,
            "measures": self.measures,
            "bins": self.bins,
            "emitters": self.emitters,
            "batch_size": self.batch_size,
            "sigma0": self.sigma0,
            "learning_rate": self.learning_rate,
            "es": self.es,
            "clear_path": self.clear_path,
            "space": self.space,
            "probes": self.probes,
        }
        (directory / "qd.json").write_text(json.dumps(settings, indent=2) + "\n")
