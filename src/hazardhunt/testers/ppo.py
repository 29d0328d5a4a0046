"""The study's learning tester: Stable-Baselines3 PPO, learning for the whole budget.

The failures PPO runs into while it learns are the result; the final policy is a by-product,
saved for inspection. Hyper-parameters are SB3's defaults (as the study) unless the campaign
file overrides them.

A run that searches on a requirement (``--search-on NAME``) gives ``ppo-max`` that
requirement's robustness as its maximum-style reward instead of the risk
(:class:`RequirementReward`).
"""

from __future__ import annotations

import importlib.util
import inspect
import json
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvStepReturn

from hazardhunt.env.agv import AGVEnv
from hazardhunt.spec.episode import EpisodeSummary
from hazardhunt.spec.rewards import RewardKind
from hazardhunt.sut.guard import is_finite_number
from hazardhunt.testers.base import (
    EpisodeRecorder,
    TesterParameterError,
    check_parameters,
    is_whole_number,
)
from hazardhunt.testers.evaluator import MAX_WORKER_PROCESSES
from hazardhunt.testers.novelty import FailureArchive
from hazardhunt.testers.objective import ContactRule, Objective

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


MAX_NOVELTY = 1e6
"""The largest weight of the novelty bonus (the risk reward is at most 200)."""

REQUIREMENT_REWARD_SCALE = 100.0
"""A requirement reward's scale: the objective's score (1 at the border of a violation, more
the deeper the violation) times this, near the risk reward's range (up to 200), so that SB3's
default hyper-parameters suit both."""


class RequirementReward(gym.Wrapper[Any, Any, Any, Any]):
    """A maximum-style reward from a requirement: 0 until an episode's last decision, then
    :data:`REQUIREMENT_REWARD_SCALE` x the objective's score of the episode (from its
    robustness ``r``: ``1 / (1 + r)`` while kept, ``1 - r`` once violated), in place of the
    risk."""

    def __init__(self, env: gym.Env[Any, Any], objective: Objective) -> None:
        super().__init__(env)
        self.objective = objective

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        observation, _, terminated, truncated, info = self.env.step(action)
        reward = 0.0
        if terminated or truncated:
            agv = self.env.unwrapped
            assert isinstance(agv, AGVEnv)
            score = self.objective.score(agv.simulation.result(keep_trajectory=False))
            reward = REQUIREMENT_REWARD_SCALE * score
            info = {**info, "requirement_score": score}
        return observation, reward, terminated, truncated, info


MAX_ROLLOUT = 1_000_000
"""The most decisions one rollout may hold (``n_steps`` x ``n_envs``): PPO keeps them all in
memory."""

POLICY_KWARGS = {
    "net_arch": "the hidden layers' sizes, [64, 64], or a table {pi = [...], vf = [...]}",
    "ortho_init": "true or false",
    "log_std_init": "a finite number",
    "full_std": "true or false",
    "use_expln": "true or false",
    "share_features_extractor": "true or false",
}
"""The MlpPolicy arguments a configuration may set in ``policy_kwargs``, and what each is."""


def _whole_at_least(least: int) -> tuple[str, Callable[[Any], bool]]:
    return f"a whole number >= {least}", lambda v: is_whole_number(v) and v >= least


def _number_in(text: str, inside: Callable[[float], bool]) -> tuple[str, Callable[[Any], bool]]:
    return f"a number {text}", lambda v: is_finite_number(v) and inside(v)


_FLAG = ("true or false", lambda v: isinstance(v, bool))

_PPO_VALUES: dict[str, tuple[str, Callable[[Any], bool]]] = {
    "learning_rate": _number_in("in (0, 1]", lambda v: 0 < v <= 1),
    "n_steps": _whole_at_least(1),
    "batch_size": _whole_at_least(2),
    "n_epochs": _whole_at_least(1),
    "gamma": _number_in("in (0, 1]", lambda v: 0 < v <= 1),
    "gae_lambda": _number_in("in [0, 1]", lambda v: 0 <= v <= 1),
    "clip_range": _number_in("> 0", lambda v: v > 0),
    "clip_range_vf": _number_in("> 0", lambda v: v > 0),
    "normalize_advantage": _FLAG,
    "ent_coef": _number_in(">= 0", lambda v: v >= 0),
    "vf_coef": _number_in(">= 0", lambda v: v >= 0),
    "max_grad_norm": _number_in("> 0", lambda v: v > 0),
    "use_sde": _FLAG,
    "sde_sample_freq": _whole_at_least(-1),
    "target_kl": _number_in("> 0", lambda v: v > 0),
    "stats_window_size": _whole_at_least(1),
    "tensorboard_log": (
        "a directory name, with the tensorboard package installed",
        lambda v: isinstance(v, str) and importlib.util.find_spec("tensorboard") is not None,
    ),
    "policy_kwargs": ("a table", lambda v: isinstance(v, dict)),
}
"""What each PPO argument a configuration may set must be: the values Stable-Baselines3 (and
torch's optimiser) accept, so that a bad one stops the run before it starts. The others (a
rollout buffer class, a schedule) cannot be written in a configuration file."""


