"""What every search method implements, and the recorder that makes each episode the run's."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, TypeGuard, runtime_checkable

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from hazardhunt.env.agv import AGVEnv
from hazardhunt.errors import InputError
from hazardhunt.sim.simulation import Action, EpisodeResult, Policy, Simulation
from hazardhunt.spec.episode import EpisodeSummary
from hazardhunt.spec.rewards import RewardKind
from hazardhunt.testers.evaluator import MAX_WORKER_PROCESSES as MAX_WORKER_PROCESSES
from hazardhunt.testers.evaluator import EpisodeEvaluator, Plan
from hazardhunt.testers.objective import CONTACT, Objective
from hazardhunt.testers.spaces import DECISION_KINDS, DecisionSpace


class TesterParameterError(InputError):
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
        self.objective: Objective = CONTACT
        """What an episode-level search looks for (the run's ``search_on``)."""
        self.episodes_done = 0
        self._evaluator: EpisodeEvaluator | None = None

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

        Kept for testers written before the
        :class:`~hazardhunt.testers.evaluator.EpisodeEvaluator`, which a tester should use
        instead.

        Args:
            sequences: Each up to :attr:`horizon` decisions in ``space``.
            workers: Worker processes that play the batch at once (kept for the recorder's life).
            clear_path: The decision space's ``detour``.
            space: The decision space's kind: ``open``, ``aim``, ``route`` or ``ambush``.
        """
        if space not in DECISION_KINDS:
            raise ValueError(f"unknown search space {space!r}: one of {', '.join(DECISION_KINDS)}")
        if self._evaluator is None or self._evaluator.workers != workers:
            self.close_pool()
            self._evaluator = EpisodeEvaluator(self, workers)
        decision_space = DecisionSpace(space, clear_path)
        plans = [Plan(decision_space, np.asarray(decisions)) for decisions in sequences]
        return self._evaluator.evaluate(plans)

    def close_pool(self) -> None:
        """Stop the worker processes of :meth:`evaluate_batch`, if any."""
        if self._evaluator is not None:
            self._evaluator.close()
            self._evaluator = None

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


def reward_of(tester: Tester) -> RewardKind:
    """The reward the env gives ``tester``: its own ``reward``, else the maximum reward."""
    reward: RewardKind = getattr(tester, "reward", "max")
    return reward
