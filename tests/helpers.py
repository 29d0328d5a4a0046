"""Helpers shared by the tests: the command as a user runs it, and run tables to compare."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pandas as pd

WALL_CLOCK_COLUMNS = ["wall_time_s", "solve_time_mean_s", "solve_time_median_s", "solve_time_max_s"]
"""Columns of episodes.parquet that measure wall-clock time and so differ between runs."""


def hazardhunt(
    *args: object, timeout: float = 300, cwd: Path | None = None
) -> subprocess.CompletedProcess[str]:
    """The ``hazardhunt`` command, as a user runs it (in ``cwd``, default the current one)."""
    return subprocess.run(
        [sys.executable, "-m", "hazardhunt.cli", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=cwd,
        # rich wraps at 80 columns when not on a terminal; errors must stay one line.
        env=os.environ | {"COLUMNS": "1000"},
        check=False,
    )


def run_tables(run_directory: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    """A run's episodes table (without wall-clock columns) and failures table."""
    episodes = pd.read_parquet(run_directory / "episodes.parquet").drop(columns=WALL_CLOCK_COLUMNS)
    return episodes, pd.read_parquet(run_directory / "failures.parquet")


MARKER_MODULE = """
from pathlib import Path

from hazardhunt.benchmark.conservative import ConservativeController as Controller

Path({marker!r}).touch()  # proof that the module was imported
"""


def marker_module(folder: Path, marker: Path, name: str = "marker_sut") -> str:
    """Write module ``name`` into ``folder``: importing it creates ``marker``; its
    ``Controller`` is a cheap one. Returns the controller's import path."""
    (folder / f"{name}.py").write_text(MARKER_MODULE.format(marker=str(marker)))
    return f"{name}:Controller"


def hostile_plugin(evidence: Path) -> dict[str, object]:
    """A plug-in as a stranger's file could name one: building it runs a shell command that
    creates ``evidence``."""
    return {"path": "os:system", "params": {"command": f"touch {evidence}"}}
