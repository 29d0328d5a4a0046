"""Run a configuration into a directory atomically, with a live progress bar."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from hazardhunt.campaign.config import ConfigError, RunConfig
from hazardhunt.campaign.run import ProgressCallback, RunProgress, execute_run, is_complete


def partial_directory(out: Path) -> Path:
    """Where a run into ``out`` is written until it completes."""
    return out.parent / f".{out.name}.partial"


def run_into(config: RunConfig, out: Path, console: Console | None = None) -> dict[str, Any]:
    """Execute ``config`` into ``out``, which appears only once the run is complete.

    A complete run already in ``out`` with the same configuration is kept and its summary
    returned; a leftover partial run is discarded and redone (runs are deterministic).

    Raises:
        ConfigError: ``out`` holds something else, or a run of another configuration.
    """
    if out.exists():
        if is_complete(out):
            stored = json.loads((out / "config.json").read_text())["run"]
            if RunConfig.model_validate(stored) != config:
                raise ConfigError(f"{out}: holds a finished run of another configuration")
            summary: dict[str, Any] = json.loads((out / "summary.json").read_text())
            if console is not None:
                console.print(f"{out}: already complete")
            return summary
        raise ConfigError(f"{out}: exists and is not a finished run; choose another --out")
    out.parent.mkdir(parents=True, exist_ok=True)
    if console is None:
        return execute_into_place(config, out)
    return _with_progress(config, out, console)


def execute_into_place(
    config: RunConfig, out: Path, progress: ProgressCallback | None = None
) -> dict[str, Any]:
    """Execute ``config`` into the hidden partial sibling of ``out`` (discarding any leftover
    there) and rename it to ``out`` once complete; the run's summary."""
    partial = partial_directory(out)
    if partial.exists():
        shutil.rmtree(partial)
    summary = execute_run(config, partial, progress)
    partial.rename(out)
    return summary


def _with_progress(config: RunConfig, out: Path, console: Console) -> dict[str, Any]:
    columns = (
        TextColumn(f"{config.run_id}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[rate]:.1f} episodes/s, {task.fields[failures]} failures"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
    )
    with Progress(*columns, console=console, transient=False) as progress:
        task = progress.add_task("run", total=config.episodes, rate=0.0, failures=0)

        def update(state: RunProgress) -> None:
            rate = state.episodes_done / state.elapsed_s if state.elapsed_s > 0 else 0.0
            progress.update(task, completed=state.episodes_done, rate=rate, failures=state.failures)

        return execute_into_place(config, out, update)
