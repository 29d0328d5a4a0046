"""The scenario a run played, recorded with it: ``scenario.json`` in the run directory, the
scenario file's contents with its map inlined. Replays, exported cases and the report's
pictures use it, so that a scenario file edited, moved or gone after the run changes none of
them (the run's stored configuration is read without the file:
:data:`~hazardhunt.campaign.config.RECORDED`); a run or campaign resumed after an edit plays
the runs made on the old file again."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from hazardhunt.world.scenario import (
    Scenario,
    ScenarioError,
    load_scenario,
    scenario_data,
    scenario_from_data,
)

SCENARIO_FILE = "scenario.json"
"""The file of a run directory that holds the scenario the run played."""


def recorded_scenario_data(run_directory: Path) -> dict[str, Any] | None:
    """The scenario a run recorded playing, its map inlined; None for a run of a version that
    did not record it.

    Raises:
        ScenarioError: The file does not read as JSON or holds no table.
    """
    path = run_directory / SCENARIO_FILE
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as error:
        raise ScenarioError(f"{path}: cannot be read as JSON: {error}") from None
    if not isinstance(data, dict):
        raise ScenarioError(f"{path}: not a scenario (a table of settings)")
    return data


def recorded_scenario(run_directory: Path) -> Scenario | None:
    """The scenario a run played, as it recorded it; None for a run of a version that did not
    record it (its scenario file is played as it is now).

    Raises:
        ScenarioError: The recorded scenario does not read, naming the file and the field.
    """
    data = recorded_scenario_data(run_directory)
    if data is None:
        return None
    return scenario_from_data(data, str(run_directory / SCENARIO_FILE))


def played_scenario(run_directory: Path, scenario: str) -> Scenario:
    """The scenario the run in ``run_directory`` played: as it recorded it, else (a run of a
    version that did not record it) ``scenario``, its built-in name or file, as it is now.

    Raises:
        ScenarioError: The recorded scenario, or else the file, does not load.
    """
    return recorded_scenario(run_directory) or load_scenario(scenario)


def played_scenario_data(run_directory: Path, scenario: str) -> dict[str, Any]:
    """:func:`played_scenario`'s contents, its map inlined (what a regression case holds),
    the recorded ones checked to read as a scenario first.

    Raises:
        ScenarioError: The recorded scenario, or else the file, does not load.
    """
    data = recorded_scenario_data(run_directory)
    if data is None:
        return scenario_data(scenario)
    scenario_from_data(data, str(run_directory / SCENARIO_FILE))
    return data


def scenario_changed(scenario: str, run_directory: Path) -> bool:
    """Whether ``scenario`` (the run's built-in name or file) now says something else than the
    run in ``run_directory`` recorded playing, or no longer loads; False for a run that
    recorded no scenario, or whose record does not read (its checksums tell that)."""
    try:
        recorded = recorded_scenario_data(run_directory)
    except ScenarioError:
        return False
    if recorded is None:
        return False
    try:
        return bool(scenario_data(scenario) != recorded)
    except ScenarioError:
        return True


def played_before_change(scenario: str, run_directory: Path) -> str | None:
    """Why the run in ``run_directory`` must be played again because ``scenario`` changed
    (:func:`scenario_changed`), in the words a run and a campaign both say it; None if it
    need not."""
    if scenario_changed(scenario, run_directory):
        return f"played on {scenario} before the file changed"
    return None
