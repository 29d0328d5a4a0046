"""Playing batches of whole episodes: the one evaluation loop of every episode-level searcher.

A searcher proposes :class:`Plan` s (a decision space and an episode's decisions in it); the
:class:`EpisodeEvaluator` plays them, here or on worker processes, and records each as the
run's next episode, in the order proposed. Every episode is deterministic, so the results do not
depend on how many workers play them.
"""

from __future__ import annotations

import multiprocessing
import os
import reprlib
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from types import TracebackType
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from hazardhunt.processes import die_with_parent
from hazardhunt.sim.simulation import EpisodeResult, Simulation, UnusableActionError
from hazardhunt.spec.episode import EpisodeSummary
from hazardhunt.sut.guard import notice_ctrl_c
from hazardhunt.testers.spaces import DecisionSpace

if TYPE_CHECKING:
    from hazardhunt.testers.base import EpisodeRecorder

MAX_WORKER_PROCESSES = 64
"""The most worker processes one run's tester may start (PPO's ``n_envs``, the searchers'
``workers``): each holds a simulation and its own interpreter, some hundred MiB."""


@dataclass(frozen=True)
class Plan:
    """One episode as a searcher proposes it."""

    space: DecisionSpace
    """How the decisions are read."""
    decisions: NDArray[np.float64]
    """Shape (up to ``horizon``, ``space.size``): the episode's decisions, in [-1, 1]."""


def unusable_decisions(plan: Plan) -> str | None:
    """What is wrong with ``plan``'s decisions, if they are not all finite numbers (the
    actions they make would not be either); None if they are."""
    try:
        finite = bool(np.isfinite(np.asarray(plan.decisions, dtype=np.float64)).all())
    except (TypeError, ValueError):
        finite = False
    if finite:
        return None
    return f"proposed decisions that are not all finite numbers ({reprlib.repr(plan.decisions)})"


SimulationSource = Simulation | Callable[[], Simulation]
"""A simulation, or what builds one in a worker process."""


class EpisodeEvaluator:
    """Plays plans and records them through an :class:`EpisodeRecorder`; owns the workers.

    Use it as a context manager, or call :meth:`close`, so that the worker processes end with
    the search.
    """

    def __init__(self, recorder: EpisodeRecorder, workers: int = 1) -> None:
        """Args:
        recorder: Records every episode played as the run's next one; its simulation plays
            them here, and its ``simulation_factory`` (else a pickled copy of the simulation)
            builds the workers' copies.
        workers: Worker processes that play a batch at once (1: in this process).
        """
        self.recorder = recorder
        self.workers = workers
        self._pool: ProcessPoolExecutor | None = None

    def evaluate(self, plans: Sequence[Plan]) -> list[EpisodeResult]:
        """Play ``plans`` and record them, in order, as the run's next episodes.

        Raises:
            UnusableActionError: A plan's decisions are not all finite numbers (none is
                played).
        """
        unusable = next(filter(None, map(unusable_decisions, plans)), None)
        if unusable is not None:
            raise UnusableActionError(unusable)
        if self.workers <= 1 or len(plans) <= 1:
            simulation, keep = self.recorder.simulation, self.recorder.keep_trajectory
            results = [plan.space.play(simulation, plan.decisions, keep) for plan in plans]
        else:
            results = list(self._workers().map(_play_in_worker, plans))
        for result in results:
            self.recorder.record(result)
        return results

    def _workers(self) -> ProcessPoolExecutor:
        if self._pool is None:
            source = self.recorder.simulation_factory or self.recorder.simulation
            self._pool = ProcessPoolExecutor(
                max_workers=self.workers,
                mp_context=multiprocessing.get_context("spawn"),
                initializer=_start_worker,
                initargs=(os.getpid(), source, self.recorder.keep_trajectory),
            )
        return self._pool

    def close(self) -> None:
        """Stop the worker processes, if any."""
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)
            self._pool = None

    def __enter__(self) -> EpisodeEvaluator:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()


# A worker process's simulation, built once when the process starts; one per process.
_worker: tuple[Simulation, Callable[[EpisodeSummary], bool]] | None = None


def _start_worker(
    parent_pid: int, source: SimulationSource, keep: Callable[[EpisodeSummary], bool]
) -> None:
    """Build the worker's simulation; the worker dies with the run's process (a run killed
    with SIGKILL leaves no worker behind)."""
    global _worker
    die_with_parent(parent_pid)
    notice_ctrl_c()
    _worker = (source if isinstance(source, Simulation) else source(), keep)


def _play_in_worker(plan: Plan) -> EpisodeResult:
    assert _worker is not None, "the worker was not started with a simulation"
    simulation, keep = _worker
    return plan.space.play(simulation, plan.decisions, keep)
