"""The Ray executor: a campaign's runs as Ray tasks on a local or remote cluster; each task
returns its run directory as a tar archive, which is unpacked and renamed into place."""

from __future__ import annotations

import io
import json
import logging
import shutil
import tarfile
import tempfile
import warnings
from pathlib import Path
from typing import Any

from hazardhunt.campaign.config import RunConfig
from hazardhunt.campaign.ledger import RunOutcome, failed
from hazardhunt.campaign.local_executor import WORKER_DEATH_RETRIES, OnOutcome
from hazardhunt.campaign.records import RunSummary
from hazardhunt.campaign.run import is_finished, partial_directory, record_run
from hazardhunt.campaign.store import find_damage
from hazardhunt.sut.compat import ProtocolWarning
from hazardhunt.warning_lines import print_warning, show_warnings_in_one_line


def execute_on_ray(
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
                archive, node, given = ray.get(ready)
            except ray.exceptions.RayError as error:
                # The cause names the run's own exception; the error holds its remote traceback.
                cause = getattr(error, "cause", None) or error
                on_outcome(failed(run, cause, remote_traceback=str(error)))
                continue
            for text in given:
                print_warning(text)
            try:
                summary = _unpack(archive, runs_directory / run.run_id)
            except (OSError, RuntimeError) as error:
                on_outcome(failed(run, error))
                continue
            on_outcome(RunOutcome(run, summary, ray_node=node))
    except BaseException:
        for reference in pending:
            ray.cancel(reference, force=True)
        raise
    finally:
        if start_cluster:
            ray.shutdown()


def _run_packed(run: RunConfig) -> tuple[bytes, str, list[str]]:
    """Execute ``run`` in a scratch directory: that directory as a tar archive, the id of the
    Ray node it executed on, and the warnings hazardhunt gave, one line each after the run's id
    (the campaign process shows them: a worker's output does not reach it)."""
    import ray

    node = ray.get_runtime_context().get_node_id()
    given: list[str] = []
    with tempfile.TemporaryDirectory(prefix="hazardhunt-run-") as scratch:
        directory = Path(scratch) / run.run_id
        with warnings.catch_warnings():  # the campaign process said so once, before any run
            warnings.simplefilter("ignore", ProtocolWarning)
            show_warnings_in_one_line(given.append, prefix=f"{run.run_id}: ")
            record_run(run, directory)
        buffer = io.BytesIO()
        with tarfile.open(fileobj=buffer, mode="w") as archive:
            archive.add(directory, arcname=".")
        return buffer.getvalue(), node, given


def _unpack(archive: bytes, final: Path) -> RunSummary:
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
    summary: RunSummary = json.loads((final / "summary.json").read_text())
    return summary
