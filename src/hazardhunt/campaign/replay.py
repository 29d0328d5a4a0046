"""Re-simulate a recorded failure from its record and check that it ends the same way.

A requirement's violation (``violations.parquet``) replays the same way, judged again by the
formula the run recorded with it: it must reproduce its robustness too.

A run directory is data: a controller or safety layer its ``config.json`` names is imported
only when the caller names it again or trusts the run's plug-ins
(:func:`hazardhunt.campaign.plugins.allowed_plugin`).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from pydantic import ValidationError

from hazardhunt.campaign.config import RECORDED, STORED, RunConfig
from hazardhunt.campaign.plugins import PluginSpec, allowed_plugin
from hazardhunt.campaign.run import is_finished
from hazardhunt.campaign.scenario_record import (
    SCENARIO_FILE,
    recorded_scenario,
    scenario_changed,
)
from hazardhunt.campaign.simulations import simulation_of
from hazardhunt.campaign.store import find_damage, sut_error_of
from hazardhunt.errors import InputError
from hazardhunt.sim.simulation import EpisodeResult, Simulation
from hazardhunt.spec.episode import EpisodeSummary
from hazardhunt.spec.requirements import RequirementError, StlRequirement
from hazardhunt.textfiles import format_validation_error
from hazardhunt.world.scenario import Scenario

TIME_TOLERANCE = 1e-9
"""Largest difference of the end time between the record and the replay, in s."""
ROBUSTNESS_TOLERANCE = 1e-9
"""Largest difference of a requirement's robustness between the record and the replay."""


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
    recorded_robustness: dict[str, float] = field(default_factory=dict)
    """The robustness of each requirement the episode violated, as recorded."""

    @property
    def sut_error(self) -> str | None:
        """What ended the replay as ``sut_error`` (:func:`sut_error_of`); None if it did not."""
        return sut_error_of(self.result.summary) if self.result.outcome == "sut_error" else None

    @property
    def matches(self) -> bool:
        """Same outcome at the same simulated time, and each recorded violation again with
        the same robustness; never a replay whose SUT erred, which tested nothing."""
        verdicts = self.result.verdicts
        return (
            self.sut_error is None
            and self.result.outcome == self.recorded_outcome
            and abs(self.result.summary.sim_time - self.recorded_sim_time) <= TIME_TOLERANCE
            and all(
                name in verdicts
                and abs(verdicts[name].robustness - robustness) <= ROBUSTNESS_TOLERANCE
                for name, robustness in self.recorded_robustness.items()
            )
        )


def not_finished(directory: Path) -> str:
    """Why ``directory``, which has a ``config.json`` but no ``summary.json``, holds no finished
    run: an estimate's directory (``hazardhunt estimate``) is called one, as its configuration
    says; anything else is a run that has not finished."""
    try:
        stored = json.loads((directory / "config.json").read_text())
    except (OSError, UnicodeDecodeError, ValueError):
        stored = None
    if _is_estimate(stored):
        return f"{directory}: an estimate, not a run; 'hazardhunt report {directory}' shows it"
    return f"{directory}: the run has not finished (no summary.json)"


def _is_estimate(stored: Any) -> bool:
    """Whether the contents of a ``config.json`` are an estimate's configuration."""
    return isinstance(stored, dict) and "estimator" in stored and "run" not in stored


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
    if _is_estimate(stored):
        raise ReplayError(not_finished(run_directory))
    if not isinstance(stored, dict) or not isinstance(stored.get("run"), dict):
        raise ReplayError(f"{config_path}: not a run's configuration (no run table)")
    try:
        # A run that recorded its scenario replays on that, whatever its file says now.
        recorded = (run_directory / SCENARIO_FILE).is_file()
        return RunConfig.model_validate(stored["run"], context=RECORDED if recorded else STORED)
    except ValidationError as error:
        problem = format_validation_error(error)
        raise ReplayError(f"{config_path}: not a run's configuration: run.{problem}") from None


def load_failure(run_directory: Path, episode: int) -> tuple[RunConfig, dict[str, Any]]:
    """The run's configuration and the failure's row (or, for an episode that violated a
    requirement without a failure, its first violation's row).

    Raises:
        ReplayError: The run has not finished, its files do not match their checksums (or do
            not read), or it recorded no failure in ``episode``.
    """
    config = load_run_config(run_directory)
    if not is_finished(run_directory):
        raise ReplayError(not_finished(run_directory))
    damage = find_damage(run_directory)
    if damage is not None:
        raise ReplayError(f"{run_directory}: the run is damaged ({damage}); nothing replayed")
    failures_path = run_directory / "failures.parquet"
    if not failures_path.is_file():
        raise ReplayError(f"{run_directory}: the run recorded no failures.parquet")
    failures = pd.read_parquet(failures_path)
    match = failures[failures["episode"] == episode]
    if match.empty:
        violations = load_violations(run_directory, episode)
        if violations:
            return config, violations[0]
        known = ", ".join(str(i) for i in failures["episode"].head(10))
        if failures.empty:
            recorded = "no failure"
        elif len(failures) == 1:
            recorded = f"1 failure, in episode {known}"
        else:
            more = " ..." if len(failures) > 10 else ""
            recorded = f"{len(failures)} failures, in episodes {known}{more}"
        raise ReplayError(
            f"{run_directory}: no failure in episode {episode} "
            f"({_what_became_of(run_directory, episode)} {recorded})"
        )
    return config, match.iloc[0].to_dict()


