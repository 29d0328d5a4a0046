"""An estimate as a run: its configuration, its batches on disk, resuming, worker processes.

An estimate's directory holds ``config.json`` (what was asked), one ``batches/NNNNN.parquet``
per finished batch (each episode's draw, its log-likelihood under the model, its exact log
likelihood ratio, what it did) with the proposal it was drawn from (``NNNNN.json``), and, once
all batches are played, ``estimate.json`` (:mod:`hazardhunt.likelihood.results`). A batch is
written whole or not at all, so an interrupted estimate resumes at its first missing batch and
plays exactly the episodes it would have played (each batch's draws come from the seed and the
batch's number, its proposal from the batches before it).

The directory is data: nothing in it is imported or called, and it holds no symbolic link.

The module is long because the directory is one format: what writes it (the run, its batches,
its worker processes) and what checks a directory before anything is played in it (claiming,
resuming, extending, the models it recorded) are kept side by side.
"""

from __future__ import annotations

import contextlib
import json
import multiprocessing
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import pandas as pd
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from hazardhunt.campaign.config import EnvOptions, first_difference, scenario_field
from hazardhunt.campaign.plugins import PluginSpec
from hazardhunt.campaign.simulations import build_simulation, try_sut
from hazardhunt.campaign.store import symbolic_link_in
from hazardhunt.errors import HazardhuntError, InputError
from hazardhunt.file_writes import file_written
from hazardhunt.likelihood.distributions import Dimension
from hazardhunt.likelihood.encounters import (
    Draw,
    EncounterSource,
    Played,
    SimulationEncounters,
    played_row,
)
from hazardhunt.likelihood.estimators import (
    BATCH_SIZE,
    MIN_EPISODES,
    EstimatorParams,
    PlannedBatch,
    Planner,
    SamplingPlanner,
)
from hazardhunt.likelihood.model_record import Models, models_recorded
from hazardhunt.likelihood.people import (
    CHECK_SAMPLES,
    DEFAULT_MODEL,
    ModelError,
    ModelPlayError,
    PluginModel,
    finite_log_prob,
    load_model,
    try_model,
)
from hazardhunt.likelihood.splitting import SplittingPlanner
from hazardhunt.likelihood.uncertainty import load_uncertainties
from hazardhunt.processes import die_with_parent
from hazardhunt.sut.guard import notice_ctrl_c
from hazardhunt.textfiles import format_validation_error

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
    digests: dict[str, str] | None = None
    """The SHA-256 of the models its batches were played on, by option (``scenario``,
    ``people``, ``uncertainties``: :mod:`~hazardhunt.likelihood.model_record`), recorded when
    it starts; None in an estimate of a version that recorded none, or not yet started."""

    _field_ok = field_validator("field")(scenario_field)


class EstimateError(HazardhuntError):
    """An estimate that could not be done (no episode it counts was tested, a weight that
    overflows)."""


def nothing_tested(config: EstimateConfig, table: pd.DataFrame) -> str | None:
    """Why ``config``'s estimate of ``table``'s episodes gives no probability when every
    episode it counts (``ce``: those drawn once its proposal stopped moving; the others: all)
    ended in a SUT error, with the first error (a table written before errors were recorded has
    none to name); None when some of them were tested."""
    counted = table
    if config.estimator.method == "ce" and not table["sut_error"].all():
        counted = table[~table["adapting"].to_numpy(bool)]
        which = f"{len(counted)} episodes drawn from the final proposal, the ones it counts,"
    else:
        which = f"{len(table)} episodes"
    if counted.empty or not counted["sut_error"].all():
        return None
    first = first_sut_error(counted)
    cause = f" (the first: {first})" if first else ""
    return (
        f"every one of the {which} ended in a SUT error{cause}: nothing was tested, no "
        "probability can be given"
    )


def first_sut_error(table: pd.DataFrame) -> str | None:
    """What the SUT raised (or how it failed) in the first of ``table``'s episodes that ended
    in a SUT error; None if none did, or the table was written before errors were recorded."""
    return next((e for e in table.get("error", ()) if isinstance(e, str) and e), None)


BATCHES_AT_LEAST: dict[str, int] = {"mc": 1, "ce": 3, "splitting": 2}
"""The fewest batches (levels, for ``splitting``) each method needs to give an interval."""


def resumed_batch_size(directory: Path, method: str) -> int | None:
    """The batch size of the estimate by ``method`` in ``directory``, which a command that
    resumes or extends it keeps unless told otherwise; None when there is none (or its
    configuration does not read: the run says so)."""
    try:
        found = load_config(directory)
    except InputError:
        return None
    return found.estimator.batch_size if found.estimator.method == method else None


