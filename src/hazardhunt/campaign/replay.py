"""Re-simulate a recorded failure from its record and check that it ends the same way."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hazardhunt.campaign.config import RunConfig
from hazardhunt.campaign.run import simulation_of
from hazardhunt.sim.simulation import EpisodeResult, Simulation

TIME_TOLERANCE = 1e-9
"""Largest difference of the end time between the record and the replay, in s."""


class ReplayError(ValueError):
    """The run directory or failure does not exist."""


@dataclass(frozen=True)
class ReplayResult:
    """What the record says and what the replay did."""

    episode: int
    recorded_outcome: str
    recorded_sim_time: float
    result: EpisodeResult
    """The replayed episode, with its trajectory."""
    simulation: Simulation
    """The simulation after the replay (for pictures and animations)."""

    @property
    def matches(self) -> bool:
        """Same outcome at the same simulated time."""
        return (
            self.result.outcome == self.recorded_outcome
            and abs(self.result.summary.sim_time - self.recorded_sim_time) <= TIME_TOLERANCE
        )


def load_run_config(run_directory: Path) -> RunConfig:
    """A run's configuration, from ``config.json``."""
    config_path = run_directory / "config.json"
    if not config_path.is_file():
        raise ReplayError(f"{run_directory}: not a run directory (no config.json)")
    stored = json.loads(config_path.read_text())
    return RunConfig.model_validate(stored["run"])


def load_failure(run_directory: Path, episode: int) -> tuple[RunConfig, dict[str, Any]]:
    """The run's configuration and the failure's row."""
    config = load_run_config(run_directory)
    failures_path = run_directory / "failures.parquet"
    if not failures_path.is_file():
        raise ReplayError(f"{run_directory}: the run has not finished (no failures.parquet)")
    failures = pd.read_parquet(failures_path)
    match = failures[failures["episode"] == episode]
    if match.empty:
        known = ", ".join(str(i) for i in failures["episode"].head(10))
        raise ReplayError(
            f"{run_directory}: no failure in episode {episode} (the run recorded "
            f"{len(failures)}{': ' + known if known else ''}{' ...' if len(failures) > 10 else ''})"
        )
    return config, match.iloc[0].to_dict()


def replay_actions(config: RunConfig, actions: Any) -> tuple[Simulation, EpisodeResult]:
    """Play one episode of a run's simulation with recorded actions; the simulation after it
    and the episode's result (with its trajectory)."""
    simulation = simulation_of(config)
    actions = np.asarray([list(action) for action in actions], dtype=np.float32).reshape(-1, 2)
    return simulation, simulation.simulate(actions)


def replay_failure(run_directory: Path, episode: int) -> ReplayResult:
    """Replay the failure of one episode of a run with its recorded actions."""
    config, row = load_failure(run_directory, episode)
    simulation, result = replay_actions(config, row["actions"])
    return ReplayResult(
        episode=episode,
        recorded_outcome=str(row["outcome"]),
        recorded_sim_time=float(row["sim_time"]),
        result=result,
        simulation=simulation,
    )
