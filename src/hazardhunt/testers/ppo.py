"""The study's learning tester: Stable-Baselines3 PPO, learning for the whole budget.

The failures PPO runs into while it learns are the result; the final policy is a by-product,
saved for inspection. Hyper-parameters are SB3's defaults (as the study) unless the campaign
file overrides them.
"""

from __future__ import annotations

import inspect
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvStepReturn

from hazardhunt.env.agv import AGVEnv
from hazardhunt.spec.episode import EpisodeSummary
from hazardhunt.spec.rewards import RewardKind
from hazardhunt.testers.base import EpisodeRecorder
from hazardhunt.testers.novelty import FailureArchive

NOVELTY_CAP = 1.5
"""The largest descriptor distance the bonus pays for (the first failure's is infinite)."""

RESERVED_PARAMETERS = frozenset({"policy", "env", "seed", "device", "verbose", "_init_setup_model"})
"""PPO arguments the tester sets itself: the run owns the env and the seed, and SPEC fixes
the policy (``MlpPolicy``) and the device (CPU, for reproducible runs)."""


TESTER_PARAMETERS = {
    "n_envs": "copies of the environment stepped at once, each in its own worker process "
    "(SB3's SubprocVecEnv); PPO collects n_steps decisions from each before it updates "
    "(default 1: one env in the run's process)",
    "novelty": "weight of the dissimilarity bonus: an episode that ends in a failure earns "
    "novelty x its mean descriptor distance to the k nearest failures found before it "
    "(capped at NOVELTY_CAP; default 0: no bonus; ppo-novelty: 100)",
    "novelty_neighbours": "the k of the bonus (default 3)",
}
"""Parameters of the tester itself, next to PPO's own."""


def ppo_defaults() -> dict[str, Any]:
    """SB3's default PPO hyper-parameters, by keyword, without the reserved ones."""
    return {
        name: parameter.default
        for name, parameter in inspect.signature(PPO.__init__).parameters.items()
        if parameter.default is not inspect.Parameter.empty and name not in RESERVED_PARAMETERS
    }


class StopAtEpisodeBudget(BaseCallback):
    """Stops learning as soon as the recorder has seen ``episodes`` episodes."""

    def __init__(self, recorder: EpisodeRecorder, episodes: int) -> None:
        super().__init__()
        self.recorder = recorder
        self.episodes = episodes

    def _on_step(self) -> bool:
        # Called after every env step, and a step ends at most one episode: stopping here
        # records exactly the budget.
        return self.recorder.episodes_done < self.episodes


class PPOTester:
    """PPO with an ``MlpPolicy`` that learns from the accumulated or the maximum reward."""

    def __init__(
        self, name: str, reward: RewardKind, seed: int, params: dict[str, Any] | None = None
    ) -> None:
        """Args:
        name: The tester's name (``ppo-acc`` or ``ppo-max``).
        reward: The reward the env gives (``acc`` or ``max``).
        seed: Seeds the policy's initialisation, its action sampling and the env's first reset.
        params: Keyword arguments of SB3's ``PPO`` overriding its defaults (``n_steps``,
            ``learning_rate``, ...).

        Raises:
            ValueError: A key of ``params`` is no PPO argument or one the tester sets itself.
        """
        params = dict(params or {})
        n_envs = params.pop("n_envs", 1)
        if isinstance(n_envs, bool) or not isinstance(n_envs, int) or n_envs < 1:
            raise ValueError(f"tester {name!r}: n_envs must be a whole number >= 1, not {n_envs!r}")
        novelty = params.pop("novelty", 0.0)
        neighbours = params.pop("novelty_neighbours", 3)
        if isinstance(novelty, bool) or not isinstance(novelty, (int, float)) or novelty < 0:
            raise ValueError(f"tester {name!r}: novelty must be a number >= 0, not {novelty!r}")
        if isinstance(neighbours, bool) or not isinstance(neighbours, int) or neighbours < 1:
            raise ValueError(
                f"tester {name!r}: novelty_neighbours must be a whole number >= 1, "
                f"not {neighbours!r}"
            )
        defaults = ppo_defaults()
        for key in params:
            if key in RESERVED_PARAMETERS:
                raise ValueError(
                    f"tester {name!r}: parameter {key!r} is set by hazardhunt and cannot be "
                    "overridden"
                )
            if key not in defaults:
                raise ValueError(
                    f"tester {name!r}: unknown parameter {key!r}; "
                    f"PPO accepts {', '.join(sorted(defaults))}; the tester accepts "
                    f"{', '.join(TESTER_PARAMETERS)}"
                )
        self.name = name
        self.reward: RewardKind = reward
        self.seed = seed
        self.params = params
        self.n_envs = n_envs
        self.novelty = float(novelty)
        self.novelty_neighbours = neighbours
        self.hyperparameters = defaults | params
        """The effective PPO arguments (defaults overridden by ``params``)."""
        self.model: PPO | None = None

    def explore(self, env: EpisodeRecorder, episodes: int) -> None:
        """Learn on ``env`` until it has recorded ``episodes`` episodes.

        Each call starts a fresh policy. SB3 seeds the env's first reset with ``seed`` and
        resets it unseeded after every episode. With ``n_envs`` > 1, copies of ``env`` run in
        worker processes and their episodes are recorded in the order they end (by env index
        within one step); episodes beyond the budget that end in the last step are dropped.
        """
        # SPEC 9: one thread per process; more only contend with the NMPC and other runs.
        torch.set_num_threads(1)
        learning_env: gym.Env[Any, Any] | VecEnv = env
        if self.n_envs > 1:
            learning_env = RecordingVecEnv(env, self.n_envs, episodes)
        if self.novelty > 0:
            if not isinstance(learning_env, VecEnv):
                learning_env = DummyVecEnv([lambda: env])
            learning_env = NoveltyBonus(learning_env, self.novelty, self.novelty_neighbours)
        try:
            self.model = PPO(
                "MlpPolicy",
                learning_env,
                seed=self.seed,
                device="cpu",
                verbose=0,
                **self.params,
            )
            # SB3 needs a length; this bound (every episode timing out) is never reached
            # because the callback ends learning at the episode budget.
            self.model.learn(
                total_timesteps=episodes * env.horizon,
                callback=StopAtEpisodeBudget(env, episodes),
            )
        finally:
            if isinstance(learning_env, VecEnv):
                learning_env.close()
        if env.episodes_done != episodes:
            raise RuntimeError(
                f"tester {self.name!r} recorded {env.episodes_done} episodes, not {episodes}"
            )

    def save(self, directory: Path) -> None:
        """Write the policy (``ppo.zip``, loadable with ``PPO.load``) and the effective
        hyper-parameters (``hyperparameters.json``) into ``directory``.

        Raises:
            RuntimeError: Nothing has been learned yet (call :meth:`explore` first).
        """
        if self.model is None:
            raise RuntimeError(f"tester {self.name!r}: explore() before save()")
        directory.mkdir(parents=True, exist_ok=True)
        self.model.save(directory / "ppo.zip")
        settings = {
            "tester": self.name,
            "reward": self.reward,
            "policy": "MlpPolicy",
            "seed": self.seed,
            "device": "cpu",
            "n_envs": self.n_envs,
            "novelty": self.novelty,
            "novelty_neighbours": self.novelty_neighbours,
            "timesteps": self.model.num_timesteps,
            **self.hyperparameters,
        }
        (directory / "hyperparameters.json").write_text(
            json.dumps(settings, indent=2, default=str) + "\n", encoding="utf-8"
        )


