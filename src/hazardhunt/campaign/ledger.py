"""A campaign's ledger: how every run of the grid stands, kept in the campaign's
``summary.json`` and rewritten after each change, and how one run ended (:class:`RunOutcome`),
as the executors report it."""

from __future__ import annotations

import json
import traceback
from dataclasses import dataclass, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import cast

from hazardhunt.campaign.config import RECORDED, CampaignConfig, RunConfig, first_difference
from hazardhunt.campaign.records import (
    CampaignSummary,
    LedgerEntry,
    NothingTested,
    RunSummary,
    campaign_totals,
    ledger_entry_problem,
)
from hazardhunt.campaign.replay import ReplayError, load_run_config
from hazardhunt.campaign.run import is_finished
from hazardhunt.campaign.scenario_record import played_before_change
from hazardhunt.campaign.store import find_damage, write_json_atomic


@dataclass(frozen=True)
class RunOutcome:
    """How one run of a campaign ended: its summary, or the error it raised."""

    config: RunConfig
    summary: RunSummary | None
    error: str | None = None
    """``Type: message`` of the exception, when the run raised."""
    traceback: str | None = None
    ray_node: str | None = None
    """The id of the Ray node that executed the run (the ``ray`` executor only)."""
    episodes: int | None = None
    """The episodes a run that tested nothing (``NothingTested``) played before it stopped."""
    sut_errors: int | None = None
    """How many of those ended in ``sut_error``."""


def failed(run: RunConfig, error: BaseException, remote_traceback: str | None = None) -> RunOutcome:
    """The outcome of a run that raised ``error`` (on another machine: ``remote_traceback``).
    Its error is said after the run's id, so without the ``run ID:`` its message may open with."""
    message = str(error).removeprefix(f"run {run.run_id}: ")
    outcome = RunOutcome(
        run,
        None,
        f"{type(error).__name__}: {message}",
        remote_traceback or "".join(traceback.format_exception(error)),
    )
    if isinstance(error, NothingTested):
        return replace(outcome, episodes=error.episodes, sut_errors=error.sut_errors)
    return outcome


def read_ledger(out: Path) -> tuple[list[LedgerEntry], str | None]:
    """The run entries of the ledger of the campaign directory ``out``, and what is wrong with
    the ledger if it does not read (None if it reads, or if there is none yet). The ledger is
    read as data from a file that may come from anyone: entries that are not as the ledger
    writes them (a run id, a status, and every other key of the type a ledger writes) are
    skipped."""
    path = out / "summary.json"
    try:
        stored = json.loads(path.read_text())
    except FileNotFoundError:
        return [], None
    except (OSError, ValueError) as error:
        return [], f"{path} does not read ({type(error).__name__}: {error})"
    runs = stored.get("runs") if isinstance(stored, dict) else None
    if not isinstance(runs, list):
        return [], f"{path} is not a campaign's summary (no list of runs)"
    entries = [
        cast(LedgerEntry, entry)
        for entry in runs
        if ledger_entry_problem(entry) is None and {"run_id", "status"} <= entry.keys()
    ]
    return entries, None


def ledger_errors(entries: list[LedgerEntry]) -> dict[str, str]:
    """Run id -> error of every run the ledger ``entries`` record as failed."""
    return {
        entry["run_id"]: str(entry.get("error") or "no error recorded")
        for entry in entries
        if entry["status"] == "failed"
    }


@dataclass(frozen=True)
class RunStates:
    """The runs of a run or campaign directory, by how they stand."""

    complete: list[Path]
    """The directories of the complete runs."""
    unfinished: list[str]
    """The run ids of the runs that have not run yet, or are running."""
    failed: dict[str, str]
    """Run id -> the error the campaign's ledger records."""
    damaged: dict[str, str]
    """Run id -> what is wrong with its files."""
    ledger_problem: str | None = None
    """Why the campaign's ledger does not read, if it does not: a run it recorded as failed
    is then among ``unfinished``, as nothing tells the two apart."""


def campaign_run_states(out: Path, config: CampaignConfig) -> RunStates:
    """The runs of the campaign ``config`` in ``out`` (read with :data:`RECORDED`: what ran,
    its scenario files not needed): a run that has not finished failed if the ledger records it
    as failed, else it has not run yet (or is running); a finished one whose files do not match
    their checksums, or that holds a run of another configuration than the campaign's, is
    damaged (the campaign runs it again)."""
    entries, problem = read_ledger(out)
    errors = ledger_errors(entries)
    states = RunStates([], [], {}, {}, problem)
    for run in config.runs(RECORDED):
        path = out / "runs" / run.run_id
        if not is_finished(path):
            if run.run_id in errors:
                states.failed[run.run_id] = errors[run.run_id]
            else:
                states.unfinished.append(run.run_id)
        elif (damage := find_damage(path) or other_configuration(path, run)) is not None:
            states.damaged[run.run_id] = damage
        else:
            states.complete.append(path)
    return states


