"""Re-simulate a recorded failure from its record and check that it ends the same way."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hazardhunt.campaign.config import RunConfig
from hazardhunt.campaign.run import make_env
from hazardhunt.env.agv import AGVEnv
from hazardhunt.spec.rewards import REWARD_KINDS, RewardKind

TIME_TOLERANCE = 1e-9
"""Largest difference of the end time between the record and the replay, in s."""


class ReplayError(ValueError):
    """The run directory or failure does not exist."""


@dataclass(frozen=True)
class ReplayResult:
    """What the record says and what the replay did."""

    failure_id: int
    recorded_outcome: str
    recorded_sim_time: float
    replayed_outcome: str | None
    replayed_sim_time: float
    env: AGVEnv
    """The env after the replay: its trajectory is the replayed episode's."""

    @property
    def matches(self) -> bool:
        """Same outcome at the same simulated time."""
        return (
            self.replayed_outcome == self.recorded_outcome
            and abs(self.replayed_sim_time - self.recorded_sim_time) <= TIME_TOLERANCE
        )


def load_run_config(run_directory: Path) -> tuple[RunConfig, RewardKind]:
    """A run's configuration and its tester's reward, from ``config.json``."""
    config_path = run_directory / "config.json"
    if not config_path.is_file():
        raise ReplayError(f"{run_directory}: not a run directory (no config.json)")
    stored = json.loads(config_path.read_text())
    reward = stored["reward"]
    if reward not in REWARD_KINDS:
        raise ReplayError(f"{config_path}: reward: {reward!r} is not one of {list(REWARD_KINDS)}")
    return RunConfig.model_validate(stored["run"]), reward


def load_failure(
    run_directory: Path, failure_id: int
) -> tuple[RunConfig, RewardKind, dict[str, Any]]:
    """The run's configuration, its reward and the failure's row."""
    config, reward = load_run_config(run_directory)
    failures_path = run_directory / "failures.parquet"
    if not failures_path.is_file():
        raise ReplayError(f"{run_directory}: the run has not finished (no failures.parquet)")
    failures = pd.read_parquet(failures_path)
    match = failures[failures["failure_id"] == failure_id]
    if match.empty:
        known = ", ".join(str(i) for i in failures["failure_id"].head(10))
        raise ReplayError(
            f"{run_directory}: no failure {failure_id} (the run recorded "
            f"{len(failures)}{': ' + known if known else ''}{' ...' if len(failures) > 10 else ''})"
        )
    return config, reward, match.iloc[0].to_dict()


def replay_actions(
    config: RunConfig, reward: RewardKind, actions: Any
) -> tuple[AGVEnv, dict[str, Any]]:
    """Play one episode of a run's environment with recorded actions.

    Returns:
        The env after the episode (its trajectory is the episode's) and the last step's info.
    """
    env = make_env(config, reward)
    return env, play(env, config.seed, actions)


def play(env: AGVEnv, seed: int, actions: Any) -> dict[str, Any]:
    """Reset ``env`` with ``seed`` and step it with ``actions`` until the episode ends or they
    run out; the last step's info (outcome None when the actions ran out first)."""
    env.reset(seed=seed)
    info: dict[str, Any] = {"outcome": None, "sim_time": 0.0}
    for action in actions:
        _, _, terminated, truncated, info = env.step(np.asarray(list(action), dtype=np.float32))
        if terminated or truncated:
            break
    return info


def replay_failure(run_directory: Path, failure_id: int) -> ReplayResult:
    """Replay one failure of a run with its recorded actions."""
    config, reward, row = load_failure(run_directory, failure_id)
    env, info = replay_actions(config, reward, row["actions"])
    return ReplayResult(
        failure_id=failure_id,
        recorded_outcome=str(row["outcome"]),
        recorded_sim_time=float(row["sim_time"]),
        replayed_outcome=info["outcome"],
        replayed_sim_time=float(info["sim_time"]),
        env=env,
    )
