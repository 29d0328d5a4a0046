"""An estimate as a run: its configuration, its batches on disk, resuming, worker processes.

An estimate's directory holds ``config.json`` (what was asked), one ``batches/NNNNN.parquet``
per finished batch (each episode's draw, its log-likelihood under the model, its exact log
likelihood ratio, what it did) with the proposal it was drawn from (``NNNNN.json``), and, once
all batches are played, ``estimate.json`` (:mod:`hazardhunt.likelihood.results`). A batch is
written whole or not at all, so an interrupted estimate resumes at its first missing batch and
plays exactly the episodes it would have played (each batch's draws come from the seed and the
batch's number, its proposal from the batches before it).

The directory is data: nothing in it is imported or called.
"""

from __future__ import annotations

import json
import multiprocessing
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import pandas as pd
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from hazardhunt.campaign.config import EnvOptions
from hazardhunt.campaign.plugins import PluginSpec
from hazardhunt.campaign.run import build_simulation
from hazardhunt.errors import HazardhuntError, InputError
from hazardhunt.likelihood.distributions import Dimension
from hazardhunt.likelihood.encounters import (
    Draw,
    EncounterSource,
    Played,
    SimulationEncounters,
    played_row,
)
from hazardhunt.likelihood.estimators import (
    MIN_EPISODES,
    EstimatorParams,
    PlannedBatch,
    Planner,
    SamplingPlanner,
)
from hazardhunt.likelihood.people import load_model
from hazardhunt.likelihood.splitting import SplittingPlanner
from hazardhunt.likelihood.uncertainty import load_uncertainties
from hazardhunt.processes import die_with_parent
from hazardhunt.world.scenario import format_validation_error

WALKING_PERIOD = 0.2
"""The decision period of an estimate's human (s): a walker steers every control period."""


class EstimateConfig(BaseModel):
    """What an estimate is of, and how it spends its episodes."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    scenario: str = "crossing"
    field: str = "1.25m"
    people: str | None = None
    """The model of people: None for the built-in one, a model file or an import path."""
    uncertainties: str | None = None
    """The SUT's uncertainties: None for the built-in ones, ``none``, or a file."""
    controller: PluginSpec | None = None
    safety_layer: PluginSpec | None = None
    env: EnvOptions = EnvOptions(decision_period=WALKING_PERIOD)
    estimator: EstimatorParams = EstimatorParams()
    episodes: int = Field(default=2000, ge=MIN_EPISODES, le=10_000_000)
    seed: int = Field(default=0, ge=0, le=2**32 - 1)


class EstimateError(HazardhuntError):
    """An estimate that could not be done (every episode a SUT error, a weight that overflows)."""


def check_budget(config: EstimateConfig) -> None:
    """Refuse a budget too small for an interval.

    Raises:
        InputError: ``ce`` with fewer than three batches (one to look, one to move, one to
            use), ``splitting`` with too few episodes for two levels.
    """
    size, method, episodes = config.estimator.batch_size, config.estimator.method, config.episodes
    if method == "ce" and episodes < 3 * size:
        raise InputError(
            f"episodes: {episodes} episodes in batches of {size} give cross-entropy importance "
            f"sampling fewer than 3 batches; give at least {3 * size} episodes or a smaller "
            "--batch-size"
        )
    if method == "splitting" and episodes < 2 * size:
        raise InputError(
            f"episodes: {episodes} episodes give splitting with {size} samples per level fewer "
            f"than 2 levels; give at least {2 * size} episodes or a smaller --batch-size"
        )


def planner_of(config: EstimateConfig, dims: tuple[Dimension, ...], threshold: float) -> Planner:
    """The estimator of ``config``, which chooses each batch."""
    kind = SplittingPlanner if config.estimator.method == "splitting" else SamplingPlanner
    return kind(config.estimator, dims, threshold, config.episodes, config.seed)


def encounters_of(config: EstimateConfig) -> SimulationEncounters:
    """The encounters of ``config``: its simulation, people and uncertainties.

    Raises:
        InputError: A scenario, field, model or plug-in that does not load.
    """
    simulation = build_simulation(
        config.scenario, config.field, config.env, config.controller, config.safety_layer
    )
    model = load_model(config.people, simulation.scenario)
    return SimulationEncounters(simulation, model, load_uncertainties(config.uncertainties))


