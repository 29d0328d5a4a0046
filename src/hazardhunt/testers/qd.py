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

pyribs compiles its evolution strategies' helpers with numba, about 3 s in every process that
uses them (every ``hazardhunt run``, each worker of a campaign); :func:`compile_once` keeps
them in numba's cache on disk, so that they are compiled once per machine and loaded after:
the same machine code, so the same numbers. It also loads pyribs without torch, which pyribs
imports only to accept torch's tensors (never passed here) and which would add 1.3 s to the
start of every such process.
"""

from __future__ import annotations

import contextlib
import functools
import math
import sys
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pandas as pd
from numpy.typing import NDArray
from pydantic import Field, model_validator

from hazardhunt.sim.simulation import EpisodeResult
from hazardhunt.spec.descriptors import MEASURE_NAMES, MEASURE_RANGES, measures_of
from hazardhunt.testers.base import TesterParameterError
from hazardhunt.testers.evaluator import Plan
from hazardhunt.testers.search import SearchContext, SearchTester, SpaceParams

MAX_CELLS = 1_000_000
"""The most cells of the archive, which allocates them all at the start."""
MAX_EMITTERS = 100
"""The most emitters (each keeps a CMA-ES state over the whole action sequence)."""
MAX_BATCH = 10_000
"""The most episodes an emitter asks for at once."""
DEFAULT_MEASURES = ("bearing", "robot_speed", "emergency_stop")
"""The archive's axes unless ``measures`` says otherwise."""
MAX_STATE_BYTES = 2 * 1024**3
"""The most memory the emitters' states and the archive may take; beyond it a run is refused
before it starts rather than killed for memory once it has."""


class QualityDiversityParams(SpaceParams):
    """Quality-diversity search's settings."""

    measures: tuple[str, ...] = DEFAULT_MEASURES
    """The entries that span the archive (of ``bearing``, ``robot_speed``, ``emergency_stop``,
    ``route_share``, ``human_speed``; :mod:`hazardhunt.spec.descriptors`)."""
    bins: tuple[int, ...] = (8, 3, 3)
    """Cells along each measure."""
    algorithm: Literal["cma-me", "cma-mae", "map-elites"] = "cma-me"
    """``cma-me``, ``cma-mae``, or ``map-elites`` (Gaussian mutation of archive elites, started
    from uniformly random sequences)."""
    emitters: int = Field(default=2, ge=1, le=MAX_EMITTERS)
    """Emitters (CMA-ES ones, or Gaussian ones for ``map-elites``); with a ``mixed`` space they
    take the decision spaces in turn (the first ``open``, the second ``aim``, ...)."""
    batch_size: int = Field(default=10, ge=1, le=MAX_BATCH)
    """Episodes each emitter asks for per iteration."""
    initial_spread: float = Field(default=0.6, gt=0.0, allow_inf_nan=False)
    """The emitters' initial step size, or the mutation's spread for ``map-elites``
    (``sigma0`` in earlier versions)."""
    learning_rate: float = Field(default=0.02, gt=0.0, le=1.0, allow_inf_nan=False)
    """CMA-MAE's archive learning rate (``cma-mae`` only)."""
    es: Literal["cma_es", "sep_cma_es", "lm_ma_es"] = "cma_es"
    """The emitters' evolution strategy: ``cma_es`` (a full covariance over the whole
    sequence, memory growing with its square), ``sep_cma_es`` (diagonal) or ``lm_ma_es``
    (limited memory), for long episodes with many decisions."""

    @model_validator(mode="before")
    @classmethod
    def _lists(cls, data: Any) -> Any:
        """A file's lists are the tuples of the model."""
        if isinstance(data, dict):
            return {k: tuple(v) if isinstance(v, list) else v for k, v in data.items()}
        return data

    @model_validator(mode="after")
    def _grid(self) -> QualityDiversityParams:
        known = set(self.measures) <= set(MEASURE_NAMES)
        if not (known and len(set(self.measures)) == len(self.measures) > 0):
            raise ValueError(f"measures: must be distinct names of {', '.join(MEASURE_NAMES)}")
        if len(self.bins) != len(self.measures) or math.prod(self.bins) > MAX_CELLS:
            raise ValueError(
                f"bins: must be one whole number >= 1 per measure, at most {MAX_CELLS:,} cells "
                "in all"
            )
        if any(b < 1 for b in self.bins):
            raise ValueError("bins: must be one whole number >= 1 per measure")
        return self


