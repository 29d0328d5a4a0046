"""What every search method implements, and the env wrapper that records each episode."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from hazardhunt.env.agv import AGVEnv
from hazardhunt.spec.rewards import RewardKind


@dataclass(frozen=True)
class EpisodeRecord:
    """One finished episode, as the run stores it."""

    index: int
    """Position of the episode in the run, from 0."""
    summary: dict[str, Any]
    """The env's episode summary (outcome, return, maximum risk, ...)."""
    actions: NDArray[np.float32]
    """Shape (decision steps, 2): the actions the env received, enough to replay it."""
    trajectory: list[dict[str, Any]]
    """The env's trajectory (kept for failures; empty otherwise)."""


class EpisodeRecorder(gym.Wrapper[Any, Any, Any, Any]):
    """Hands every finished episode to ``on_episode`` and counts them.

    Testers drive this wrapper and stop once ``episodes_done`` reaches their budget.
    """

    def __init__(
        self,
        env: gym.Env[Any, Any],
        on_episode: Callable[[EpisodeRecord], None],
        keep_trajectory: Callable[[dict[str, Any]], bool] = lambda summary: (
            summary["outcome"] == "failure"
        ),
    ) -> None:
        super().__init__(env)
        self.on_episode = on_episode
        self.keep_trajectory = keep_trajectory
        self.episodes_done = 0

    @property
    def agv(self) -> AGVEnv:
        """The AGV environment underneath."""
        env = self.env.unwrapped
        assert isinstance(env, AGVEnv)
        return env

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        if terminated or truncated:
            self.record(*finished_episode(self.agv, info, self.keep_trajectory))
        return observation, float(reward), terminated, truncated, info

    def record(
        self,
        summary: dict[str, Any],
        actions: NDArray[np.float32],
        trajectory: list[dict[str, Any]],
    ) -> None:
        """Hand a finished episode to ``on_episode`` as the run's next one (also for episodes
        that copies of the env ran in worker processes)."""
        record = EpisodeRecord(self.episodes_done, summary, actions, trajectory)
        self.episodes_done += 1
        self.on_episode(record)


def finished_episode(
    agv: AGVEnv, info: dict[str, Any], keep_trajectory: Callable[[dict[str, Any]], bool]
) -> tuple[dict[str, Any], NDArray[np.float32], list[dict[str, Any]]]:
    """Summary, actions and (when ``keep_trajectory`` says so) trajectory of the episode that
    ``agv`` has just ended with ``info``."""
    summary = info["summary"]
    trajectory = agv.trajectory() if keep_trajectory(summary) else []
    return summary, agv.episode_actions, trajectory


@runtime_checkable
class Tester(Protocol):
    """A search method: chooses the human's actions, episode after episode, within a budget."""

    name: str
    """The tester's name (``random``, ``ppo-acc``, ...)."""
    reward: RewardKind
    """The reward the env gives it."""

    def explore(self, env: EpisodeRecorder, episodes: int) -> None:
        """Drive ``env`` until ``env.episodes_done`` reaches ``episodes``, then return.

        The first reset must pass the run's seed; later resets need none (the env is
        deterministic). Learning testers keep learning for the whole budget.
        """
        ...

    def save(self, directory: Path) -> None:
        """Write whatever the tester learned (e.g. a policy checkpoint) into ``directory``."""
        ...
