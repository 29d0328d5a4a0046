"""The records a run and a campaign write about themselves (``summary.json``), typed: what
moves between a run, the executors, the ledger and the commands (a run's summary, or the error
of a run that failed); and the CPU clock a run's record reads."""

from __future__ import annotations

import resource
import time
from typing import Any

from pydantic import TypeAdapter, ValidationError
from typing_extensions import TypedDict  # which pydantic validates on Python 3.11

from hazardhunt.errors import HazardhuntError, InputError
from hazardhunt.sut.safety_layer import FieldShape
from hazardhunt.textfiles import format_validation_error


def cpu_seconds() -> float:
    """The CPU time, user and system, of this process and of the processes it started and
    waited for (the workers that played batches on several cores, PPO's environments), in s:
    a run records the difference over its episodes as ``cpu_time_s``."""
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime


class RunFailed(HazardhuntError):  # noqa: N818 - names an outcome, as the command reports it
    """A run could not write its results (a full disk, say), or tested nothing; nothing of it
    was kept."""


class NothingTested(RunFailed):
    """So many of a run's episodes ended in ``sut_error`` (``sut_error_limit``) that it cannot
    stand for a test of the system: its results are not kept, and the message names the first
    error. ``episodes`` counts the episodes it played, ``sut_errors`` those of them that ended in
    ``sut_error``: a campaign records both with the failed run."""

    def __init__(self, message: str, episodes: int = 0, sut_errors: int = 0) -> None:
        super().__init__(message)  # only the message is an argument: it pickles with the counts
        self.episodes = episodes
        self.sut_errors = sut_errors


class FirstError(TypedDict):
    """The first episode of a run in which a plug-in failed (the SUT, the classifier), and
    what it did."""

    episode: int
    error: str


class _Violations(TypedDict):
    violations: int
    first_violation_episode: int | None
    min_robustness: float | None
    """The lowest robustness of any episode judged (negative: the worst violation's depth);
    None when none was."""
    decided_by: dict[str, int]
    """Violations by the signals that explain them (``clearance+robot_speed``: count)."""


class RequirementCount(_Violations, total=False):
    """How a run's episodes stood against one requirement beyond the contact rule."""

    judged: int
    """Episodes judged by it: those the SUT played. One that ended as ``sut_error`` tested
    nothing and is neither a violation nor a pass (runs before 0.2.0 judged every episode and
    did not record this)."""


def requirement_count() -> RequirementCount:
    """The count of a requirement no episode has been judged by yet."""
    return {
        "judged": 0,
        "violations": 0,
        "first_violation_episode": None,
        "min_robustness": None,
        "decided_by": {},
    }


class RunSummary(TypedDict, total=False):
    """A run's ``summary.json`` (:func:`hazardhunt.campaign.run.record_run` writes every key;
    runs recorded by earlier versions may lack the later ones)."""

    run_id: str
    scenario: str
    field: str
    tester: str
    seed: int
    source_digest: str
    episodes: int
    failures: int
    safe_contacts: int
    stalls: int
    timeouts: int
    goals: int
    sut_errors: int
    classifier_errors: int
    """Failures the classifier raised on or named no class for (recorded as ``other``)."""
    first_classifier_error: FirstError | None
    first_failure_episode: int | None
    first_sut_error: FirstError | None
    field_shape: dict[str, Any]
    classifier: str
    classes: list[str]
    classes_found: int
    classes_total: int
    requirements: dict[str, RequirementCount]
    wall_time_s: float
    cpu_time_s: float
    """CPU time of the run (its process and the worker processes it waited for), user and
    system, in s: unlike the wall time, not lengthened by other work on the machine. Runs of
    versions before 0.2.0 did not record it."""
    episodes_per_s: float
    started_at: str
    finished_at: str
    checksums: dict[str, str]
    """The SHA-256 of every other file of the run."""
    left_out: list[str]
    """Folders a copy left out (``trajectories``)."""


RUN_SUMMARY_KEYS = ("run_id", "scenario", "field", "tester", "seed", "episodes", "failures")
"""Keys of a run's ``summary.json`` that every version has written and reading results needs."""


def summary_problem(stored: dict[str, Any]) -> str | None:
    """What is wrong with ``stored`` as a run's ``summary.json`` (``key: problem``), or None:
    a key every run writes is missing, or a key holds a value of another type than a run writes
    (``seed: must be a whole number, not "1"``). A run received from anyone is read as data:
    this is checked before its summary is read as a run's."""
    for key in RUN_SUMMARY_KEYS:
        if key not in stored:
            return f"{key}: missing"
    try:
        _RUN_SUMMARY.validate_python(stored, strict=True)
    except ValidationError as error:
        return format_validation_error(error)
    try:  # what a report builds the run's field from
        FieldShape(**stored.get("field_shape", {}))
    except (TypeError, InputError) as error:
        return f"field_shape: {error}"
    return None


class LedgerEntry(RunSummary, total=False):
    """A run as a campaign's ``summary.json`` lists it: its summary (without checksums) once
    complete, else its keys; and how it stands. A run that failed because it tested nothing
    keeps ``episodes`` (those it played before it stopped) and ``sut_errors`` (how many of them
    ended in ``sut_error``), which the campaign's totals leave out."""

    status: str
    """``complete``, ``failed`` or ``pending``."""
    error: str | None
    """``Type: message`` of what a failed run raised."""
    traceback: str | None
    ray_node: str
    """The Ray node that executed the run (the ``ray`` executor only)."""


class CampaignTotals(TypedDict):
    """A campaign's counts over its runs."""

    runs_total: int
    runs_complete: int
    runs_failed: int
    runs_pending: int
    episodes: int
    failures: int
    sut_errors: int


class CampaignSummary(CampaignTotals):
    """A campaign's ``summary.json``."""

    campaign: dict[str, Any]
    """The campaign's configuration."""
    updated_at: str
    runs: list[LedgerEntry]


def campaign_totals(entries: list[LedgerEntry]) -> CampaignTotals:
    """A campaign summary's counts from its run entries: the runs by status, and the episodes,
    failures and SUT errors of the complete ones."""
    complete = [e for e in entries if e["status"] == "complete"]
    return {
        "runs_total": len(entries),
        "runs_complete": len(complete),
        "runs_failed": sum(e["status"] == "failed" for e in entries),
        "runs_pending": sum(e["status"] == "pending" for e in entries),
        "episodes": sum(e.get("episodes", 0) for e in complete),
        "failures": sum(e.get("failures", 0) for e in complete),
        "sut_errors": sum(e.get("sut_errors", 0) for e in complete),
    }


def ledger_entry_problem(entry: object) -> str | None:
    """What is wrong with ``entry`` as a run's entry of a campaign's ledger, or None: not a
    table, or a key that holds a value of another type than the ledger writes."""
    try:
        _LEDGER_ENTRY.validate_python(entry, strict=True)
    except ValidationError as error:
        return format_validation_error(error)
    return None


_RUN_SUMMARY = TypeAdapter(RunSummary)
_LEDGER_ENTRY = TypeAdapter(LedgerEntry)
