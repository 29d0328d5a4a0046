"""The study's learning tester: Stable-Baselines3 PPO, learning for the whole budget.

The failures PPO runs into while it learns are the result; the final policy is a by-product,
saved for inspection. Hyper-parameters are SB3's defaults (as the study) unless the campaign
file overrides them.
"""

from __future__ import annotations

import inspect
import json
import math
from pathlib import Path
from typing import Any

import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback

from hazardhunt.spec.rewards import RewardKind
from hazardhunt.testers.base import EpisodeRecorder

RESERVED_PARAMETERS = frozenset({"policy", "env", "seed", "device", "verbose", "_init_setup_model"})
"""PPO arguments the tester sets itself: the run owns the env and the seed, and SPEC fixes
the policy (``MlpPolicy``) and the device (CPU, for reproducible runs)."""


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
                    f"PPO accepts {', '.join(sorted(defaults))}"
                )
        self.name = name
        self.reward: RewardKind = reward
        self.seed = seed
        self.params = params
        self.hyperparameters = defaults | params
        """The effective PPO arguments (defaults overridden by ``params``)."""
        self.model: PPO | None = None

    def explore(self, env: EpisodeRecorder, episodes: int) -> None:
        """Learn on ``env`` until it has recorded ``episodes`` episodes.

        Each call starts a fresh policy. SB3 seeds the env's first reset with ``seed`` and
        resets it unseeded after every episode.
        """
        # SPEC 9: one thread per process; more only contend with the NMPC and other runs.
        torch.set_num_threads(1)
        self.model = PPO(
            "MlpPolicy",
            env,
            seed=self.seed,
            device="cpu",
            verbose=0,
            **self.params,
        )
        agv = env.agv
        most_steps_per_episode = math.ceil(agv.termination.episode_duration / agv.decision_period)
        # SB3 needs a length; this bound (every episode timing out) is never reached because
        # the callback ends learning at the episode budget.
        self.model.learn(
            total_timesteps=episodes * most_steps_per_episode,
            callback=StopAtEpisodeBudget(env, episodes),
        )
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
            "timesteps": self.model.num_timesteps,
            **self.hyperparameters,
        }
        (directory / "hyperparameters.json").write_text(
            json.dumps(settings, indent=2, default=str) + "\n", encoding="utf-8"
        )