def check_ppo_parameters(name: str, params: Mapping[str, Any], n_envs: object = 1) -> None:
    """Raises :class:`TesterParameterError` unless every key of ``params`` is a PPO argument a
    run may set, with a value PPO can use, and ``n_envs`` is a whole number of envs.

    Args:
        name: The tester's name, for the message.
        params: PPO's keyword arguments (without the tester's own ``n_envs`` and ``novelty``).
        n_envs: Copies of the env stepped at once.
    """
    envs_ok = is_whole_number(n_envs) and 1 <= n_envs <= MAX_WORKER_PROCESSES
    check_parameters(
        name, {"n_envs": (n_envs, f"a whole number from 1 to {MAX_WORKER_PROCESSES}", envs_ok)}
    )
    defaults = ppo_defaults()
    for key, value in params.items():
        if key in RESERVED_PARAMETERS:
            raise TesterParameterError(name, key, "is set by hazardhunt and cannot be overridden")
        if key not in _PPO_VALUES:
            known = sorted(k for k in defaults if k in _PPO_VALUES)
            raise TesterParameterError(
                name,
                key,
                f"unknown parameter; PPO takes {', '.join(known)}; the tester takes "
                f"{', '.join(TESTER_PARAMETERS)}",
            )
        wanted, accepts = _PPO_VALUES[key]
        if not accepts(value):
            raise TesterParameterError(name, key, f"must be {wanted}, not {value!r}")
    if "policy_kwargs" in params:
        _check_policy_kwargs(name, params["policy_kwargs"])
    rollout = params.get("n_steps", defaults["n_steps"]) * n_envs
    if not 2 <= rollout <= MAX_ROLLOUT:
        raise TesterParameterError(
            name,
            "n_steps",
            f"n_steps x n_envs ({rollout}) must be from 2 to {MAX_ROLLOUT:,} decisions",
        )


def _check_policy_kwargs(name: str, values: Mapping[str, Any]) -> None:
    for key, value in values.items():
        where = f"policy_kwargs.{key}"
        if key not in POLICY_KWARGS:
            raise TesterParameterError(
                name, where, f"unknown parameter; the policy takes {', '.join(POLICY_KWARGS)}"
            )
        if key == "net_arch":
            layers = value.values() if isinstance(value, dict) else [value]
            good = (not isinstance(value, dict) or set(value) <= {"pi", "vf"}) and all(
                isinstance(sizes, list)
                and all(is_whole_number(n) and 1 <= n <= 4096 for n in sizes)
                for sizes in layers
            )
        elif key == "log_std_init":
            good = is_finite_number(value)
        else:
            good = isinstance(value, bool)
        if not good:
            raise TesterParameterError(name, where, f"must be {POLICY_KWARGS[key]}, not {value!r}")


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
            TesterParameterError: A key of ``params`` is no PPO argument, or one the tester
                sets itself, or its value is one PPO cannot use.
        """
        params = dict(params or {})
        n_envs = params.pop("n_envs", 1)
        novelty = params.pop("novelty", 0.0)
        neighbours = params.pop("novelty_neighbours", 3)
        check_ppo_parameters(name, params, n_envs)
        checks = {
            "novelty": (
                novelty,
                f"a number from 0 to {MAX_NOVELTY:g}",
                is_finite_number(novelty) and 0 <= novelty <= MAX_NOVELTY,
            ),
            "novelty_neighbours": (
                neighbours,
                "a whole number >= 1",
                is_whole_number(neighbours) and neighbours >= 1,
            ),
        }
        check_parameters(name, checks)
        defaults = ppo_defaults()
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
        self.search_on: str | None = None
        """The requirement whose robustness was the reward (None: the risk)."""

    def explore(self, env: EpisodeRecorder, episodes: int) -> None:
        """Learn on ``env`` until it has recorded ``episodes`` episodes.

        Each call starts a fresh policy. SB3 seeds the env's first reset with ``seed`` and
        resets it unseeded after every episode. With ``n_envs`` > 1, copies of ``env`` run in
        worker processes and their episodes are recorded in the order they end (by env index
        within one step); episodes beyond the budget that end in the last step are dropped.
        """
        # SPEC 9: one thread per process; more only contend with the NMPC and other runs.
        torch.set_num_threads(1)
        self.search_on = None if isinstance(env.objective, ContactRule) else env.objective.name
        learning_env: gym.Env[Any, Any] | VecEnv = env
        if self.search_on is not None:
            learning_env = RequirementReward(env, env.objective)
        if self.n_envs > 1:
            learning_env = RecordingVecEnv(env, self.n_envs, episodes)
        if self.novelty > 0:
            if not isinstance(learning_env, VecEnv):
                single = learning_env
                learning_env = DummyVecEnv([lambda: single])
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
            if "tensorboard_log" not in self.params:
                # SB3's default logger makes an empty SB3-<date> directory in the temporary
                # directory on every learn(); a run keeps its own tables, so it logs nowhere.
                self.model.set_logger(Logger(folder=None, output_formats=[]))
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
            "reward": self.reward if self.search_on is None else f"requirement:{self.search_on}",
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
        self.objective = recorder.objective

    def __call__(self) -> gym.Env[Any, Any]:
        env: gym.Env[Any, Any] | None = self.env
        if env is None:
            assert self.simulation_factory is not None
            env = AGVEnv.wrapping(self.simulation_factory(), self.reward)
        if not isinstance(self.objective, ContactRule):
            env = RequirementReward(env, self.objective)
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