class EstimateRun:
    """Plays an estimate's missing batches into its directory."""

    def __init__(
        self,
        config: EstimateConfig,
        directory: Path,
        source: EncounterSource | None = None,
        workers: int = 1,
    ) -> None:
        """Args:
        config: The estimate.
        directory: Where its batches go (created; an estimate of another configuration
            already there is refused).
        source: What plays the encounters; built from ``config`` when None (and then, with
            more than one worker, in each worker process).
        workers: Processes that play a batch at once.

        Raises:
            InputError: The directory holds another estimate, or the budget is too small.
        """
        check_budget(config)
        self.config = config
        self.directory = directory
        self.source = source if source is not None else encounters_of(config)
        self.dimensions: tuple[Dimension, ...] = tuple(self.source.dimensions)
        self.workers = workers if source is None else 1
        self._pool: ProcessPoolExecutor | None = None
        _claim(directory, config)

    def played(self) -> list[pd.DataFrame]:
        """The finished batches, in order (stopping at the first missing one)."""
        tables: list[pd.DataFrame] = []
        while (path := batch_path(self.directory, len(tables))).exists():
            tables.append(pd.read_parquet(path))
        return tables

    def run(self, progress: Callable[[int, int], None] | None = None) -> pd.DataFrame:
        """Play every missing batch; the whole episode table.

        Args:
            progress: Called with (episodes played, episodes in all) after each batch.
        """
        tables = self.played()
        config = self.config
        planner = planner_of(config, self.dimensions, self.source.threshold)
        try:
            while (plan := planner.next_batch(tables)) is not None:
                played = sum(len(t) for t in tables)
                if progress is not None:
                    progress(played, config.episodes)
                table = self._table(len(tables), played, plan, self._play(plan.draws))
                _write_batch(self.directory, len(tables), table, plan.record)
                tables.append(table)
        finally:
            self.close()
        if progress is not None:
            progress(config.episodes, config.episodes)
        return pd.concat(tables, ignore_index=True)

    def _play(self, batch_draws: Sequence[Draw]) -> list[Played]:
        if self.workers <= 1:
            return [self.source.play(draw) for draw in batch_draws]
        if self._pool is None:
            self._pool = ProcessPoolExecutor(
                max_workers=self.workers,
                mp_context=multiprocessing.get_context("spawn"),
                initializer=_start_worker,
                initargs=(os.getpid(), self.config),
            )
        return list(self._pool.map(_play_in_worker, batch_draws, chunksize=4))

    def _table(
        self, batch: int, first: int, plan: PlannedBatch, played: Sequence[Played]
    ) -> pd.DataFrame:
        rows = []
        for i, (draw, outcome) in enumerate(zip(plan.draws, played, strict=True)):
            log_p = sum(dim.log_prob(draw.values[dim.name]) for dim in self.dimensions)
            rows.append(
                {
                    "episode": first + i,
                    "batch": batch,
                    **{f"x.{name}": value for name, value in draw.values.items()},
                    "noise_seed": draw.seed,
                    "log_p": log_p,
                    **{name: column[i] for name, column in plan.columns.items()},
                    **played_row(outcome),
                }
            )
        return pd.DataFrame(rows)

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)
            self._pool = None


def batch_path(directory: Path, batch: int) -> Path:
    return directory / "batches" / f"{batch:05d}.parquet"


def draw_of(row: Any, dims: Sequence[Dimension]) -> Draw:
    """The draw an episode table's row records."""
    return Draw({dim.name: float(row[f"x.{dim.name}"]) for dim in dims}, int(row["noise_seed"]))


def _write_batch(directory: Path, batch: int, table: pd.DataFrame, record: dict[str, Any]) -> None:
    """The batch's table and how it was drawn, each renamed into place once complete (the
    table last: a batch counts as played when its table is there)."""
    path = batch_path(directory, batch)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_suffix(".json.partial")
    partial.write_text(json.dumps({"batch": batch, **record}, indent=1) + "\n")
    partial.replace(path.with_suffix(".json"))
    partial = path.with_suffix(".parquet.partial")
    table.to_parquet(partial, index=False)
    partial.replace(path)


def _claim(directory: Path, config: EstimateConfig) -> None:
    """Write ``config.json``, or check that the one there is this estimate's."""
    path = directory / "config.json"
    wanted = config.model_dump(mode="json")
    if path.exists():
        # Read as a configuration, so that settings added since it was written take their
        # defaults: an estimate of an earlier version resumes.
        found = load_config(directory).model_dump(mode="json")
        if found != wanted:
            differ = sorted(k for k in set(found) | set(wanted) if found.get(k) != wanted.get(k))
            raise InputError(
                f"{directory}: holds an estimate of another configuration ({', '.join(differ)} "
                "differ); choose another --out or give the same options to resume it"
            )
        return
    directory.mkdir(parents=True, exist_ok=True)
    partial = path.with_suffix(".json.partial")
    partial.write_text(json.dumps(wanted, indent=1) + "\n")
    partial.replace(path)


def load_config(directory: Path) -> EstimateConfig:
    """The configuration of the estimate in ``directory``.

    Raises:
        InputError: There is none, or it does not read.
    """
    path = directory / "config.json"
    try:
        return EstimateConfig.model_validate_json(path.read_text())
    except OSError as error:
        raise InputError(f"{directory}: no estimate here ({error.strerror}: {path.name})") from None
    except ValidationError as error:
        raise InputError(f"{path}: {format_validation_error(error)}") from None


# A worker process's encounters, built once when the process starts.
_worker: SimulationEncounters | None = None


def _start_worker(parent_pid: int, config: EstimateConfig) -> None:
    global _worker
    die_with_parent(parent_pid)
    _worker = encounters_of(config)


def _play_in_worker(draw: Draw) -> Played:
    assert _worker is not None, "the worker was not started"
    return _worker.play(draw)
