"""A campaign: every run of a grid, executed in parallel into one directory that survives a kill.

Layout of a campaign directory::

    campaign.json              the resolved campaign configuration (written first)
    runs/<run_id>/             one complete run directory each (see ``hazardhunt.campaign.store``)
    runs/.<run_id>.partial     a run in progress; deleted and redone when the campaign resumes
    summary.json               per run its summary, or its error; rewritten after each run
    .lock                      held (``flock``) by the one campaign process writing the
                               directory, there while it writes

A run directory appears under its name only once the run is complete, so resuming is: keep the
complete runs whose files match the checksums they recorded, delete the partial and damaged
ones and run them again. Runs are deterministic per seed, so a redone run loses nothing and
counts nothing twice. A run whose worker process dies (killed by the out-of-memory killer, say)
is started again in a new worker, up to ``WORKER_DEATH_RETRIES`` times.

This module checks the directory and the SUT and drives the others, one job each:
``ledger`` (how every run stands, ``summary.json``), ``local_executor`` (worker processes on
this machine), ``ray_executor`` (a Ray cluster) and ``progress`` (the bars, the log lines and
the final table).
"""

from __future__ import annotations

import fnmatch
import functools
import shutil
from collections.abc import Sequence
from pathlib import Path

from rich.console import Console
from rich.markup import escape
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

import hazardhunt
from hazardhunt.campaign.config import (
    CampaignConfig,
    ConfigError,
    RunConfig,
    first_difference,
    read_stored_campaign,
)
from hazardhunt.campaign.ledger import Ledger, RunOutcome
from hazardhunt.campaign.local_executor import WORKER_DEATH_RETRIES, execute_locally
from hazardhunt.campaign.lock import exclusive_lock
from hazardhunt.campaign.progress import ProgressDisplay, print_campaign_table
from hazardhunt.campaign.ray_executor import execute_on_ray
from hazardhunt.campaign.records import CampaignSummary
from hazardhunt.campaign.run import is_complete, make_directory
from hazardhunt.campaign.simulations import check_sut
from hazardhunt.campaign.store import write_json_atomic
from hazardhunt.errors import HazardhuntError

EXECUTORS = ("local", "ray")
"""Where runs execute: a local process pool, or a Ray cluster."""


class CampaignFailed(HazardhuntError):  # noqa: N818 - names an outcome, as the command reports it
    """Some runs raised while the others completed (``summary`` records which and why), or the
    campaign's ``summary.json`` could not be written."""

    def __init__(self, summary: CampaignSummary, reason: str | None = None) -> None:
        super().__init__(
            reason
            or f"{summary['runs_failed']} of {summary['runs_total']} runs raised (see summary.json)"
        )
        self.summary = summary


def run_campaign(
    config: CampaignConfig,
    out: Path,
    *,
    workers: int = 1,
    executor: str = "local",
    address: str | None = None,
    console: Console | None = None,
    only: Sequence[str] = (),
) -> CampaignSummary:
    """Execute every run of ``config`` into the campaign directory ``out``, or finish it.

    Runs execute in separate processes even with ``workers=1`` (one worker), so that a run that
    crashes its interpreter takes no other run with it and both executors behave alike.

    Args:
        config: The campaign.
        out: The campaign directory: created, or resumed if it holds this campaign.
        workers: Runs executed at once (local) or CPUs of the local Ray cluster started.
        executor: ``local`` (a process pool on this machine) or ``ray``.
        address: Address of an existing Ray cluster to run on (``ray`` only); its nodes need
            hazardhunt installed, but no file system shared with this machine.
        console: Where progress and the final table are printed; nothing is printed if None.
        only: Shell-style patterns of run ids (``crossing__*__seed0``): execute only the runs
            that match one of them now and leave the others pending, to run a large campaign
            in slices into one directory. Empty: every run.

    Returns:
        The campaign summary, as written to ``out/summary.json``.

    Raises:
        ConfigError: ``out`` holds another campaign or something else, or another campaign
            process is writing it; nothing is written then.
        PluginError: A plug-in of the SUT fails on a trial episode; nothing is written.
        CampaignFailed: After all other runs finished, if some runs raised (or their workers
            died every time they were tried), or if ``summary.json`` could not be written.
    """
    if executor not in EXECUTORS:
        raise ValueError(f"executor must be one of {', '.join(EXECUTORS)}, not {executor!r}")
    if workers < 1:
        raise ValueError(f"workers must be at least 1, not {workers}")
    runs = config.runs()
    selected = selected_runs(runs, only)
    _check_suts(selected)
    _check_directory(config, out)
    make_directory(out, "--out")
    with exclusive_lock(out / ".lock", out, "campaign"):
        _check_directory(config, out)  # another campaign may have claimed it before our lock
        if not _holds_complete_runs(out):  # else it holds this campaign: checked above
            write_json_atomic(out / "campaign.json", config.model_dump(mode="json"))
        runs_directory = out / "runs"
        runs_directory.mkdir(exist_ok=True)
        for leftover in runs_directory.glob(".*.partial"):
            shutil.rmtree(leftover)
        ledger = Ledger(config, runs, out)
        _redo(ledger, runs_directory, console)
        _warn_of_other_versions(ledger, console)
        pending = [run for run in selected if ledger.status(run) != "complete"]
        if pending:
            _execute(pending, runs_directory, ledger, workers, executor, address, console)
        summary = ledger.write()
    if console is not None:
        print_campaign_table(console, summary, out)
    if ledger.write_error is not None:
        reason = (
            f"{ledger.path}: could not be written ({ledger.write_error}); the complete runs are "
            "kept under runs/: run the same command again to write it"
        )
        if console is not None:
            console.print(f"[red]error:[/red] {escape(reason)}")
        raise CampaignFailed(summary, reason)
    if summary["runs_failed"]:
        raise CampaignFailed(summary)
    return summary