class Ledger:
    """The campaign's ``summary.json``: how every run stands, rewritten after each change.

    Complete runs are read back from their own directories, so the ledger of a resumed campaign
    is right even if the previous campaign process died between a run and its ledger update. A
    run folder whose files do not match their checksums, that holds a run of another
    configuration (another command wrote it) or no ``summary.json`` is damaged, and one played on
    a scenario file that has changed since is out of date: the campaign names it (``redo``) and
    runs it again, and never counts it.
    """

    def __init__(self, config: CampaignConfig, runs: list[RunConfig], out: Path) -> None:
        self.config = config
        self.path = out / "summary.json"
        self.entries: dict[str, LedgerEntry] = {}
        self.redo: dict[str, str] = {}
        """Run id -> why its folder is played again ("is damaged (...)", "was played on ...")."""
        self.write_error: OSError | None = None
        """Why the last write of ``summary.json`` failed; None once one succeeded."""
        for run in runs:
            directory = out / "runs" / run.run_id
            if is_finished(directory):
                damage = find_damage(directory)
                why = f"is damaged ({damage})" if damage else _not_this_run(directory, run)
                if why is None:
                    stored = json.loads((directory / "summary.json").read_text())
                    self.entries[run.run_id] = _ledger_entry(stored, "complete")
                    continue
                self.redo[run.run_id] = why
            elif directory.exists():  # the campaign's own folder, without its summary.json
                self.redo[run.run_id] = "is damaged (it holds no summary.json (an unfinished run))"
            self.entries[run.run_id] = _run_keys(run, "pending")
        self.write()

    def status(self, run: RunConfig) -> str:
        """``complete``, ``failed`` or ``pending``."""
        return str(self.entries[run.run_id]["status"])

    def record(self, outcome: RunOutcome) -> None:
        """Store how a run ended and rewrite ``summary.json``."""
        run = outcome.config
        if outcome.summary is not None:
            entry = _ledger_entry(outcome.summary, "complete")
            if outcome.ray_node is not None:
                entry["ray_node"] = outcome.ray_node
        else:
            entry = _run_keys(run, "failed")
            entry["error"], entry["traceback"] = outcome.error, outcome.traceback
            if outcome.episodes is not None and outcome.sut_errors is not None:
                entry["episodes"], entry["sut_errors"] = outcome.episodes, outcome.sut_errors
        self.entries[run.run_id] = entry
        self.write()

    def summary(self) -> CampaignSummary:
        """The campaign summary: totals, then one entry per run in grid order."""
        entries = list(self.entries.values())
        return CampaignSummary(
            campaign=self.config.model_dump(mode="json"),
            **campaign_totals(entries),
            updated_at=datetime.now(timezone.utc).isoformat(),
            runs=entries,
        )

    def write(self) -> CampaignSummary:
        """Rewrite ``summary.json`` atomically; the summary meant to be written.

        A write that fails (a full disk) is remembered in ``write_error`` rather than raised:
        the runs go on, and the next write tries again.
        """
        summary = self.summary()
        try:
            write_json_atomic(self.path, summary)
        except OSError as error:
            self.write_error = error
        else:
            self.write_error = None
        return summary


def _not_this_run(directory: Path, run: RunConfig) -> str | None:
    """Why the finished run in ``directory`` is not ``run`` (another configuration, or played on
    its scenario file before the file changed), if it is not."""
    if (why := other_configuration(directory, run)) is not None:
        return f"is damaged ({why})"
    if (why := played_before_change(run.scenario, directory)) is not None:
        return f"was {why}"
    return None


def other_configuration(directory: Path, run: RunConfig) -> str | None:
    """Why the finished run in ``directory`` does not hold ``run``'s configuration, if it does
    not: its ``config.json`` does not read, or says other settings (the first that differs)."""
    try:
        stored = load_run_config(directory)
    except ReplayError:
        return "its config.json does not read as a run's configuration"
    if stored != run:
        return f"it holds a run of another configuration ({first_difference(stored, run)})"
    return None


def _ledger_entry(summary: RunSummary, status: str) -> LedgerEntry:
    """A run's summary as the ledger keeps it: with its status, without its files' checksums."""
    entry = cast(LedgerEntry, {"status": status, **summary})
    entry.pop("checksums", None)
    return entry


def _run_keys(run: RunConfig, status: str) -> LedgerEntry:
    """The entry of a run that has no summary (pending or failed)."""
    return LedgerEntry(
        status=status,
        run_id=run.run_id,
        scenario=run.scenario,
        field=run.field,
        tester=run.tester,
        seed=run.seed,
    )
