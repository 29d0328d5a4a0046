"""What every search method implements, and the recorder that makes each episode the run's."""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, TypeGuard, runtime_checkable

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from hazardhunt.env.agv import AGVEnv
from hazardhunt.sim.simulation import Action, EpisodeResult, Policy, Simulation
from hazardhunt.spec.episode import EpisodeSummary
from hazardhunt.spec.rewards import RewardKind
from hazardhunt.testers.spaces import play_in_space

MAX_WORKER_PROCESSES = 64
"""The most worker processes one run's tester may start (PPO's ``n_envs``, the searchers'
``n_workers``): each holds a simulation and its own interpreter, some hundred MiB."""


class TesterParameterError(ValueError):
    """A tester parameter the tester does not take, or a value it cannot use; ``key`` names the
    parameter and ``problem`` says what is wrong with it."""

    def __init__(self, tester: str, key: str, problem: str) -> None:
        super().__init__(f"tester {tester!r}: {key}: {problem}")
        self.tester = tester
        self.key = key
        self.problem = problem


def is_whole_number(value: object) -> TypeGuard[int]:
    """Whether ``value`` is an int (a bool is not)."""
    return isinstance(value, int) and not isinstance(value, bool)


def check_parameters(tester: str, checks: Mapping[str, tuple[object, str, bool]]) -> None:
    """Raise for the first parameter whose check failed.

    Args:
        tester: The tester's name, for the message.
        checks: Per parameter: its value, what it must be (``"> 0"``), whether it is.

    Raises:
        TesterParameterError: A value is not what it must be, naming the key.
    """
    for key, (value, wanted, ok) in checks.items():
        if not ok:
            raise TesterParameterError(tester, key, f"must be {wanted}, not {value!r}")


@dataclass(frozen=True)
class EpisodeRecord:
    """One finished episode, as the run stores it."""

    episode: int
    """Position of the episode in the run, from 0."""
    result: EpisodeResult
    """What the episode amounts to, and the actions that replay it (its trajectory is kept
    for failures only)."""


def is_failure(summary: EpisodeSummary) -> bool:
    """Whether an episode ended in an unsafe contact: the episodes whose trajectory is kept."""
    return summary.outcome == "failure"


class EpisodeRecorder(gym.Wrapper[Any, Any, Any, Any]):
    """Hands every finished episode to ``on_episode`` and counts them.

    It wraps an :class:`~hazardhunt.env.agv.AGVEnv` (or a wrapper of one).

    A learning tester steps this wrapper like any Gymnasium env; an episode-level tester plays
    whole episodes with :meth:`evaluate`. Either stops once ``episodes_done`` reaches its
    budget.
    """

    def __init__(
        self,
        env: gym.Env[Any, Any],
        on_episode: Callable[[EpisodeRecord], None],
        keep_trajectory: Callable[[EpisodeSummary], bool] = is_failure,
        simulation_factory: Callable[[], Simulation] | None = None,
    ) -> None:
        """Args:
        env: The environment (an AGVEnv, or a wrapper of one).
        on_episode: Called with every finished episode.
        keep_trajectory: Which episodes keep their trajectory (failures).
        simulation_factory: Builds a copy of the simulation in a worker process (a picklable
            callable: a run passes one that rebuilds it from the run's configuration, so that
            a plug-in found only on the run's search path loads there too); without it,
            workers receive a pickled copy of the simulation.
        """
        super().__init__(env)
        self.on_episode = on_episode
        self.keep_trajectory = keep_trajectory
        self.simulation_factory = simulation_factory
        self.episodes_done = 0
        self._pool: ProcessPoolExecutor | None = None
        self._pool_size = 0

    @property
    def simulation(self) -> Simulation:
        """The simulation underneath."""
        env = self.env.unwrapped
        assert isinstance(env, AGVEnv)
        return env.simulation

    @property
    def horizon(self) -> int:
        """Decisions in an episode that runs its full duration: the length of an action
        sequence for :meth:`evaluate`."""
        return self.simulation.horizon

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        if terminated or truncated:
            self.record(self.simulation.result(self.keep_trajectory))
        return observation, float(reward), terminated, truncated, info

    def evaluate(
        self, actions: Sequence[Action] | NDArray[np.floating[Any]] | Policy
    ) -> EpisodeResult:
        """Play one episode from the scenario's start and record it as the run's next one.

        Args:
            actions: Up to :attr:`horizon` normalised actions, played open loop (an episode
                still going when they run out is recorded as it stands, outcome None), or a
                policy that chooses each action from the simulation's state.
        """
        result = self.simulation.simulate(actions, self.keep_trajectory)
        self.record(result)
        return result

    def evaluate_batch(
        self,
        sequences: Sequence[NDArray[np.floating[Any]]],
        workers: int = 1,
        clear_path: bool = False,
        space: str = "open",
    ) -> list[EpisodeResult]:
        """Play whole episodes' decisions and record them, in order, as the run's next episodes.

        Args:
            sequences: Each up to :attr:`horizon` decisions in ``space``: normalised actions
                played open loop by default.
            workers: Worker processes that play the batch at once, each with its own copy of
                the simulation (kept for the recorder's life); 1 plays it here. The results do
                not depend on it: every episode is deterministic.
            clear_path: Whether each action that would walk the human into a static obstacle
                is replaced by the nearest one that does not, as it is played
                (:func:`~hazardhunt.testers.clear_path.clear_action`).
            space: What a decision's numbers mean (:mod:`hazardhunt.testers.spaces`):
                ``open``, ``aim`` or ``route``.
        """
        arrays = [np.asarray(a) for a in sequences]
        if workers <= 1 or len(arrays) <= 1:
            keep = self.keep_trajectory
            results = [play_in_space(self.simulation, a, space, keep, clear_path) for a in arrays]
        else:
            if self._pool is None or self._pool_size != workers:
                self.close_pool()
                source = self.simulation_factory or self.simulation
                self._pool = _episode_pool(source, self.keep_trajectory, workers)
                self._pool_size = workers
            count = len(arrays)
            results = list(
                self._pool.map(_play_in_worker, arrays, [clear_path] * count, [space] * count)
            )
        for result in results:
            self.record(result)
        return results

    def close_pool(self) -> None:
        """Stop the worker processes of :meth:`evaluate_batch`, if any."""
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)
            self._pool = None

    def close(self) -> None:
        self.close_pool()
        super().close()

    def record(self, result: EpisodeResult) -> None:
        """Hand a finished episode to ``on_episode`` as the run's next one (also for episodes
        that copies of the env ran in worker processes)."""
        record = EpisodeRecord(self.episodes_done, result)
        self.episodes_done += 1
        self.on_episode(record)