def _check_suts(runs: list[RunConfig]) -> None:
    """Try each system under test the runs name on a trial episode (:func:`check_sut`), once
    per controller, safety layer and environment: a plug-in that cannot run stops the
    campaign before anything is written."""
    tried: set[str] = set()
    for run in runs:
        sut = run.model_dump_json(include={"controller", "safety_layer", "env"})
        if sut not in tried:
            tried.add(sut)
            check_sut(run)


def selected_runs(runs: list[RunConfig], only: Sequence[str]) -> list[RunConfig]:
    """The runs whose ids match one of the shell-style patterns ``only`` (all if empty).

    Raises:
        ConfigError: A pattern matches no run; the message shows what run ids look like.
    """
    if not only:
        return runs
    for pattern in only:
        if not any(fnmatch.fnmatchcase(run.run_id, pattern) for run in runs):
            raise ConfigError(
                f"--runs: {pattern!r} matches no run of the campaign; its run ids look like "
                f"{runs[0].run_id!r} (scenario__field__tester__seedN)"
            )
    return [run for run in runs if any(fnmatch.fnmatchcase(run.run_id, p) for p in only)]


def _redo(ledger: Ledger, runs_directory: Path, console: Console | None) -> None:
    """Remove the run folders that are damaged, of another configuration, unfinished or played
    on a scenario file that changed since, so that they are run again."""
    for run_id, why in ledger.redo.items():
        if console is not None:
            console.print(
                f"[yellow]warning:[/yellow] run {escape(run_id)} {escape(why)}; running it again"
            )
        shutil.rmtree(runs_directory / run_id)


def _warn_of_other_versions(ledger: Ledger, console: Console | None) -> None:
    """Say so when complete runs were made by other code than the runs still to come."""
    current = hazardhunt.source_digest()
    others = sorted(
        entry["run_id"]
        for entry in ledger.entries.values()
        if entry["status"] == "complete" and entry.get("source_digest", current) != current
    )
    if others and console is not None:
        console.print(
            f"[yellow]warning:[/yellow] {len(others)} complete runs were made by other hazardhunt "
            f"code (source digest differs from {current}): {escape(', '.join(others))}. "
            "Delete their directories under runs/ to redo them with this code."
        )


def _check_directory(config: CampaignConfig, out: Path) -> None:
    """Refuse ``out`` unless it is absent, empty, a directory of this very campaign, or one of
    another campaign that has no complete run (it is taken over: a campaign file fixed after
    its runs failed is run again with the same command)."""
    stored_file = out / "campaign.json"
    if stored_file.is_file():
        if not _holds_complete_runs(out):
            return
        stored = read_stored_campaign(stored_file)
        if stored is None:
            raise ConfigError(f"{stored_file}: not a campaign configuration; use another --out")
        if stored != config:
            raise ConfigError(
                f"{out}: holds a different campaign ({first_difference(stored, config)}); "
                "use another --out or delete it"
            )
    elif out.exists() and (
        not out.is_dir() or any(not p.name.startswith(".") for p in out.iterdir())
    ):
        raise ConfigError(f"{out}: exists and is not a campaign directory; use another --out")


def _holds_complete_runs(out: Path) -> bool:
    """Whether ``out/runs`` holds a complete run (a campaign directory without one holds no
    result, and may be taken over by another campaign)."""
    runs = out / "runs"
    return runs.is_dir() and any(is_complete(directory) for directory in runs.iterdir())


def _execute(
    pending: list[RunConfig],
    runs_directory: Path,
    ledger: Ledger,
    workers: int,
    executor: str,
    address: str | None,
    console: Console | None,
) -> None:
    """Execute ``pending`` runs, recording each in ``ledger`` as soon as it ends."""
    columns = (
        TextColumn("{task.description:>8}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TextColumn("left"),
        TimeRemainingColumn(),
    )
    on_terminal = console is not None and console.is_terminal
    with Progress(*columns, console=console, disable=not on_terminal) as progress:
        # Ray reports a run only once it is done, so only the local executor counts episodes.
        log = None
        if console is not None and not on_terminal:  # a log file: lines instead of bars
            log = functools.partial(console.print, markup=False, highlight=False, soft_wrap=True)
        display = ProgressDisplay(
            progress, ledger, pending, show_episodes=executor == "local", log=log
        )

        def on_outcome(outcome: RunOutcome) -> None:
            unwritten = ledger.write_error
            ledger.record(outcome)
            display.run_ended(outcome)
            if console is None:
                return
            if outcome.summary is None:
                console.print(
                    f"[red]run {outcome.config.run_id} failed:[/red] {escape(str(outcome.error))}"
                )
            if ledger.write_error is not None and unwritten is None:
                console.print(
                    f"[red]{escape(str(ledger.path))} could not be written:[/red] "
                    f"{escape(str(ledger.write_error))}; it is tried again after each run"
                )

        def on_retry(run: RunConfig, how: str, attempt: int) -> None:
            display.run_restarted(run.run_id)
            if console is not None:
                console.print(
                    f"[yellow]run {run.run_id}: its worker process {how}; starting it again "
                    f"(attempt {attempt} of {WORKER_DEATH_RETRIES + 1})[/yellow]"
                )

        if executor == "ray":
            execute_on_ray(pending, runs_directory, workers, address, on_outcome)
        else:
            execute_locally(
                pending, runs_directory, workers, display.episodes_done, on_outcome, on_retry
            )
