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