@runtime_checkable
class Tester(Protocol):
    """A search method: chooses the human's actions, episode after episode, within a budget.

    A tester that learns from the env's per-step reward also declares ``reward`` (``acc`` or
    ``max``); without it the env gives the maximum reward, which episode-level searchers,
    which score whole episodes, do not read.
    """

    name: str
    """The tester's name (``random``, ``ppo-acc``, ...)."""

    def explore(self, env: EpisodeRecorder, episodes: int) -> None:
        """Drive ``env`` until ``env.episodes_done`` reaches ``episodes``, then return.

        Step it as a Gymnasium env (the first reset passes the run's seed) or play whole
        episodes with ``env.evaluate``. Learning testers keep learning for the whole budget.
        """
        ...

    def save(self, directory: Path) -> None:
        """Write whatever the tester learned (e.g. a policy checkpoint) into ``directory``."""
        ...


# The worker's simulation: a spawned process receives it once, at start-up.
_worker_simulation: tuple[Simulation, Callable[[EpisodeSummary], bool]] | None = None


SimulationSource = Simulation | Callable[[], Simulation]
"""A simulation, or what builds one in a worker process."""


def _episode_pool(
    source: SimulationSource, keep_trajectory: Callable[[EpisodeSummary], bool], workers: int
) -> ProcessPoolExecutor:
    return ProcessPoolExecutor(
        max_workers=workers,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=_start_worker,
        initargs=(source, keep_trajectory),
    )


def _start_worker(source: SimulationSource, keep: Callable[[EpisodeSummary], bool]) -> None:
    global _worker_simulation
    simulation = source if isinstance(source, Simulation) else source()
    _worker_simulation = (simulation, keep)


def _play_in_worker(
    decisions: NDArray[np.floating[Any]], clear_path: bool, space: str
) -> EpisodeResult:
    assert _worker_simulation is not None, "the worker was not started with a simulation"
    simulation, keep = _worker_simulation
    return play_in_space(simulation, decisions, space, keep, clear_path)


def reward_of(tester: Tester) -> RewardKind:
    """The reward the env gives ``tester``: its own ``reward``, else the maximum reward."""
    reward: RewardKind = getattr(tester, "reward", "max")
    return reward