_EPISODE = "hazardhunt_episode"
"""Info key under which a worker's env returns the episode it has just ended."""


class _EpisodeReporter(gym.Wrapper[Any, Any, Any, Any]):
    """In a worker process: adds the finished episode's record to the info of its last step."""

    def __init__(
        self, env: gym.Env[Any, Any], keep_trajectory: Callable[[EpisodeSummary], bool]
    ) -> None:
        super().__init__(env)
        self.keep_trajectory = keep_trajectory

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        if terminated or truncated:
            agv = self.env.unwrapped
            assert isinstance(agv, AGVEnv)
            info = {**info, _EPISODE: agv.simulation.result(self.keep_trajectory)}
        return observation, float(reward), terminated, truncated, info


class _ReporterFactory:
    """Builds a worker's env: from the recorder's simulation factory when it has one (plug-ins
    then load from the run's search path in the worker too), else from a pickled copy of the
    run's env."""

    def __init__(self, recorder: EpisodeRecorder) -> None:
        agv = recorder.env.unwrapped
        assert isinstance(agv, AGVEnv)
        self.simulation_factory = recorder.simulation_factory
        self.env = agv if self.simulation_factory is None else None
        self.reward: RewardKind = agv.reward_kind
        self.keep_trajectory = recorder.keep_trajectory

    def __call__(self) -> gym.Env[Any, Any]:
        env = self.env
        if env is None:
            assert self.simulation_factory is not None
            env = AGVEnv.wrapping(self.simulation_factory(), self.reward)
        return _EpisodeReporter(env, self.keep_trajectory)


class RecordingVecEnv(VecEnvWrapper):
    """``n_envs`` copies of the recorder's env in worker processes, whose finished episodes the
    recorder records as if they had run in the run's own process (until the budget)."""

    def __init__(self, recorder: EpisodeRecorder, n_envs: int, budget: int) -> None:
        super().__init__(SubprocVecEnv([_ReporterFactory(recorder)] * n_envs))
        self.recorder = recorder
        self.budget = budget

    def reset(self) -> Any:
        return self.venv.reset()

    def step_wait(self) -> VecEnvStepReturn:
        observations, rewards, dones, infos = self.venv.step_wait()
        for info in infos:
            episode = info.pop(_EPISODE, None)
            if episode is not None and self.recorder.episodes_done < self.budget:
                self.recorder.record(episode)
        return observations, np.asarray(rewards), dones, infos


class NoveltyBonus(VecEnvWrapper):
    """Adds a dissimilarity bonus to the reward of every episode that ends in a failure (Corso
    et al. 2019): ``weight`` x the mean descriptor distance of the failure to the ``k`` nearest
    failures found before it, capped at ``NOVELTY_CAP``, so that PPO is pushed away from the
    mechanisms it already knows."""

    def __init__(self, venv: VecEnv, weight: float, neighbours: int) -> None:
        super().__init__(venv)
        self.weight = weight
        self.archive = FailureArchive(neighbours)

    def reset(self) -> Any:
        return self.venv.reset()

    def step_wait(self) -> VecEnvStepReturn:
        observations, rewards, dones, infos = self.venv.step_wait()
        rewards = np.asarray(rewards, dtype=np.float32).copy()
        for index, (done, info) in enumerate(zip(dones, infos, strict=True)):
            summary = info.get("summary")
            if done and isinstance(summary, EpisodeSummary) and summary.outcome == "failure":
                novelty = min(self.archive.novelty(summary), NOVELTY_CAP)
                rewards[index] += self.weight * novelty
                info["novelty_bonus"] = self.weight * novelty
                self.archive.add(summary)
        return observations, rewards, dones, infos
