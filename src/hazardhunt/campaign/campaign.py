"""A campaign: every run of a grid, executed in parallel into one directory that survives a kill.

Layout of a campaign directory::

    campaign.json              the resolved campaign configuration (written first)
    runs/<run_id>/             one complete run directory each (see ``hazardhunt.campaign.store``)
    runs/.<run_id>.partial     a run in progress; deleted and redone when the campaign resumes
    summary.json               per run its summary, or its error; rewritten after each run
    .lock                      held (``flock``) by the one campaign process writing the directory

A run directory appears under its name only once the run is complete, so resuming is: keep the
complete runs whose files match the checksums they recorded, delete the partial and damaged
ones and run them again. Runs are deterministic per seed, so a redone run loses nothing and
counts nothing twice. A run whose worker process dies (killed by the out-of-memory killer, say)
is started again in a new worker, up to ``WORKER_DEATH_RETRIES`` times.
"""

from __future__ import annotations

import contextlib
import ctypes
import fnmatch
import functools
import io
import json
import logging
import multiprocessing
import multiprocessing.connection
import os
import shutil
import signal
import statistics
import sys
import tarfile
import tempfile
import time
import traceback
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from multiprocessing.connection import Connection
from multiprocessing.context import SpawnContext, SpawnProcess
from pathlib import Path
from typing import Any

from pydantic import ValidationError
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
from rich.table import Table

import hazardhunt
from hazardhunt.campaign.config import CampaignConfig, ConfigError, RunConfig
from hazardhunt.campaign.lock import exclusive_lock
from hazardhunt.campaign.run import (
    RunProgress,
    check_sut,
    execute_run_atomically,
    is_complete,
    is_finished,
    partial_directory,
    record_run,
)
from hazardhunt.campaign.store import campaign_totals, find_damage, write_json_atomic
from hazardhunt.errors import HazardhuntError

EXECUTORS = ("local", "ray")
"""Where runs execute: a local process pool, or a Ray cluster."""

PROGRESS_INTERVAL_S = 0.5
"""Least time between two progress reports of a run to the campaign process, in s."""
LOG_INTERVAL_S = 600.0
"""Time between two progress lines when the campaign's output is not a terminal (a log file,
where progress bars do not show), in s; every run that ends writes one too."""

WORKER_DEATH_RETRIES = 2
"""Times a run is started again, in a new worker process, after the process executing it died
(killed by a signal, say the out-of-memory killer's SIGKILL) before it is recorded as failed."""

_PR_SET_PDEATHSIG = 1


class CampaignFailed(HazardhuntError):  # noqa: N818 - names an outcome, as the command reports it
    """Some runs raised while the others completed (``summary`` records which and why), or the
    campaign's ``summary.json`` could not be written."""

    def __init__(self, summary: dict[str, Any], reason: str | None = None) -> None:
        super().__init__(
            reason
            or f"{summary['runs_failed']} of {summary['runs_total']} runs raised (see summary.json)"
        )
        self.summary = summary


class WorkerDied(HazardhuntError, RuntimeError):  # noqa: N818 - names an outcome, as summary.json reports it
    """The process executing a run ended without finishing it, every time it was tried."""


@dataclass(frozen=True)
class RunOutcome:
    """How one run of a campaign ended: its summary, or the error it raised."""

    config: RunConfig
    summary: dict[str, Any] | None
    error: str | None = None
    """``Type: message`` of the exception, when the run raised."""
    traceback: str | None = None
    ray_node: str | None = None
    """The id of the Ray node that executed the run (the ``ray`` executor only)."""


OnEpisodes = Callable[[str, int], None]
"""Called with a run id and its episodes done so far."""
OnOutcome = Callable[[RunOutcome], None]


def run_campaign(
    config: CampaignConfig,
    out: Path,
    *,
    workers: int = 1,
    executor: str = "local",
    address: str | None = None,
    console: Console | None = None,
    only: Sequence[str] = (),
) -> dict[str, Any]:
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
    out.mkdir(parents=True, exist_ok=True)
    with exclusive_lock(out / ".lock", out, "campaign"):
        _check_directory(config, out)  # another campaign may have claimed it before our lock
        if not _holds_complete_runs(out):  # else it holds this campaign: checked above
            write_json_atomic(out / "campaign.json", config.model_dump(mode="json"))
        runs_directory = out / "runs"
        runs_directory.mkdir(exist_ok=True)
        for leftover in runs_directory.glob(".*.partial"):
            shutil.rmtree(leftover)
        ledger = _Ledger(config, runs, out)
        _redo_damaged(ledger, runs_directory, console)
        _warn_of_other_versions(ledger, console)
        pending = [run for run in selected if ledger.status(run) != "complete"]
        if pending:
            _execute(pending, runs_directory, ledger, workers, executor, address, console)
        summary = ledger.write()
    if console is not None:
        _print_report(console, summary, out)
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