def _what_became_of(run_directory: Path, episode: int) -> str:
    """The start of the reason why ``episode`` has no failure to replay: how it ended (with
    the error of a SUT that erred), or which episodes the run played (from
    ``episodes.parquet``; just "the run recorded" without it)."""
    try:
        played = pd.read_parquet(run_directory / "episodes.parquet")
    except (OSError, ValueError):
        return "the run recorded"
    row = played[played["episode"] == episode]
    if not row.empty:
        outcome = row["outcome"].iloc[0]
        if outcome == "sut_error":
            error = sut_error_of(EpisodeSummary.from_row(row.iloc[0].to_dict()))
            return f"it ended in a SUT error, which tested nothing: {error}; the run recorded"
        return f"it ended as {outcome!r}; the run recorded"
    if played.empty:
        return "the run played no episode and recorded"
    first, last = int(played["episode"].min()), int(played["episode"].max())
    return f"the run played episodes {first} to {last} and recorded"


def load_violations(run_directory: Path, episode: int) -> list[dict[str, Any]]:
    """The rows of ``violations.parquet`` for one episode (none for a run without
    requirements beyond the contact rule, nor for an episode that ended in a SUT error: it
    tested nothing, though runs before 0.2.0 recorded its violations)."""
    path = run_directory / "violations.parquet"
    if not path.is_file():
        return []
    violations = pd.read_parquet(path)
    mine = violations[violations["episode"] == episode]
    return [row for row in mine.to_dict("records") if row.get("outcome") != "sut_error"]


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


def replay_actions(
    config: RunConfig,
    actions: Any,
    formulas: Mapping[str, str] | None = None,
    where: str = "",
    scenario: Scenario | None = None,
) -> tuple[Simulation, EpisodeResult]:
    """Play one episode of a run's simulation with recorded actions, on ``scenario`` (the
    one the run recorded, :func:`recorded_scenario`; None: its scenario file), judged by the
    requirements ``formulas`` (name: formula, as recorded; not the run's requirement files,
    which need not be where they were); the simulation after it and the episode's result
    (with its trajectory). This imports the plug-ins ``config`` names: a configuration read
    back from a file goes through :func:`allowed_sut` first.

    Raises:
        ReplayError: A formula does not parse (``where``: the file it came from).
    """
    simulation = simulation_of(config.model_copy(update={"requirements": []}), scenario)
    period = simulation.controller.control_period
    simulation.requirements = tuple(
        _recorded_requirement(name, formula, where, period)
        for name, formula in (formulas or {}).items()
    )
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
    controller_timeout: float | None = None,
) -> ReplayResult:
    """Replay the failure of one episode of a run with its recorded actions (or its
    violation of a requirement: :class:`ReplayResult` checks the robustness too), with
    ``controller_timeout`` (in s) as the limit on each call of the SUT if given, else the run's.

    A run with the built-in SUT replays as it is. A controller or safety layer the run names
    is imported only when given again (``controller``, ``safety_layer``: another SUT, or the
    same import path to confirm it) or with ``trust_plugins``; ``announce`` is told which
    module is about to be imported.

    Raises:
        ReplayError: The run directory or the failure does not exist, or a violation's
            recorded formula does not parse.
        UntrustedPluginError: The run names a plug-in that is neither given nor trusted;
            nothing has been imported.
        PluginError: A plug-in does not load.
    """
    config, row = load_failure(run_directory, episode)
    violations = load_violations(run_directory, episode)
    config = allowed_sut(
        config,
        run_directory,
        controller=controller,
        safety_layer=safety_layer,
        trust_plugins=trust_plugins,
        announce=announce,
    )
    if controller_timeout is not None:
        env = config.env.model_copy(update={"controller_timeout": controller_timeout})
        config = config.model_copy(update={"env": env})
    # Judged by the formulas recorded with the violations, not by the run's requirement files,
    # which may have changed or moved since.
    formulas = {str(v["requirement"]): str(v.get("formula") or "") for v in violations}
    where = str(run_directory / "violations.parquet")
    # On the scenario the run played, which its file may no longer say.
    scenario = recorded_scenario(run_directory)
    if announce is not None and scenario_changed(config.scenario, run_directory):
        announce(
            f"{config.scenario}: has changed or gone since the run; replayed on the scenario "
            f"the run recorded ({run_directory / SCENARIO_FILE})"
        )
    simulation, result = replay_actions(config, row["actions"], formulas, where, scenario)
    return ReplayResult(
        episode=episode,
        recorded_outcome=str(row["outcome"]),
        recorded_sim_time=float(row["sim_time"]),
        result=result,
        simulation=simulation,
        recorded_robustness={str(v["requirement"]): float(v["robustness"]) for v in violations},
    )


def _recorded_requirement(
    name: str, formula: str, where: str, sampling_period: float
) -> StlRequirement:
    """The requirement of a recorded violation, from the formula stored with it (data, parsed
    by rtamt, never run as code).

    Raises:
        ReplayError: The violation has no formula, or it does not parse.
    """
    if not formula:
        raise ReplayError(f"{where}: requirement {name!r}: no formula recorded to judge it by")
    try:
        return StlRequirement(name, formula, where=where, sampling_period=sampling_period)
    except RequirementError as error:
        raise ReplayError(str(error)) from None