def default_batch_size(method: str, episodes: int) -> int:
    """The batch size of an estimate that names none: the estimator's 200, or fewer where the
    budget would not give ``method`` its fewest batches (:data:`BATCHES_AT_LEAST`), never
    below the 10 a batch needs (a budget too small even then is refused by
    :func:`check_budget`)."""
    return max(10, min(BATCH_SIZE, episodes // BATCHES_AT_LEAST.get(method, 1)))


def check_budget(config: EstimateConfig) -> None:
    """Refuse a budget too small for an interval.

    Raises:
        InputError: A batch larger than the budget, ``ce`` with fewer than three batches (one
            to look, one to move, one to use), ``splitting`` with too few episodes for two
            levels.
    """
    size, method, episodes = config.estimator.batch_size, config.estimator.method, config.episodes
    if size > episodes:
        raise InputError(
            f"batch_size: batches of {size} episodes are more than the budget of {episodes}; "
            "give a --batch-size of at most --episodes"
        )
    batches = BATCHES_AT_LEAST[method]
    if method == "ce" and episodes < batches * size:
        raise InputError(
            f"episodes: {episodes} episodes in batches of {size} give cross-entropy importance "
            f"sampling fewer than {batches} batches; give at least {batches * size} episodes or "
            "a smaller --batch-size"
        )
    if method == "splitting" and episodes < batches * size:
        raise InputError(
            f"episodes: {episodes} episodes give splitting with {size} samples per level fewer "
            f"than {batches} levels; give at least {batches * size} episodes or a smaller "
            "--batch-size"
        )


def planner_of(config: EstimateConfig, dims: tuple[Dimension, ...], threshold: float) -> Planner:
    """The estimator of ``config``, which chooses each batch."""
    kind = SplittingPlanner if config.estimator.method == "splitting" else SamplingPlanner
    return kind(config.estimator, dims, threshold, config.episodes, config.seed)


def models_of(config: EstimateConfig) -> Models:
    """What ``config``'s encounters are drawn from and played on."""
    return Models(config.scenario, config.people, config.uncertainties)


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


def _try_people(config: EstimateConfig, encounters: SimulationEncounters) -> None:
    """A people model of one's own plays the first decision of a draw, in a simulation of its
    own (the SUT's plug-ins in the estimate's play its first episode as their first); the
    built-in model and model files are not tried.

    Raises:
        ModelError: The model's policy raised or gave an unusable action.
    """
    if isinstance(encounters.model, PluginModel):
        trial = build_simulation(
            config.scenario, config.field, config.env, config.controller, config.safety_layer
        )
        try_model(encounters.model, trial, config.seed)


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
            InputError: The directory holds another estimate or something else, or the
                budget is too small.
            PluginError: A plug-in of the SUT does not load, or fails on a trial episode;
                nothing is written.
            ModelError: A people model of one's own fails on a trial draw (:func:`_try_people`);
                nothing is written.
        """
        check_budget(config)
        self.directory = directory
        # Built here from ``config``, the encounters can be built again in worker processes.
        self.workers = workers if source is None else 1
        if source is None:
            encounters = encounters_of(config)
            # On a SUT of its own, as in a worker process: a plug-in that keeps state from one
            # episode to the next plays the estimate's first episode as its first.
            sut = (config.controller, config.safety_layer)
            try_sut(config.scenario, config.field, config.env, *sut, "the estimate")
            _try_people(config, encounters)
            source = encounters
        # Once the models have loaded (a file that does not is named by its loader).
        config = config.model_copy(update={"digests": models_of(config).digests()})
        self.config = config
        self.source = source
        self.dimensions: tuple[Dimension, ...] = tuple(self.source.dimensions)
        self._pool: ProcessPoolExecutor | None = None
        _claim(directory, config)

    def played(self) -> list[pd.DataFrame]:
        """The finished batches, in order (stopping at the first missing one).

        Raises:
            InputError: A batch's file does not read (:func:`played_batches`).
        """
        return played_batches(self.directory)

    def run(self, progress: Callable[[int, int], None] | None = None) -> pd.DataFrame:
        """Play every missing batch; the whole episode table.

        Args:
            progress: Called with (episodes played, episodes in all) after each batch.

        Raises:
            EstimateError: No episode the estimate counts was tested, each ended in a SUT
                error (:func:`nothing_tested`), or a people model of one's own raised or gave
                an unusable action (:class:`~hazardhunt.likelihood.people.ModelPlayError`);
                nothing of the estimate is kept.
        """
        tables = self.played()
        config = self.config
        planner = planner_of(config, self.dimensions, self.source.threshold)
        try:
            while (plan := planner.next_batch(tables)) is not None:
                played = sum(len(t) for t in tables)
                if progress is not None:
                    progress(played, config.episodes)
                log_p = self._log_likelihoods(played, plan.draws)
                table = self._table(len(tables), played, plan, log_p, self._play(plan.draws))
                _write_batch(self.directory, len(tables), table, plan.record)
                tables.append(table)
        except ModelError as error:
            self._discard(len(tables))
            raise ModelError(f"{error}; no estimate is given, and nothing of it was kept") from None
        except ModelPlayError as error:
            # Kept, its batches would resume only with the model unchanged, which fails again.
            self._discard(len(tables))
            raise EstimateError(f"{error}; nothing of the estimate was kept") from None
        finally:
            self.close()
        if progress is not None:
            progress(config.episodes, config.episodes)
        table = pd.concat(tables, ignore_index=True)
        untested = nothing_tested(config, table) if len(table) else None
        if untested is not None:
            self._discard(len(tables))
            raise EstimateError(f"{untested}; nothing of it was kept")
        return table

    def _discard(self, batches: int) -> None:
        """Delete what the estimate wrote (its batches and ``config.json``; the directory
        too once empty), so that the same command plays it anew once the SUT is mended."""
        for batch in range(batches):
            path = batch_path(self.directory, batch)
            path.unlink(missing_ok=True)
            path.with_suffix(".json").unlink(missing_ok=True)
        (self.directory / "config.json").unlink(missing_ok=True)
        for folder in (batch_path(self.directory, 0).parent, self.directory):
            with contextlib.suppress(OSError):  # it holds files the estimate did not write
                folder.rmdir()

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

    def _log_likelihoods(self, first: int, draws: Sequence[Draw]) -> list[float]:
        """The log-likelihood of each draw (episodes ``first``, ...) under the model.

        Raises:
            ModelError: A dimension's is not finite on a draw of its own, past the ones
                checked before the estimate (:func:`~.people.check_model`).
        """
        model = f"people model {self.config.people or DEFAULT_MODEL}"
        checked = f", past the {CHECK_SAMPLES} draws checked before the estimate"
        return [
            finite_log_prob(model, self.dimensions, draw.values, f" (episode {n}{checked})")
            for n, draw in enumerate(draws, start=first)
        ]

    def _table(
        self,
        batch: int,
        first: int,
        plan: PlannedBatch,
        log_p: Sequence[float],
        played: Sequence[Played],
    ) -> pd.DataFrame:
        rows = []
        for i, (draw, outcome) in enumerate(zip(plan.draws, played, strict=True)):
            rows.append(
                {
                    "episode": first + i,
                    "batch": batch,
                    **{f"x.{name}": value for name, value in draw.values.items()},
                    "noise_seed": draw.seed,
                    "log_p": log_p[i],
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


def played_batches(directory: Path) -> list[pd.DataFrame]:
    """The finished batches of the estimate in ``directory``, in order (stopping at the first
    missing one).

    Raises:
        InputError: A batch's file does not read (truncated or changed since it was written).
    """
    tables: list[pd.DataFrame] = []
    while (path := batch_path(directory, len(tables))).exists():
        try:
            tables.append(pd.read_parquet(path))
        except (OSError, ValueError) as error:  # pyarrow's ArrowInvalid is a ValueError
            raise InputError(
                f"{path}: cannot be read ({error}); delete it and run the estimate's command "
                "again: it plays that batch and the ones after it anew, as they were"
            ) from None
    return tables


def draw_of(row: Any, dims: Sequence[Dimension]) -> Draw:
    """The draw an episode table's row records."""
    return Draw({dim.name: float(row[f"x.{dim.name}"]) for dim in dims}, int(row["noise_seed"]))


def _write_batch(directory: Path, batch: int, table: pd.DataFrame, record: dict[str, Any]) -> None:
    """The batch's table and how it was drawn, each renamed into place once complete (the
    table last: a batch counts as played when its table is there)."""
    path = batch_path(directory, batch)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_suffix(".json.partial")
    with file_written(partial, named=path.with_suffix(".json")):
        partial.write_text(json.dumps({"batch": batch, **record}, indent=1) + "\n")
        partial.replace(path.with_suffix(".json"))
    partial = path.with_suffix(".parquet.partial")
    with file_written(partial, named=path):
        table.to_parquet(partial, index=False)
        partial.replace(path)


def _claim(directory: Path, config: EstimateConfig) -> None:
    """Write ``config.json``, or check that the one there is this estimate's: the same, or a
    plain Monte Carlo estimate whose budget this one extends (:func:`_check_extension`)."""
    path = directory / "config.json"
    wanted = config.model_dump(mode="json")
    check_no_links(directory)
    _check_holds_no_other(directory)
    if path.exists():
        # Read as a configuration, so that settings added since it was written take their
        # defaults: an estimate of an earlier version resumes.
        found = load_config(directory)
        asked = config.model_copy(update={"digests": found.digests})
        same = found.model_dump(mode="json") == asked.model_dump(mode="json")
        if not same:
            extended = found.model_copy(update={"episodes": config.episodes})
            if extended.model_dump(mode="json") != asked.model_dump(mode="json"):
                raise InputError(
                    f"{directory}: holds an estimate of another configuration "
                    f"({first_difference(found, asked)}); choose another --out or give the "
                    "same options to resume it"
                )
            _check_extension(directory, found, config)
        assert config.digests is not None, "taken before the directory is claimed"
        # Nothing played yet, nothing to mix: the models are recorded as they are now.
        recorded = batch_path(directory, 0).exists() and models_recorded(
            directory, found.digests, models_of(config), config.digests
        )
        if same and recorded:
            return
        if not same:  # the result of the smaller budget no longer describes the directory
            (directory / "estimate.json").unlink(missing_ok=True)
    directory.mkdir(parents=True, exist_ok=True)
    partial = path.with_suffix(".json.partial")
    with file_written(partial, named=path):
        partial.write_text(json.dumps(wanted, indent=1) + "\n")
        partial.replace(path)


def check_no_links(directory: Path) -> None:
    """Raises InputError if ``directory`` holds a symbolic link: an estimate holds none, as a
    run holds none, and nothing is read or written through one (a ``batches`` linked elsewhere
    would take the estimate's files outside its directory)."""
    link = symbolic_link_in(directory) if directory.is_dir() else None
    if link is not None:
        raise InputError(
            f"{directory}: {link} is a symbolic link (an estimate holds none; it is not "
            "followed): put what it links to in its place"
        )


def _check_holds_no_other(directory: Path) -> None:
    """Raises InputError if ``directory`` holds something other than an estimate: files but
    no ``config.json`` (a half-written one aside), or the ``config.json`` of something else
    (a run's, say). A damaged estimate's is left to :func:`load_config` to describe."""
    if not directory.is_dir():
        return
    path = directory / "config.json"
    if path.exists():
        try:
            stored = json.loads(path.read_text())
        except (OSError, ValueError, RecursionError):
            return
        if not isinstance(stored, dict) or "estimator" in stored or "scenario" in stored:
            return
    elif all(entry.name.endswith(".partial") for entry in directory.iterdir()):
        return
    raise InputError(f"{directory}: exists and is not an estimate; choose another --out")


def _check_extension(directory: Path, found: EstimateConfig, config: EstimateConfig) -> None:
    """Raises InputError unless ``config``, which differs from the estimate ``found`` in
    ``directory`` in its budget alone, extends it: a plain Monte Carlo estimate given more
    episodes, all of whose batches so far are whole, so that the episodes it adds are those an
    estimate of the larger budget plays from the start (each batch drawn from the seed and
    its number)."""
    there = f"{directory}: holds an estimate of {found.episodes:,} episodes"
    if config.estimator.method != "mc":
        raise InputError(
            f"{there}, not {config.episodes:,}; a {config.estimator.method} estimate plans its "
            "batches from its budget and cannot be extended: choose another --out, or give "
            f"--episodes {found.episodes} to resume it"
        )
    if config.episodes < found.episodes:
        raise InputError(
            f"{there}, more than {config.episodes:,}; give --episodes {found.episodes} or more "
            "to resume or extend it, or choose another --out"
        )
    size = config.estimator.batch_size
    short = [len(table) for table in played_batches(directory) if len(table) != size]
    if short:
        raise InputError(
            f"{there}, whose last batch has {short[0]} episodes, not {size}: more episodes "
            "would not be the ones an estimate of that budget plays; choose another --out"
        )


def load_config(directory: Path) -> EstimateConfig:
    """The configuration of the estimate in ``directory``.

    Raises:
        InputError: There is none, or it does not read.
    """
    path = directory / "config.json"
    try:
        return EstimateConfig.model_validate_json(path.read_bytes())  # not UTF-8: invalid JSON
    except OSError as error:
        raise InputError(f"{directory}: no estimate here ({error.strerror}: {path.name})") from None
    except ValidationError as error:
        raise InputError(f"{path}: {format_validation_error(error, EstimateConfig)}") from None


# A worker process's encounters, built once when the process starts.
_worker: SimulationEncounters | None = None


def _start_worker(parent_pid: int, config: EstimateConfig) -> None:
    global _worker
    die_with_parent(parent_pid)
    notice_ctrl_c()
    _worker = encounters_of(config)


def _play_in_worker(draw: Draw) -> Played:
    assert _worker is not None, "the worker was not started"
    return _worker.play(draw)