def _redo_damaged(ledger: _Ledger, runs_directory: Path, console: Console | None) -> None:
    """Remove the finished runs whose files are damaged, so that they are run again."""
    for run_id, damage in ledger.damaged.items():
        if console is not None:
            console.print(
                f"[yellow]warning:[/yellow] run {escape(run_id)} is damaged ({escape(damage)}); "
                "running it again"
            )
        shutil.rmtree(runs_directory / run_id)


def _warn_of_other_versions(ledger: _Ledger, console: Console | None) -> None:
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
        try:
            stored = CampaignConfig.model_validate_json(stored_file.read_bytes())
        except (OSError, ValidationError):
            raise ConfigError(
                f"{stored_file}: not a campaign configuration; use another --out"
            ) from None
        if stored != config:
            raise ConfigError(
                f"{out}: holds a different campaign ({_first_difference(stored, config)}); "
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


def _first_difference(stored: CampaignConfig, given: CampaignConfig) -> str:
    stored_values, given_values = stored.model_dump(mode="json"), given.model_dump(mode="json")
    key = next(k for k in stored_values if stored_values[k] != given_values[k])
    return f"{key}: there {stored_values[key]!r}, here {given_values[key]!r}"


class _Ledger:
    """The campaign's ``summary.json``: how every run stands, rewritten after each change.

    Complete runs are read back from their own directories, so the ledger of a resumed campaign
    is right even if the previous campaign process died between a run and its ledger update. A
    finished run whose files do not match its checksums is ``damaged`` and pending.
    """

    def __init__(self, config: CampaignConfig, runs: list[RunConfig], out: Path) -> None:
        self.config = config
        self.path = out / "summary.json"
        self.entries: dict[str, dict[str, Any]] = {}
        self.damaged: dict[str, str] = {}
        """Run id -> what is wrong with its files."""
        self.write_error: OSError | None = None
        """Why the last write of ``summary.json`` failed; None once one succeeded."""
        for run in runs:
            directory = out / "runs" / run.run_id
            if is_finished(directory):
                damage = find_damage(directory)
                if damage is None:
                    stored = json.loads((directory / "summary.json").read_text())
                    self.entries[run.run_id] = {"status": "complete"} | _ledger_entry(stored)
                    continue
                self.damaged[run.run_id] = damage
            elif directory.exists():
                raise ConfigError(f"{directory}: not a complete run; delete it to redo the run")
            self.entries[run.run_id] = {"status": "pending"} | _run_keys(run)
        self.write()

    def status(self, run: RunConfig) -> str:
        """``complete``, ``failed`` or ``pending``."""
        return str(self.entries[run.run_id]["status"])

    def record(self, outcome: RunOutcome) -> None:
        """Store how a run ended and rewrite ``summary.json``."""
        run = outcome.config
        if outcome.summary is not None:
            entry = {"status": "complete"} | _ledger_entry(outcome.summary)
            if outcome.ray_node is not None:
                entry["ray_node"] = outcome.ray_node
        else:
            failure = {"error": outcome.error, "traceback": outcome.traceback}
            entry = {"status": "failed"} | _run_keys(run) | failure
        self.entries[run.run_id] = entry
        self.write()

    def summary(self) -> dict[str, Any]:
        """The campaign summary: totals, then one entry per run in grid order."""
        entries = list(self.entries.values())
        return {
            "campaign": self.config.model_dump(mode="json"),
            **campaign_totals(entries),
            "updated_at": datetime.now(timezone.utc).isoformat(),
            "runs": entries,
        }

    def write(self) -> dict[str, Any]:
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


def _ledger_entry(summary: dict[str, Any]) -> dict[str, Any]:
    """A run's summary as the ledger keeps it: without the checksums of its files."""
    return {key: value for key, value in summary.items() if key != "checksums"}


def _run_keys(run: RunConfig) -> dict[str, Any]:
    return {
        "run_id": run.run_id,
        "scenario": run.scenario,
        "field": run.field,
        "tester": run.tester,
        "seed": run.seed,
    }


def _execute(
    pending: list[RunConfig],
    runs_directory: Path,
    ledger: _Ledger,
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
    with Progress(*columns, console=console, disable=console is None) as progress:
        # Ray reports a run only once it is done, so only the local executor counts episodes.
        log = None
        if console is not None and not console.is_terminal:
            log = functools.partial(console.print, markup=False, highlight=False, soft_wrap=True)
        display = _ProgressDisplay(
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
            _execute_on_ray(pending, runs_directory, workers, address, on_outcome)
        else:
            _execute_locally(
                pending, runs_directory, workers, display.episodes_done, on_outcome, on_retry
            )


class _ProgressDisplay:
    """Progress bars of the runs and of the episodes done, in complete and running runs."""

    def __init__(
        self,
        progress: Progress,
        ledger: _Ledger,
        pending: list[RunConfig],
        show_episodes: bool,
        log: Callable[[str], None] | None = None,
    ) -> None:
        """Args:
        progress: Where the bars are drawn.
        ledger: The campaign's runs and how they stand.
        pending: The runs about to be executed.
        show_episodes: Whether the episodes done are counted (not with Ray).
        log: Where a line of progress goes every ``LOG_INTERVAL_S`` and at each run's end,
            for output that is not a terminal; None for none.
        """
        complete = [e for e in ledger.entries.values() if e["status"] == "complete"]
        self.progress = progress
        self.log = log
        self.logged_at = time.monotonic()
        # A slice (--runs) counts the runs it executes and those already complete, not the
        # runs it leaves pending, as the episodes do.
        self.runs_ended, self.runs_total = len(complete), len(complete) + len(pending)
        self.episodes_of_complete_runs = sum(int(e["episodes"]) for e in complete)
        self.episodes_total = self.episodes_of_complete_runs + sum(r.episodes for r in pending)
        self.in_flight: dict[str, int] = {}
        self.ended: set[str] = set()  # a run's last report may arrive after its end
        self.run_task = progress.add_task("runs", total=self.runs_total, completed=len(complete))
        self.episode_task = progress.add_task(
            "episodes", total=self.episodes_total, visible=show_episodes
        )
        self._show_episodes()

    def episodes_done(self, run_id: str, episodes_done: int) -> None:
        """A running run reports its episodes done so far."""
        if run_id not in self.ended:
            self.in_flight[run_id] = max(self.in_flight.get(run_id, 0), episodes_done)
            self._show_episodes()

    def run_restarted(self, run_id: str) -> None:
        """A run starts again from its first episode."""
        self.in_flight.pop(run_id, None)
        self._show_episodes()

    def run_ended(self, outcome: RunOutcome) -> None:
        """A run completed or raised."""
        self.ended.add(outcome.config.run_id)
        self.in_flight.pop(outcome.config.run_id, None)
        if outcome.summary is not None:
            self.episodes_of_complete_runs += int(outcome.summary["episodes"])
        else:
            self.episodes_total -= outcome.config.episodes
        self.progress.advance(self.run_task)
        self.runs_ended += 1
        self._show_episodes()
        if self.log is not None:
            how = "failed"
            if outcome.summary is not None:
                errors = outcome.summary.get("sut_errors", 0)
                how = "complete" + (f" with {errors} SUT errors" if errors else "")
            self.log(f"run {outcome.config.run_id} {how}: {self._standing()}")
            self.logged_at = time.monotonic()

    def _show_episodes(self) -> None:
        done = self.episodes_of_complete_runs + sum(self.in_flight.values())
        self.progress.update(self.episode_task, completed=done, total=self.episodes_total)
        if self.log is not None and time.monotonic() - self.logged_at >= LOG_INTERVAL_S:
            self.log(self._standing())
            self.logged_at = time.monotonic()

    def _standing(self) -> str:
        """How far the campaign is, in one line."""
        done = self.episodes_of_complete_runs + sum(self.in_flight.values())
        share = done / self.episodes_total if self.episodes_total else 1.0
        return (
            f"{self.runs_ended} of {self.runs_total} runs ended, "
            f"{done:,} of {self.episodes_total:,} episodes ({share:.0%})"
        )


def _failed(run: RunConfig, error: BaseException) -> RunOutcome:
    return RunOutcome(
        run,
        None,
        f"{type(error).__name__}: {error}",
        "".join(traceback.format_exception(error)),
    )


# --- local executor ----------------------------------------------------------------------------


OnRetry = Callable[[RunConfig, str, int], None]
"""Called with a run whose worker process died, how it died, and the attempt about to start."""


def _execute_locally(
    runs: list[RunConfig],
    runs_directory: Path,
    workers: int,
    on_episodes: OnEpisodes,
    on_outcome: OnOutcome,
    on_retry: OnRetry,
) -> None:
    """Execute ``runs`` in up to ``workers`` spawned worker processes that die with this one.

    A worker that dies takes only its own run with it: a new worker takes its place, and the
    run is started again up to ``WORKER_DEATH_RETRIES`` times before it is recorded as failed
    with how its worker died.
    """
    context = multiprocessing.get_context("spawn")
    queue = deque(runs)
    deaths: dict[str, int] = {}
    pool: list[_Worker] = []
    try:
        while queue or pool:
            pool = _assign(pool, queue, workers, context, runs_directory)
            handles = [w.connection for w in pool] + [w.process.sentinel for w in pool]
            ready = multiprocessing.connection.wait(handles, PROGRESS_INTERVAL_S)
            for worker in [w for w in pool if {w.connection, w.process.sentinel} & set(ready)]:
                outcome = worker.receive(on_episodes)
                if outcome is not None:
                    on_outcome(outcome)
                if not worker.alive:
                    pool.remove(worker)
                    _worker_died(worker, runs_directory, queue, deaths, on_outcome, on_retry)
    except BaseException:
        # Without this, leaving (Ctrl-C) would wait for every run in flight to finish.
        for worker in pool:
            worker.process.kill()
        raise


def _assign(
    pool: list[_Worker],
    queue: deque[RunConfig],
    workers: int,
    context: SpawnContext,
    runs_directory: Path,
) -> list[_Worker]:
    """The pool once every idle worker has a queued run, new workers (up to ``workers``) have
    the others, and the workers left idle are stopped."""
    kept = []
    for worker in pool:
        if worker.run is None:
            if not queue:
                worker.stop()
                continue
            worker.assign(queue.popleft())
        kept.append(worker)
    while queue and len(kept) < workers:
        worker = _Worker.start(context, runs_directory)
        worker.assign(queue.popleft())
        kept.append(worker)
    return kept


def _worker_died(
    worker: _Worker,
    runs_directory: Path,
    queue: deque[RunConfig],
    deaths: dict[str, int],
    on_outcome: OnOutcome,
    on_retry: OnRetry,
) -> None:
    """Queue the run of a dead worker again, or record it as failed after too many deaths;
    either way, remove what it left of the run."""
    run, how = worker.run, worker.death()
    if run is None:
        return
    shutil.rmtree(partial_directory(runs_directory / run.run_id), ignore_errors=True)
    deaths[run.run_id] = attempts = deaths.get(run.run_id, 0) + 1
    if attempts <= WORKER_DEATH_RETRIES:
        on_retry(run, how, attempts + 1)
        queue.appendleft(run)
    else:
        error = WorkerDied(f"its worker process {how}, on each of {attempts} attempts")
        on_outcome(_failed(run, error))


class _Worker:
    """A worker process of the local executor: executes the runs it is sent, one at a time,
    and sends back progress reports and each run's outcome over its own pipe (so that a
    worker killed mid-message disturbs no other)."""

    def __init__(self, process: SpawnProcess, connection: Connection) -> None:
        self.process = process
        self.connection = connection
        self.run: RunConfig | None = None
        """The run it executes; None while idle."""
        self.alive = True
        """False once its process has ended."""

    @classmethod
    def start(cls, context: SpawnContext, runs_directory: Path) -> _Worker:
        """A new worker process."""
        connection, worker_end = context.Pipe()
        process = context.Process(
            target=_serve, args=(worker_end, os.getpid(), runs_directory), name="hazardhunt-run"
        )
        process.start()
        worker_end.close()  # so that the worker's death reads as the end of the pipe
        return cls(process, connection)

    def assign(self, run: RunConfig) -> None:
        """Send it ``run`` to execute."""
        self.run = run
        with contextlib.suppress(OSError):  # a worker that died is found so by ``receive``
            self.connection.send(run)

    def receive(self, on_episodes: OnEpisodes) -> RunOutcome | None:
        """Read what the worker sent: progress reports, and its run's outcome once it ended;
        ``alive`` turns False if its process has ended."""
        outcome = None
        try:
            while self.connection.poll():
                message = self.connection.recv()
                if isinstance(message, RunOutcome):
                    outcome, self.run = message, None
                else:
                    on_episodes(*message)
        except (EOFError, OSError):
            self.alive = False
        if not self.process.is_alive():
            self.alive = False
        return outcome

    def death(self) -> str:
        """How its process ended, once it has: "was killed by SIGKILL", "exited with code 1"."""
        self.process.join()
        code = self.process.exitcode or 0
        if code < 0:
            return f"was killed by {signal.Signals(-code).name}"
        return f"exited with code {code}"

    def stop(self) -> None:
        """Tell the idle worker to exit, and wait until it has."""
        with contextlib.suppress(OSError):
            self.connection.send(None)
        self.process.join(timeout=30)
        if self.process.is_alive():
            self.process.kill()
            self.process.join()
        self.connection.close()


# The worker's end of its pipe to the campaign process, for progress reports.
_connection: Connection | None = None


def _serve(connection: Connection, campaign_pid: int, runs_directory: Path) -> None:
    """A worker process: execute each run the campaign process sends until it sends None."""
    global _connection
    _initialize_worker(campaign_pid)
    _connection = connection
    while True:
        try:
            run = connection.recv()
        except EOFError:  # the campaign process is gone
            return
        if run is None:
            return
        try:
            outcome = RunOutcome(run, _run_in_worker(run, runs_directory))
        except Exception as error:
            outcome = _failed(run, error)
        connection.send(outcome)


def _initialize_worker(campaign_pid: int) -> None:
    """Tie the worker's life to the campaign process, so that no orphan goes on writing."""
    if sys.platform == "linux":
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        if libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL) != 0:
            errno = ctypes.get_errno()
            raise OSError(errno, f"prctl(PR_SET_PDEATHSIG): {os.strerror(errno)}")
    if os.getppid() != campaign_pid:  # the campaign died before prctl took effect
        os._exit(1)
    # Ctrl-C is the campaign process's to handle: it kills the workers.
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _run_in_worker(run: RunConfig, runs_directory: Path) -> dict[str, Any]:
    """Execute ``run`` into its partial directory and rename it into place once complete."""
    return execute_run_atomically(run, runs_directory / run.run_id, _progress_reporter(run.run_id))


def _progress_reporter(run_id: str) -> Callable[[RunProgress], None]:
    last_report = 0.0

    def report(state: RunProgress) -> None:
        nonlocal last_report
        now = time.monotonic()
        if _connection is not None and now - last_report >= PROGRESS_INTERVAL_S:
            last_report = now
            _connection.send((run_id, state.episodes_done))

    return report


# --- Ray executor ------------------------------------------------------------------------------


def _execute_on_ray(
    runs: list[RunConfig],
    runs_directory: Path,
    workers: int,
    address: str | None,
    on_outcome: OnOutcome,
) -> None:
    """Execute ``runs`` as Ray tasks; each returns its run directory as a tar archive."""
    import ray

    start_cluster = address is None and not ray.is_initialized()
    ray.init(
        address=address,
        num_cpus=None if address is not None else workers,
        ignore_reinit_error=True,
        include_dashboard=False,
        log_to_driver=False,
        logging_level=logging.ERROR,
    )
    pending: dict[Any, RunConfig] = {}
    try:
        # Ray starts a task whose worker died again by itself, as many times as ours.
        task = ray.remote(num_cpus=1, max_retries=WORKER_DEATH_RETRIES)(_run_packed)
        pending = {task.remote(run): run for run in runs}
        while pending:
            # One at a time, so that a kill loses no run that already came back.
            [ready], _ = ray.wait(list(pending), num_returns=1)
            run = pending.pop(ready)
            try:
                archive, node = ray.get(ready)
            except ray.exceptions.RayError as error:
                # The cause names the run's own exception; the error holds its remote traceback.
                cause = getattr(error, "cause", None) or error
                on_outcome(RunOutcome(run, None, f"{type(cause).__name__}: {cause}", str(error)))
                continue
            try:
                summary = _unpack(archive, runs_directory / run.run_id)
            except (OSError, RuntimeError) as error:
                on_outcome(_failed(run, error))
                continue
            on_outcome(RunOutcome(run, summary, ray_node=node))
    except BaseException:
        for reference in pending:
            ray.cancel(reference, force=True)
        raise
    finally:
        if start_cluster:
            ray.shutdown()


def _run_packed(run: RunConfig) -> tuple[bytes, str]:
    """Execute ``run`` in a scratch directory: that directory as a tar archive, and the id of
    the Ray node it executed on."""
    import ray

    node = ray.get_runtime_context().get_node_id()
    with tempfile.TemporaryDirectory(prefix="hazardhunt-run-") as scratch:
        directory = Path(scratch) / run.run_id
        record_run(run, directory)
        buffer = io.BytesIO()
        with tarfile.open(fileobj=buffer, mode="w") as archive:
            archive.add(directory, arcname=".")
        return buffer.getvalue(), node


def _unpack(archive: bytes, final: Path) -> dict[str, Any]:
    """Unpack a run's archive into its partial directory, rename it into place; its summary.

    Raises:
        OSError: It could not be written (the partial directory is removed).
        RuntimeError: The archive holds no complete run.
    """
    partial = partial_directory(final)
    if partial.exists():
        shutil.rmtree(partial)
    try:
        partial.mkdir()
        with tarfile.open(fileobj=io.BytesIO(archive)) as members:
            if hasattr(tarfile, "data_filter"):
                members.extractall(partial, filter="data")
            else:  # pragma: no cover - Python < 3.10.12, and the archive is our own
                members.extractall(partial)
        if not is_finished(partial):
            raise RuntimeError(f"{final.name}: the run's archive holds no summary.json")
        damage = find_damage(partial)
        if damage is not None:
            raise RuntimeError(f"{final.name}: the run's archive is damaged ({damage})")
        partial.rename(final)
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)
        raise
    summary: dict[str, Any] = json.loads((final / "summary.json").read_text())
    return summary


# --- report ------------------------------------------------------------------------------------


def shown_scenario(scenario: str) -> str:
    """A scenario as the campaign's table shows it: a built-in by its name, a file by its path
    relative to the working directory when it lies below it, or else by its file name."""
    if not scenario.endswith(".toml"):
        return scenario
    path = Path(scenario)
    with contextlib.suppress(ValueError):
        return str(path.resolve().relative_to(Path.cwd().resolve()))
    return path.name


def _print_report(console: Console, summary: dict[str, Any], out: Path) -> None:
    """Per scenario x field x tester: failures of the run, or over seeds their mean ± std, and
    the mean wall time."""
    groups: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    for entry in summary["runs"]:
        key = (entry["scenario"], entry["field"], entry["tester"])
        groups.setdefault(key, []).append(entry)
    table = Table("scenario", "field", "tester", "runs", "failures", "SUT errors", "wall time (s)")
    for (scenario, field, tester), entries in groups.items():
        complete = [e for e in entries if e["status"] == "complete"]
        failures = [int(e["failures"]) for e in complete]
        sut_errors = sum(int(e.get("sut_errors", 0)) for e in complete)
        wall_times = [float(e["wall_time_s"]) for e in complete]
        table.add_row(
            escape(shown_scenario(scenario)),
            escape(field),
            escape(tester),
            f"{len(complete)}/{len(entries)}",
            _mean_std(failures),
            f"[red]{sut_errors}[/red]" if sut_errors else "0",
            f"{statistics.fmean(wall_times):.1f}" if wall_times else "-",
        )
    console.print(table)
    for entry in summary["runs"]:
        if entry["status"] == "failed":
            console.print(f"[red]failed:[/red] {entry['run_id']}: {escape(str(entry['error']))}")
    console.print(
        f"{summary['runs_complete']}/{summary['runs_total']} runs complete, "
        f"{summary['failures']} failures in {summary['episodes']} episodes; "
        f"results in [bold]{out.resolve()}[/bold] (summary.json, runs/)"
    )
    if summary.get("sut_errors"):
        console.print(
            f"[red]warning: {summary['sut_errors']} episodes ended in a SUT error and tested "
            "nothing[/red] (the column SUT errors; each run's first in its summary.json)"
        )
    if summary["runs_failed"]:
        console.print(
            f"[red]runs that raised: {summary['runs_failed']}[/red] (errors in summary.json); "
            "run the same command again to retry them"
        )
    if summary["runs_pending"]:
        console.print(
            f"{summary['runs_pending']} runs not run yet: run the campaign again (with other "
            "--runs patterns, or without) to run them"
        )


def _mean_std(counts: list[int]) -> str:
    """One run's count as it is; the mean ± standard deviation of several."""
    if not counts:
        return "-"
    if len(counts) == 1:
        return str(counts[0])
    return f"{statistics.fmean(counts):.1f} ± {statistics.stdev(counts):.1f}"
