"""The local executor: a campaign's runs in spawned worker processes on this machine, which die
with the campaign process; a worker that dies takes only its own run with it."""

from __future__ import annotations

import contextlib
import multiprocessing
import multiprocessing.connection
import os
import shutil
import signal
import time
import warnings
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing.connection import Connection
from multiprocessing.context import SpawnContext, SpawnProcess
from pathlib import Path

from hazardhunt.campaign.config import RunConfig
from hazardhunt.campaign.ledger import RunOutcome, failed
from hazardhunt.campaign.records import RunSummary
from hazardhunt.campaign.run import RunProgress, execute_run_atomically, partial_directory
from hazardhunt.errors import HazardhuntError
from hazardhunt.processes import die_with_parent
from hazardhunt.sut.compat import ProtocolWarning
from hazardhunt.warning_lines import print_warning, show_warnings_in_one_line

PROGRESS_INTERVAL_S = 0.5
"""Least time between two progress reports of a run to the campaign process, in s."""

WORKER_DEATH_RETRIES = 2
"""Times a run is started again, in a new worker process, after the process executing it died
(killed by a signal, say the out-of-memory killer's SIGKILL) before it is recorded as failed."""


class WorkerDied(HazardhuntError, RuntimeError):  # noqa: N818 - names an outcome, as summary.json reports it
    """The process executing a run ended without finishing it, every time it was tried."""


OnEpisodes = Callable[[str, int], None]
"""Called with a run id and its episodes done so far."""
OnOutcome = Callable[[RunOutcome], None]
OnRetry = Callable[[RunConfig, str, int], None]
"""Called with a run whose worker died, how it died, and the attempt about to start."""


def execute_locally(
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
        on_outcome(failed(run, error))


@dataclass(frozen=True)
class _Warning:
    """A warning hazardhunt gave in a worker, as one line: shown by the campaign process."""

    text: str


class _Worker:
    """A worker process of the local executor: executes the runs it is sent, one at a time,
    and sends back progress reports, warnings and each run's outcome over its own pipe (so
    that a worker killed mid-message disturbs no other)."""

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
        """Read what the worker sent: progress reports, warnings (shown on stderr, which the
        campaign's progress display prints above its bars), and its run's outcome once it
        ended; ``alive`` turns False if its process has ended."""
        outcome = None
        try:
            while self.connection.poll():
                message = self.connection.recv()
                if isinstance(message, RunOutcome):
                    outcome, self.run = message, None
                elif isinstance(message, _Warning):
                    print_warning(message.text)
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


def _serve(connection: Connection, campaign_pid: int, runs_directory: Path) -> None:
    """A worker process: execute each run the campaign process sends until it sends None."""
    _initialize_worker(campaign_pid)
    while True:
        try:
            run = connection.recv()
        except EOFError:  # the campaign process is gone
            return
        if run is None:
            return
        try:
            outcome = RunOutcome(run, _run_in_worker(run, runs_directory, connection))
        except BaseException as error:  # SystemExit too: the run failed, not the worker
            outcome = failed(run, error)
        connection.send(outcome)


def _initialize_worker(campaign_pid: int) -> None:
    """Tie the worker's life to the campaign process, so that no orphan goes on writing, and
    leave warnings the campaign process gave to it."""
    die_with_parent(campaign_pid)
    # Ctrl-C is the campaign process's to handle: it kills the workers.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # A plug-in of an earlier protocol: the campaign process said so once, before any run.
    warnings.filterwarnings("ignore", category=ProtocolWarning)


def _run_in_worker(run: RunConfig, runs_directory: Path, connection: Connection) -> RunSummary:
    """Execute ``run`` into its partial directory and rename it into place once complete,
    reporting its progress over ``connection``, and hazardhunt's warnings, one line each after
    the run's id."""
    reporter = _progress_reporter(run.run_id, connection)
    with warnings.catch_warnings():
        show_warnings_in_one_line(
            lambda text: connection.send(_Warning(text)), prefix=f"{run.run_id}: "
        )
        return execute_run_atomically(run, runs_directory / run.run_id, reporter)


def _progress_reporter(run_id: str, connection: Connection) -> Callable[[RunProgress], None]:
    """Sends a run's episodes done to the campaign process, at most every
    ``PROGRESS_INTERVAL_S``."""
    last_report = 0.0

    def report(state: RunProgress) -> None:
        nonlocal last_report
        now = time.monotonic()
        if now - last_report >= PROGRESS_INTERVAL_S:
            last_report = now
            connection.send((run_id, state.episodes_done))

    return report
