"""A campaign: every run of a grid, executed in parallel into one directory that survives a kill.

Layout of a campaign directory::

    campaign.json              the resolved campaign configuration (written first)
    runs/<run_id>/             one complete run directory each (see ``hazardhunt.campaign.store``)
    runs/.<run_id>.partial     a run in progress; deleted and redone when the campaign resumes
    summary.json               per run its summary, or its error; rewritten after each run
    .lock                      held (``flock``) by the one campaign process writing the directory

A run directory appears under its name only once the run is complete, so resuming is: keep the
complete runs, delete the partial ones and run them again. Runs are deterministic per seed, so a
redone run loses nothing and counts nothing twice.
"""

from __future__ import annotations

import ctypes
import fcntl
import io
import json
import logging
import multiprocessing
import os
import shutil
import signal
import statistics
import sys
import tarfile
import tempfile
import time
import traceback
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import datetime, timezone
from multiprocessing.queues import Queue
from pathlib import Path
from queue import Empty
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
from hazardhunt.campaign.run import (
    RunProgress,
    execute_run_atomically,
    is_complete,
    partial_directory,
    record_run,
)
from hazardhunt.campaign.store import write_json_atomic

EXECUTORS = ("local", "ray")
"""Where runs execute: a local process pool, or a Ray cluster."""

PROGRESS_INTERVAL_S = 0.5
"""Least time between two progress reports of a run to the campaign process, in s."""

_PR_SET_PDEATHSIG = 1


class CampaignFailed(Exception):  # noqa: N818 - names an outcome, as the command reports it
    """Some runs raised while the others completed; ``summary`` records which and why."""

    def __init__(self, summary: dict[str, Any]) -> None:
        super().__init__(
            f"{summary['runs_failed']} of {summary['runs_total']} runs raised (see summary.json)"
        )
        self.summary = summary


