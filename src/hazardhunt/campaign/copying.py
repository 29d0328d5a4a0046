"""Copies of results small enough to keep in version control: a run or campaign directory
without its failures' trajectories.

A copy holds every table, configuration and summary, and the testers' state; the report and
the export work on it (the failures of the built-in SUT replay from their recorded actions).
Only finished runs whose files match their checksums are copied; copying again adds the runs
finished since, so a campaign run in slices can be copied after each slice.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hazardhunt.campaign.config import (
    ConfigError,
    first_difference,
    read_stored_campaign,
)
from hazardhunt.campaign.ledger import campaign_run_states, read_ledger
from hazardhunt.campaign.records import LedgerEntry, campaign_totals
from hazardhunt.campaign.replay import not_finished
from hazardhunt.campaign.run import is_finished
from hazardhunt.campaign.store import (
    LEAVABLE,
    LEFT_OUT_KEY,
    copy_run,
    find_damage,
    write_json_atomic,
)


@dataclass
class Copied:
    """What :func:`copy_results` did, by run id."""

    copied: list[str] = field(default_factory=list)
    already_there: list[str] = field(default_factory=list)
    unfinished: list[str] = field(default_factory=list)
    """Runs that have not run yet, or are running."""
    failed: dict[str, str] = field(default_factory=dict)
    """Runs the campaign's ledger records as failed, with their errors: nothing to copy."""
    damaged: dict[str, str] = field(default_factory=dict)
    ledger_problem: str | None = None
    """Why the campaign's ledger (``summary.json``) does not read, if it does not: it is not
    copied, and its failed runs are among ``unfinished``."""


def copy_results(source: Path, destination: Path, leave_out: tuple[str, ...] = LEAVABLE) -> Copied:
    """Copy the finished, undamaged runs of the run or campaign directory ``source`` into
    ``destination``, without the folders ``leave_out``.

    A campaign's ``campaign.json`` and ``summary.json`` are copied as they are, except that a
    run the copy already holds finished stays complete in its summary when the source does not
    have it complete (a campaign directory started afresh after an earlier copy); a
    ``summary.json`` that does not read is not copied (``ledger_problem`` says why). A run
    already in ``destination`` with the same summary is left alone, one with another summary
    (run again since) is replaced.

    Raises:
        ConfigError: ``source`` is neither a run nor a campaign directory, a run that has not
            finished or is damaged, or ``destination`` holds other results or is a symbolic
            link.
    """
    if destination.is_symlink():  # a run's copy replaces the folder, never what a link names
        raise ConfigError(
            f"--out: {destination} is a symbolic link; copy writes a folder of its own, never "
            "through a link: name the folder itself, or another"
        )
    if destination.resolve().is_relative_to(source.resolve()):
        raise ConfigError(f"{destination}: inside the results it would copy; name another folder")
    if (source / "campaign.json").is_file():
        return _copy_campaign(source, destination, leave_out)
    if not (source / "config.json").is_file():
        raise ConfigError(f"{source}: not a run or campaign directory")
    if not is_finished(source):
        raise ConfigError(not_finished(source))
    if (damage := find_damage(source)) is not None:
        raise ConfigError(f"{source}: the run is damaged ({damage}); run it again")
    if destination.exists() and any(destination.iterdir()):
        mine = destination / "config.json"
        if not mine.is_file() or mine.read_bytes() != (source / "config.json").read_bytes():
            raise ConfigError(f"{destination}: exists and holds something else than this run")
    copied = Copied()
    _copy_if_new(source, destination, leave_out, copied)
    return copied


def _copy_campaign(source: Path, destination: Path, leave_out: tuple[str, ...]) -> Copied:
    config = read_stored_campaign(source / "campaign.json")
    if config is None:
        raise ConfigError(f"{source / 'campaign.json'}: not a campaign configuration")
    theirs = destination / "campaign.json"
    if theirs.is_file():
        stored = read_stored_campaign(theirs)
        if stored is None:
            raise ConfigError(f"{destination}: holds the copy of another campaign")
        if stored != config:
            raise ConfigError(
                f"{destination}: holds the copy of another campaign "
                f"({first_difference(stored, config)})"
            )
    elif destination.exists() and any(destination.iterdir()):
        raise ConfigError(f"{destination}: exists and holds something else than this campaign")
    (destination / "runs").mkdir(parents=True, exist_ok=True)
    states = campaign_run_states(source, config)
    copied = Copied(unfinished=states.unfinished, failed=states.failed, damaged=states.damaged)
    for path in states.complete:
        _copy_if_new(path, destination / "runs" / path.name, leave_out, copied)
    write_json_atomic(
        destination / "campaign.json", json.loads((source / "campaign.json").read_text())
    )
    their_runs, copied.ledger_problem = read_ledger(source)
    if (source / "summary.json").is_file() and copied.ledger_problem is None:
        summary = json.loads((source / "summary.json").read_text())
        my_runs, _ = read_ledger(destination)
        if my_runs:
            summary = _keeping_runs(summary, their_runs, my_runs, destination / "runs")
        write_json_atomic(destination / "summary.json", summary)
    return copied


def _keeping_runs(
    summary: dict[str, Any], theirs: list[LedgerEntry], mine: list[LedgerEntry], runs: Path
) -> dict[str, Any]:
    """The source's campaign ``summary`` (its run entries ``theirs``), with the runs the copy
    holds finished kept as the copy records them (``mine``) where the source does not have them
    complete (the source directory was started afresh, or lost its runs since an earlier copy);
    the totals counted anew."""
    complete = {e["run_id"]: e for e in mine if e["status"] == "complete"}
    entries = [
        complete[e["run_id"]]
        if e["status"] != "complete" and e["run_id"] in complete and is_finished(runs / e["run_id"])
        else e
        for e in theirs
    ]
    return summary | campaign_totals(entries) | {"runs": entries}


def _copy_if_new(
    source: Path, destination: Path, leave_out: tuple[str, ...], copied: Copied
) -> None:
    if is_finished(destination) and find_damage(destination) is None:  # else copied anew
        mine = json.loads((destination / "summary.json").read_text())
        mine.pop(LEFT_OUT_KEY, None)
        theirs = json.loads((source / "summary.json").read_text())
        theirs.pop(LEFT_OUT_KEY, None)
        if mine == theirs:
            copied.already_there.append(destination.name)
            return
    if destination.exists():
        shutil.rmtree(destination)
    copy_run(source, destination, leave_out)
    copied.copied.append(destination.name)
