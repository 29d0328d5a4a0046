"""Re-simulate a recorded failure from its record and check that it ends the same way.

A run directory is data: a controller or safety layer its ``config.json`` names is imported
only when the caller names it again or trusts the run's plug-ins
(:func:`hazardhunt.campaign.plugins.allowed_plugin`).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from pydantic import ValidationError

from hazardhunt.campaign.config import RunConfig
from hazardhunt.campaign.plugins import PluginSpec, allowed_plugin
from hazardhunt.campaign.run import simulation_of
from hazardhunt.errors import InputError
from hazardhunt.sim.simulation import EpisodeResult, Simulation
from hazardhunt.world.scenario import format_validation_error

TIME_TOLERANCE = 1e-9
"""Largest difference of the end time between the record and the replay, in s."""


class ReplayError(InputError):
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
    """A run's configuration, from ``config.json``.

    Raises:
        ReplayError: It is missing, or does not read as a run's configuration (naming the file
            and the first problem).
    """
    config_path = run_directory / "config.json"
    if not config_path.is_file():
        raise ReplayError(f"{run_directory}: not a run directory (no config.json)")
    try:
        stored = json.loads(config_path.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as error:
        raise ReplayError(f"{config_path}: cannot be read as JSON: {error}") from None
    if not isinstance(stored, dict) or not isinstance(stored.get("run"), dict):
        raise ReplayError(f"{config_path}: not a run's configuration (no run table)")
    try:
        return RunConfig.model_validate(stored["run"])
    except ValidationError as error:
        problem = format_validation_error(error)
        raise ReplayError(f"{config_path}: not a run's configuration: run.{problem}") from None


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


def names_sut_plugins(config: RunConfig) -> bool:
    """Whether a run's SUT has a plug-in (controller or safety layer): replaying it imports
    code."""
    return config.controller is not None or config.safety_layer is not None


def allowed_sut(
    config: RunConfig,
    run_directory: Path,
    *,
    controller: PluginSpec | None = None,
    safety_layer: PluginSpec | None = None,
    trust_plugins: bool = False,
    announce: Callable[[str], None] | None = None,
) -> RunConfig:
    """A stored run's configuration with the SUT plug-ins that may be imported to replay it:
    those given, else (with ``trust_plugins``) those it names (see
    :func:`hazardhunt.campaign.plugins.allowed_plugin`).

    Raises:
        UntrustedPluginError: The run names a plug-in that is neither given nor trusted.
    """
    where = str(run_directory / "config.json")
    allowed = {
        key: allowed_plugin(
            getattr(config, key),
            given,
            where=f"{where}: run.{key}",
            option=option,
            trust=trust_plugins,
            announce=announce,
        )
        for key, given, option in (
            ("controller", controller, "--controller"),
            ("safety_layer", safety_layer, "--safety-layer"),
        )
    }
    return config.model_copy(update=allowed)


def replay_actions(config: RunConfig, actions: Any) -> tuple[Simulation, EpisodeResult]:
    """Play one episode of a run's simulation with recorded actions; the simulation after it
    and the episode's result (with its trajectory). This imports the plug-ins ``config``
    names: a configuration read back from a file goes through :func:`allowed_sut` first."""
    simulation = simulation_of(config)
    actions = np.asarray([list(action) for action in actions], dtype=np.float32).reshape(-1, 2)
    return simulation, simulation.simulate(actions)


def replay_failure(
    run_directory: Path,
    episode: int,
    *,
    controller: PluginSpec | None = None,
    safety_layer: PluginSpec | None = None,
    trust_plugins: bool = False,
    announce: Callable[[str], None] | None = None,
) -> ReplayResult:
    """Replay the failure of one episode of a run with its recorded actions.

    A run with the built-in SUT replays as it is. A controller or safety layer the run names
    is imported only when given again (``controller``, ``safety_layer``: another SUT, or the
    same import path to confirm it) or with ``trust_plugins``; ``announce`` is told which
    module is about to be imported.

    Raises:
        ReplayError: The run directory or the failure does not exist.
        UntrustedPluginError: The run names a plug-in that is neither given nor trusted;
            nothing has been imported.
        PluginError: A plug-in does not load.
    """
    config, row = load_failure(run_directory, episode)
    config = allowed_sut(
        config,
        run_directory,
        controller=controller,
        safety_layer=safety_layer,
        trust_plugins=trust_plugins,
        announce=announce,
    )
    simulation, result = replay_actions(config, row["actions"])
    return ReplayResult(
        episode=episode,
        recorded_outcome=str(row["outcome"]),
        recorded_sim_time=float(row["sim_time"]),
        result=result,
        simulation=simulation,
    )