@dataclass(frozen=True)
class RunOutcome:
    """How one run of a campaign ended: its summary, or the error it raised."""

    config: RunConfig
    summary: dict[str, Any] | None
    error: str | None = None
    """``Type: message`` of the exception, when the run raised."""
    traceback: str | None = None


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

    Returns:
        The campaign summary, as written to ``out/summary.json``.

    Raises:
        ConfigError: ``out`` holds another campaign or something else, or another campaign
            process is writing it; nothing is written then.
        CampaignFailed: After all other runs finished, if some runs raised.
    """
    if executor not in EXECUTORS:
        raise ValueError(f"executor must be one of {', '.join(EXECUTORS)}, not {executor!r}")
    if workers < 1:
        raise ValueError(f"workers must be at least 1, not {workers}")
    runs = config.runs()
    _check_directory(config, out)
    out.mkdir(parents=True, exist_ok=True)
    with _exclusive_lock(out):
        _check_directory(config, out)  # another campaign may have claimed it before our lock
        if not _holds_complete_runs(out):  # else it holds this campaign: checked above
            write_json_atomic(out / "campaign.json", config.model_dump(mode="json"))
        runs_directory = out / "runs"
        runs_directory.mkdir(exist_ok=True)
        for leftover in runs_directory.glob(".*.partial"):
            shutil.rmtree(leftover)
        ledger = _Ledger(config, runs, out)
        _warn_of_other_versions(ledger, console)
        pending = [run for run in runs if ledger.status(run) != "complete"]
        if pending:
            _execute(pending, runs_directory, ledger, workers, executor, address, console)
        summary = ledger.write()
    if console is not None:
        _print_report(console, summary, out)
    if summary["runs_failed"]:
        raise CampaignFailed(summary)
    return summary


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


@contextmanager
def _exclusive_lock(out: Path) -> Iterator[None]:
    """Hold ``out/.lock``; the kernel drops the lock when the process dies, however it dies."""
    with open(out / ".lock", "a+") as handle:
        try:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            holder = handle.read().strip() or "?"
            raise ConfigError(
                f"{out}: another campaign (pid {holder}) is writing this directory"
            ) from None
        handle.truncate(0)
        handle.write(f"{os.getpid()}\n")
        handle.flush()
        yield


class _Ledger:
    """The campaign's ``summary.json``: how every run stands, rewritten after each change.

    Complete runs are read back from their own directories, so the ledger of a resumed campaign
    is right even if the previous campaign process died between a run and its ledger update.
    """

    def __init__(self, config: CampaignConfig, runs: list[RunConfig], out: Path) -> None:
        self.config = config
        self.path = out / "summary.json"
        self.entries: dict[str, dict[str, Any]] = {}
        for run in runs:
            directory = out / "runs" / run.run_id
            if is_complete(directory):
                stored = json.loads((directory / "summary.json").read_text())
                self.entries[run.run_id] = {"status": "complete"} | stored
            elif directory.exists():
                raise ConfigError(f"{directory}: not a complete run; delete it to redo the run")
            else:
                self.entries[run.run_id] = {"status": "pending"} | _run_keys(run)
        self.write()

    def status(self, run: RunConfig) -> str:
        """``complete``, ``failed`` or ``pending``."""
        return str(self.entries[run.run_id]["status"])

    def record(self, outcome: RunOutcome) -> None:
        """Store how a run ended and rewrite ``summary.json``."""
        run = outcome.config
        if outcome.summary is not None:
            entry = {"status": "complete"} | outcome.summary
        else:
            failure = {"error": outcome.error, "traceback": outcome.traceback}
            entry = {"status": "failed"} | _run_keys(run) | failure
        self.entries[run.run_id] = entry
        self.write()

    def summary(self) -> dict[str, Any]:
        """The campaign summary: totals, then one entry per run in grid order."""
        entries = list(self.entries.values())
        complete = [e for e in entries if e["status"] == "complete"]
        return {
            "campaign": self.config.model_dump(mode="json"),
            "runs_total": len(entries),
            "runs_complete": len(complete),
            "runs_failed": sum(e["status"] == "failed" for e in entries),
            "runs_pending": sum(e["status"] == "pending" for e in entries),
            "episodes": sum(e["episodes"] for e in complete),
            "failures": sum(e["failures"] for e in complete),
            "updated_at": datetime.now(timezone.utc).isoformat(),
            "runs": entries,
        }

    def write(self) -> dict[str, Any]:
        """Rewrite ``summary.json`` atomically; the summary written."""
        summary = self.summary()
        write_json_atomic(self.path, summary)
        return summary


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
        display = _ProgressDisplay(progress, ledger, pending, show_episodes=executor == "local")

        def on_outcome(outcome: RunOutcome) -> None:
            ledger.record(outcome)
            display.run_ended(outcome)
            if outcome.summary is None and console is not None:
                console.print(
                    f"[red]run {outcome.config.run_id} failed:[/red] {escape(str(outcome.error))}"
                )

        if executor == "ray":
            _execute_on_ray(pending, runs_directory, workers, address, on_outcome)
        else:
            _execute_locally(pending, runs_directory, workers, display.episodes_done, on_outcome)


class _ProgressDisplay:
    """Progress bars of the runs and of the episodes done, in complete and running runs."""

    def __init__(
        self, progress: Progress, ledger: _Ledger, pending: list[RunConfig], show_episodes: bool
    ) -> None:
        complete = [e for e in ledger.entries.values() if e["status"] == "complete"]
        self.progress = progress
        self.episodes_of_complete_runs = sum(int(e["episodes"]) for e in complete)
        self.episodes_total = self.episodes_of_complete_runs + sum(r.episodes for r in pending)
        self.in_flight: dict[str, int] = {}
        self.ended: set[str] = set()  # a run's last report may arrive after its end
        self.run_task = progress.add_task(
            "runs", total=len(ledger.entries), completed=len(complete)
        )
        self.episode_task = progress.add_task(
            "episodes", total=self.episodes_total, visible=show_episodes
        )
        self._show_episodes()

    def episodes_done(self, run_id: str, episodes_done: int) -> None:
        """A running run reports its episodes done so far."""
        if run_id not in self.ended:
            self.in_flight[run_id] = max(self.in_flight.get(run_id, 0), episodes_done)
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
        self._show_episodes()

    def _show_episodes(self) -> None:
        done = self.episodes_of_complete_runs + sum(self.in_flight.values())
        self.progress.update(self.episode_task, completed=done, total=self.episodes_total)


def _failed(run: RunConfig, error: BaseException) -> RunOutcome:
    return RunOutcome(
        run,
        None,
        f"{type(error).__name__}: {error}",
        "".join(traceback.format_exception(error)),
    )


# --- local executor ----------------------------------------------------------------------------


def _execute_locally(
    runs: list[RunConfig],
    runs_directory: Path,
    workers: int,
    on_episodes: OnEpisodes,
    on_outcome: OnOutcome,
) -> None:
    """Execute ``runs`` in a pool of spawned worker processes that die with this process."""
    context = multiprocessing.get_context("spawn")
    progress_queue: Queue[tuple[str, int]] = context.Queue()
    pool = ProcessPoolExecutor(
        max_workers=min(workers, len(runs)),
        mp_context=context,
        initializer=_initialize_worker,
        initargs=(os.getpid(), progress_queue),
    )
    try:
        futures = {pool.submit(_run_in_worker, run, runs_directory): run for run in runs}
        waiting: set[Future[dict[str, Any]]] = set(futures)
        while waiting:
            done, waiting = wait(waiting, timeout=PROGRESS_INTERVAL_S, return_when=FIRST_COMPLETED)
            _drain(progress_queue, on_episodes)
            for future in done:
                run = futures[future]
                try:
                    outcome = RunOutcome(run, future.result())
                except Exception as error:
                    outcome = _failed(run, error)
                on_outcome(outcome)
    except BaseException:
        # Without this, leaving (Ctrl-C) would wait for every run in flight to finish.
        processes = list((pool._processes or {}).values())  # public only from Python 3.14
        for process in processes:
            process.kill()
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown()
    progress_queue.close()


def _drain(progress_queue: Queue[tuple[str, int]], on_episodes: OnEpisodes) -> None:
    while True:
        try:
            run_id, episodes_done = progress_queue.get_nowait()
        except Empty:
            return
        on_episodes(run_id, episodes_done)


# The worker's end of the progress queue: a spawned process can only receive it at start-up.
_progress_queue: Queue[tuple[str, int]] | None = None


def _initialize_worker(campaign_pid: int, progress_queue: Queue[tuple[str, int]]) -> None:
    """Tie the worker's life to the campaign process, so that no orphan goes on writing."""
    global _progress_queue
    if sys.platform == "linux":
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        if libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL) != 0:
            errno = ctypes.get_errno()
            raise OSError(errno, f"prctl(PR_SET_PDEATHSIG): {os.strerror(errno)}")
    if os.getppid() != campaign_pid:  # the campaign died before prctl took effect
        os._exit(1)
    # Ctrl-C is the campaign process's to handle: it kills the workers.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    progress_queue.cancel_join_thread()  # an unread progress report must not block exit
    _progress_queue = progress_queue