def import_ribs() -> None:
    """Import pyribs' archives, emitters and schedulers, without torch unless the process has
    it already: pyribs imports torch where it can, to accept torch's tensors and for archives
    hazardhunt does not use; a process that needs torch later (PPO) imports it as usual."""
    if "ribs" in sys.modules or "torch" in sys.modules:
        return
    sys.meta_path.insert(0, _WithoutTorch)
    try:
        import ribs.archives
        import ribs.emitters
        import ribs.schedulers  # noqa: F401
    finally:
        sys.meta_path.remove(_WithoutTorch)


class _WithoutTorch:
    """An import finder under which torch is not installed."""

    @staticmethod
    def find_spec(name: str, path: object = None, target: object = None) -> None:
        if name == "torch" or name.startswith("torch."):
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)


@functools.cache
def compile_once() -> None:
    """Load pyribs (:func:`import_ribs`) and keep the numba-compiled helpers of its evolution
    strategies in numba's cache on disk (beside their source, or in the user's cache where that
    cannot be written); where neither can, or a pyribs version has none, they are compiled in
    each process as before."""
    import_ribs()
    from numba.core.dispatcher import Dispatcher
    from ribs.emitters import opt

    strategies = (
        getattr(opt, name, None)
        for name in (
            "CMAEvolutionStrategy",
            "SeparableCMAEvolutionStrategy",
            "LMMAEvolutionStrategy",
        )
    )
    for strategy in strategies:
        for attribute in vars(strategy).values() if strategy is not None else ():
            function = getattr(attribute, "__func__", attribute)  # a staticmethod's function
            if isinstance(function, Dispatcher):
                with contextlib.suppress(RuntimeError):  # no cache directory can be written
                    function.enable_caching()