def _run_in_worker(run: RunConfig, runs_directory: Path) -> dict[str, Any]:
    """Execute ``run`` into its partial directory and rename it into place once complete."""
    return execute_run_atomically(run, runs_directory / run.run_id, _progress_reporter(run.run_id))


def _progress_reporter(run_id: str) -> Callable[[RunProgress], None]:
    last_report = 0.0

    def report(state: RunProgress) -> None:
        nonlocal last_report
        now = time.monotonic()
        if _progress_queue is not None and now - last_report >= PROGRESS_INTERVAL_S:
            last_report = now
            _progress_queue.put_nowait((run_id, state.episodes_done))

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
        task = ray.remote(num_cpus=1)(_run_packed)
        pending = {task.remote(run): run for run in runs}
        while pending:
            # One at a time, so that a kill loses no run that already came back.
            [ready], _ = ray.wait(list(pending), num_returns=1)
            run = pending.pop(ready)
            try:
                archive = ray.get(ready)
            except ray.exceptions.RayError as error:
                # The cause names the run's own exception; the error holds its remote traceback.
                cause = getattr(error, "cause", None) or error
                on_outcome(RunOutcome(run, None, f"{type(cause).__name__}: {cause}", str(error)))
                continue
            on_outcome(RunOutcome(run, _unpack(archive, runs_directory / run.run_id)))
    except BaseException:
        for reference in pending:
            ray.cancel(reference, force=True)
        raise
    finally:
        if start_cluster:
            ray.shutdown()


def _run_packed(run: RunConfig) -> bytes:
    """Execute ``run`` in a scratch directory and return that directory as a tar archive."""
    with tempfile.TemporaryDirectory(prefix="hazardhunt-run-") as scratch:
        directory = Path(scratch) / run.run_id
        record_run(run, directory)
        buffer = io.BytesIO()
        with tarfile.open(fileobj=buffer, mode="w") as archive:
            archive.add(directory, arcname=".")
        return buffer.getvalue()


def _unpack(archive: bytes, final: Path) -> dict[str, Any]:
    """Unpack a run's archive into its partial directory, rename it into place; its summary."""
    partial = partial_directory(final)
    if partial.exists():
        shutil.rmtree(partial)
    partial.mkdir()
    with tarfile.open(fileobj=io.BytesIO(archive)) as members:
        if hasattr(tarfile, "data_filter"):
            members.extractall(partial, filter="data")
        else:  # pragma: no cover - Python < 3.10.12, and the archive is our own
            members.extractall(partial)
    if not is_complete(partial):
        raise RuntimeError(f"{final.name}: the run's archive holds no summary.json")
    partial.rename(final)
    summary: dict[str, Any] = json.loads((final / "summary.json").read_text())
    return summary


# --- report ------------------------------------------------------------------------------------


def _print_report(console: Console, summary: dict[str, Any], out: Path) -> None:
    """Per scenario x field x tester: failures over seeds (mean ± std) and mean wall time."""
    groups: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    for entry in summary["runs"]:
        key = (entry["scenario"], entry["field"], entry["tester"])
        groups.setdefault(key, []).append(entry)
    table = Table("scenario", "field", "tester", "runs", "failures", "wall time (s)")
    for (scenario, field, tester), entries in groups.items():
        complete = [e for e in entries if e["status"] == "complete"]
        failures = [float(e["failures"]) for e in complete]
        wall_times = [float(e["wall_time_s"]) for e in complete]
        table.add_row(
            scenario,
            field,
            tester,
            f"{len(complete)}/{len(entries)}",
            _mean_std(failures),
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
    if summary["runs_failed"]:
        console.print(
            f"[red]runs that raised: {summary['runs_failed']}[/red] (errors in summary.json); "
            "run the same command again to retry them"
        )


def _mean_std(values: list[float]) -> str:
    if not values:
        return "-"
    if len(values) == 1:
        return f"{values[0]:.1f}"
    return f"{statistics.fmean(values):.1f} ± {statistics.stdev(values):.1f}"