class QualityDiversitySampler:
    """pyribs' scheduler over the human's decision sequences; with a ``mixed`` space, one
    archive that every decision space fills."""

    def __init__(self, params: QualityDiversityParams, context: SearchContext) -> None:
        self.params = params
        self.objective = context.objective
        self.seed = context.seed
        self.horizon = context.horizon
        self.spaces = params.space.decision_spaces
        self.decision_size = params.space.largest_size
        self.scheduler = self._scheduler(context)
        self.archive: Any = self.scheduler.result_archive
        # The plain attacks of each space first, one batch each, into the archive(s).
        self._attacks = list(self.spaces) if params.space.plain_attacks else []
        self._asked: NDArray[np.float64] | None = None
        self._attacking = False

    def ask(self) -> list[Plan]:
        if self._attacks:
            space = self._attacks.pop(0)
            attacks = space.plain_attacks(self.horizon)
            solutions = np.zeros((len(attacks), self.horizon, self.decision_size))
            solutions[:, :, : space.size] = attacks
            self._asked, self._attacking = solutions.reshape(len(attacks), -1), True
            return [Plan(space, plan) for plan in attacks]
        self._asked, self._attacking = self.scheduler.ask(), False
        decisions = self._asked.reshape(len(self._asked), self.horizon, self.decision_size)
        batch = self.params.batch_size
        # Each emitter's batch in its decision space, the emitters taking the spaces in turn.
        return [
            Plan(space, sequence[:, : space.size])
            for index, sequence in enumerate(decisions)
            for space in (self.spaces[(index // batch) % len(self.spaces)],)
        ]

    def tell(self, plans: list[Plan], results: list[EpisodeResult]) -> None:
        assert self._asked is not None, "tell() before ask()"
        names = self.params.measures
        objective = [self.objective.score(result) for result in results]
        measures = [measures_of(result.summary, names) for result in results]
        solutions = self._asked[: len(results)]
        if self._attacking or len(results) < len(self._asked):
            # Not the emitters' batch, or the budget ended within it: into the archive(s).
            archives = {id(a): a for a in (self.scheduler.archive, self.archive)}
            for archive in archives.values():
                archive.add(solutions, objective, measures)
        else:
            self.scheduler.tell(objective, measures)

    def record(self) -> dict[str, Any]:
        return {"cells_filled": len(self.archive)}

    def archive_table(self) -> pd.DataFrame:
        """The archive: one row per filled cell, its measures, objective (the episode's
        maximum risk) and the cell's index."""
        data = self.archive.data(["index", "objective", "measures"], return_type="pandas")
        table: pd.DataFrame = data.rename(
            columns={f"measures_{i}": name for i, name in enumerate(self.params.measures)}
        )
        return table

    def _scheduler(self, context: SearchContext) -> Any:
        compile_once()
        from ribs.archives import GridArchive
        from ribs.emitters import EvolutionStrategyEmitter
        from ribs.schedulers import Scheduler

        params, seed = self.params, self.seed
        ranges = {
            **MEASURE_RANGES,
            "robot_speed": (0.0, context.simulation.robot_params.max_speed),
            "human_speed": (0.0, context.simulation.human_params.max_speed),
        }
        dimension = self.horizon * self.decision_size
        grid: dict[str, Any] = {
            "dims": list(params.bins),
            "ranges": [ranges[m] for m in params.measures],
        }
        result_archive = GridArchive(solution_dim=dimension, seed=seed, **grid)
        archive, ranker = result_archive, "2imp"
        if params.algorithm == "cma-mae":
            archive = GridArchive(
                solution_dim=dimension,
                learning_rate=params.learning_rate,
                threshold_min=0.0,
                seed=seed,
                **grid,
            )
            ranker = "imp"
        if params.algorithm == "map-elites":
            return Scheduler(archive, self._gaussian_emitters(archive, dimension))
        emitters = [
            EvolutionStrategyEmitter(
                archive,
                x0=np.zeros(dimension),
                sigma0=params.initial_spread,
                ranker=ranker,
                es=params.es,
                # No bounds: CMA-ES would resample until a whole sequence lies in [-1, 1]; the
                # simulation clips every action instead, as it does for any tester.
                batch_size=params.batch_size,
                seed=seed * 1000 + index,
            )
            for index in range(params.emitters)
        ]
        separate = result_archive if archive is not result_archive else None
        return Scheduler(archive, emitters, result_archive=separate)

    def _gaussian_emitters(self, archive: Any, dimension: int) -> list[Any]:
        from ribs.emitters import GaussianEmitter

        params = self.params
        rng = np.random.default_rng(self.seed)
        return [
            GaussianEmitter(
                archive,
                sigma=params.initial_spread,
                initial_solutions=rng.uniform(-1.0, 1.0, (params.batch_size, dimension)),
                bounds=[(-1.0, 1.0)] * dimension,
                batch_size=params.batch_size,
                seed=self.seed * 1000 + index,
            )
            for index in range(params.emitters)
        ]


class QualityDiversityTester(SearchTester):
    """CMA-ME / CMA-MAE emitters over an archive of failure descriptors."""

    name = "qd"
    params_model = QualityDiversityParams
    params: QualityDiversityParams
    sampler: QualityDiversitySampler | None

    def make_sampler(self, context: SearchContext) -> QualityDiversitySampler:
        self.check_horizon(context.horizon)
        return QualityDiversitySampler(self.params, context)

    def check_horizon(self, horizon: int) -> None:
        """Refuse episodes of ``horizon`` decisions when the emitters and the archive over
        their decision sequences would not fit in :data:`MAX_STATE_BYTES` (a full covariance
        grows with the square of the sequence's length). A run's configuration calls it before
        the run starts.

        Raises:
            TesterParameterError: Naming the setting to change.
        """
        params = self.params
        dimension = params.space.largest_size * horizon
        archives = 2 if params.algorithm == "cma-mae" else 1
        archive = archives * math.prod(params.bins) * (dimension + 8) * 8
        if params.algorithm == "map-elites" or params.es != "cma_es":
            per_emitter = 20 * dimension * 8  # a few vectors (lm_ma_es: a few dozen)
        else:
            per_emitter = 3 * dimension * dimension * 8  # covariance, eigenbasis, its inverse
        needed = archive + params.emitters * per_emitter
        if needed > MAX_STATE_BYTES:
            raise TesterParameterError(
                self.name,
                "es" if per_emitter > archive else "bins",
                f"episodes of {horizon:,} decisions make action sequences of "
                f"{dimension:,} numbers, for which {params.emitters} emitter(s) with "
                f"es={params.es!r} and {math.prod(params.bins):,} cells need "
                f"{needed / 1024**3:.1f} GiB (at most {MAX_STATE_BYTES / 1024**3:.0f}): use "
                "es='sep_cma_es', fewer cells, a longer decision period or shorter episodes",
            )

    def archive_table(self) -> pd.DataFrame:
        """The archive of the last search (:meth:`QualityDiversitySampler.archive_table`)."""
        if self.sampler is None:
            raise RuntimeError("tester 'qd': explore() before reading the archive")
        return self.sampler.archive_table()

    def save(self, directory: Path) -> None:
        """The archive (``archive.parquet``) and the settings (``qd.json``)."""
        super().save(directory)
        self.archive_table().to_parquet(directory / "archive.parquet", index=False)
