"""One run: a tester explores one scenario and field setting for a budget of episodes.

Three ways to execute a run, from the outside in:

- :func:`execute_run`: what ``hazardhunt run`` calls; holds a lock next to the run directory,
  keeps a finished run of the same configuration (redoes it if its files are damaged), refuses
  anything else in the way, shows a progress bar;
- :func:`execute_run_atomically`: writes into a hidden partial directory and renames it into
  place once complete, or removes it if the run fails (what each run of a campaign does);
- :func:`record_run`: writes the run's files into a new directory (the two above, and Ray's
  workers, call it).
"""

from __future__ import annotations

import functools
import json
import platform
import shutil
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from datetime import datetime, timezone
from pathlib import Path

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

import hazardhunt
from hazardhunt.campaign.config import STORED, ConfigError, RunConfig, first_difference
from hazardhunt.campaign.lock import exclusive_lock
from hazardhunt.campaign.plugins import make_classifier, make_plugin_tester
from hazardhunt.campaign.records import NothingTested, RunFailed, RunSummary, cpu_seconds
from hazardhunt.campaign.scenario_record import SCENARIO_FILE, played_before_change
from hazardhunt.campaign.simulations import check_sut, simulation_of
from hazardhunt.campaign.store import RunStore, file_checksums, find_damage, write_json_atomic
from hazardhunt.env.agv import AGVEnv
from hazardhunt.sim.simulation import UnusableActionError
from hazardhunt.spec.failure_classes import OTHER
from hazardhunt.sut.guard import is_plugin_fault, raised
from hazardhunt.sut.safety_layer import FieldShape
from hazardhunt.testers import make_tester
from hazardhunt.testers.base import EpisodeRecord, EpisodeRecorder, Tester, reward_of
from hazardhunt.testers.objective import objective_of
from hazardhunt.world.scenario import scenario_data


@dataclass(frozen=True)
class RunProgress:
    """Where a run stands, when its episodes start and after each of them."""

    episodes_done: int
    episodes: int
    failures: int
    elapsed_s: float
    sut_errors: int = 0
    """Episodes that ended in ``sut_error``: the system under test raised, hung or returned
    something unusable, so they tested nothing."""


ProgressCallback = Callable[[RunProgress], None]


def make_run_tester(config: RunConfig) -> Tester:
    """The tester a run's configuration names: a registered one, or a user's plug-in.

    Raises:
        PluginError: A plug-in does not load.
    """
    if config.tester_plugin is None:
        return make_tester(config.tester, config.seed, config.tester_params)
    return make_plugin_tester(config.tester_plugin, config.seed)


def record_run(
    config: RunConfig, directory: Path, progress: ProgressCallback | None = None
) -> RunSummary:
    """Run ``config`` and write its results into ``directory`` (created; must not exist).

    ``progress`` hears when the episodes start and after each of them.

    Returns:
        The run's summary, also written as ``summary.json`` (the last file written), with the
        checksums of the other files.
    """
    simulation = simulation_of(config)  # settings that cannot work stop the run here
    tester = make_run_tester(config)
    directory.mkdir(parents=True)
    started_at = datetime.now(timezone.utc).isoformat()
    classifier = make_classifier(config.classifier, simulation.robot_params)
    write_json_atomic(
        directory / "config.json",
        {
            "run": config.model_dump(),
            "run_id": config.run_id,
            "reward": reward_of(tester),
            "hazardhunt_version": hazardhunt.__version__,
            "source_digest": hazardhunt.source_digest(),
            "python": platform.python_version(),
            "blas": hazardhunt.blas_kernel(),
            "physics_step": simulation.physics_step,
            "control_period": simulation.controller.control_period,
            "field_shape": asdict(simulation.field),
            "started_at": started_at,
        },
    )
    write_json_atomic(directory / SCENARIO_FILE, scenario_data(config.scenario))
    replay_keys = {
        "scenario": config.scenario,
        "field": config.field,
        "seed": config.seed,
        "decision_period": config.env.decision_period,
    }
    field, requirements = simulation.field, simulation.requirements
    store = RunStore(directory, replay_keys, classifier, field, requirements=requirements)
    clock, cpu = time.perf_counter(), cpu_seconds()

    def on_episode(record: EpisodeRecord) -> None:
        store.add(record)
        if progress is not None:
            elapsed = time.perf_counter() - clock
            done, failures = record.episode + 1, store.failure_count
            progress(RunProgress(done, config.episodes, failures, elapsed, store.sut_error_count))
        if store.sut_error_count >= config.sut_error_limit * config.episodes:
            raise _nothing_tested(config, store)  # the run can no longer pass

    recorder = _recorder(config, AGVEnv.wrapping(simulation, reward_of(tester)), on_episode)
    if progress is not None:
        progress(RunProgress(0, config.episodes, 0, 0.0))
    _explore(config, tester, recorder)
    _check_played(config, store)
    _call_tester(config, functools.partial(tester.save, directory / "tester"), "save()")
    store.close()
    wall_time = time.perf_counter() - clock
    summary = _run_summary(config, store, simulation.field, wall_time, started_at)
    summary["cpu_time_s"] = cpu_seconds() - cpu
    summary["checksums"] = file_checksums(directory)
    write_json_atomic(directory / "summary.json", summary)
    return summary


def _recorder(
    config: RunConfig, env: AGVEnv, on_episode: Callable[[EpisodeRecord], None]
) -> EpisodeRecorder:
    """What the run's tester plays through, its search after the run's objective."""
    recorder = EpisodeRecorder(
        env, on_episode, simulation_factory=functools.partial(simulation_of, config)
    )
    recorder.objective = objective_of(config.search_on)
    return recorder


def _explore(config: RunConfig, tester: Tester, recorder: EpisodeRecorder) -> None:
    """The tester plays the run's episodes.

    Raises:
        RunFailed: The tester raised (:func:`_call_tester`).
    """
    try:
        _call_tester(config, functools.partial(tester.explore, recorder, config.episodes))
    finally:
        recorder.close()  # the worker processes of batches played on several cores


def _call_tester(config: RunConfig, method: Callable[[], None], call: str | None = None) -> None:
    """Call one of the run's tester's methods (``call`` names it in messages, unless it is
    ``explore``).

    Raises:
        RunFailed: A user's tester raised (where in its code, in one line), ``SystemExit``,
            a ``KeyboardInterrupt`` of its own and any other ``BaseException`` too; or any
            tester played an action that is not two finite numbers, or raised what is not an
            ``Exception`` (a plug-in's, as a portfolio arm). The user's Ctrl-C goes through;
            a built-in tester's other errors are hazardhunt's, shown whole.
    """
    try:
        method()
    except BaseException as error:  # a plug-in may raise anything, SystemExit too
        hazardhunts = config.tester_plugin is None and isinstance(error, Exception)
        if hazardhunts and not isinstance(error, UnusableActionError):
            raise  # a built-in tester's bug, shown whole
        if isinstance(error, RunFailed) or not is_plugin_fault(error):
            raise
        name = config.tester if config.tester_plugin is None else config.tester_plugin.path
        where = "" if call is None else f", in {call},"
        raise RunFailed(
            f"run {config.run_id}: tester {name!r}{where} {_what_went_wrong(error)}; "
            "nothing of the run was kept"
        ) from error


def _what_went_wrong(error: BaseException) -> str:
    """What a tester did, in a few words: an unusable action played, or what it raised and
    where in its code."""
    if isinstance(error, UnusableActionError):
        return f"played an unusable action: {error}"
    return f"raised {raised(error)}"


def _check_played(config: RunConfig, store: RunStore) -> None:
    """Raises RunFailed unless the run tested its SUT (``NothingTested``) with every episode of
    its budget, no more and no fewer."""
    if store.sut_error_count >= config.sut_error_limit * len(store.episodes):
        raise _nothing_tested(config, store)  # a tester that played no episode, too
    if len(store.episodes) != config.episodes:
        raise RunFailed(
            f"run {config.run_id}: its tester played {len(store.episodes)} episodes of a budget "
            f"of {config.episodes}; a run plays its budget, so nothing of it was kept"
        )


def _run_summary(
    config: RunConfig, store: RunStore, field: FieldShape, wall_time: float, started_at: str
) -> RunSummary:
    """What ``summary.json`` says of a finished run."""
    classifier = store.classifier
    outcomes = [row["outcome"] for row in store.episodes]
    return {
        "run_id": config.run_id,
        "scenario": config.scenario,
        "field": config.field,
        "tester": config.tester,
        "seed": config.seed,
        "source_digest": hazardhunt.source_digest(),
        "episodes": len(outcomes),
        "failures": outcomes.count("failure"),
        "safe_contacts": outcomes.count("safe_contact"),
        "stalls": outcomes.count("stall"),
        "timeouts": outcomes.count("timeout"),
        "goals": outcomes.count("goal"),
        "sut_errors": outcomes.count("sut_error"),
        "first_failure_episode": next(
            (i for i, outcome in enumerate(outcomes) if outcome == "failure"), None
        ),
        "first_sut_error": store.first_sut_error,
        "classifier_errors": store.classifier_errors,
        "first_classifier_error": store.first_classifier_error,
        "field_shape": asdict(field),
        "classifier": classifier.name,
        "classes": store.classes,
        "classes_found": len(set(store.classes) - {OTHER}),
        "classes_total": len(classifier.classes_for(field)) - 1,
        "requirements": store.requirement_summary(),
        "wall_time_s": wall_time,
        "episodes_per_s": len(outcomes) / wall_time if wall_time > 0 else 0.0,
        "started_at": started_at,
        "finished_at": datetime.now(timezone.utc).isoformat(),
    }


def _nothing_tested(config: RunConfig, store: RunStore) -> NothingTested:
    """The error of ``config``'s run, whose episodes so far ``store`` holds, that tested
    nothing."""
    played, first = len(store.episodes), store.first_sut_error
    if first is None:
        message = "its tester played no episode, so it tested nothing"
    else:
        share = "every one" if store.sut_error_count == played else store.sut_error_count
        message = (
            f"{share} of its {played} episodes ended in a SUT error, so it tested nothing "
            f"(sut_error_limit {config.sut_error_limit:g}); the first, episode "
            f"{first['episode']}: {first['error']}"
        )
    message = f"run {config.run_id}: {message}; nothing of it was kept"
    return NothingTested(message, played, store.sut_error_count)


def is_finished(directory: Path) -> bool:
    """Whether a run directory holds a finished run (its files may still be damaged)."""
    return (directory / "summary.json").is_file()


def is_complete(directory: Path) -> bool:
    """Whether a run directory holds a finished run whose files are as it wrote them."""
    return is_finished(directory) and find_damage(directory) is None


def partial_directory(out: Path) -> Path:
    """Where a run into ``out`` is written until it completes."""
    return out.parent / f".{out.name}.partial"


def execute_run_atomically(
    config: RunConfig, out: Path, progress: ProgressCallback | None = None
) -> RunSummary:
    """Execute ``config`` into the hidden partial sibling of ``out`` (discarding any leftover
    there) and rename it to ``out`` once complete; the run's summary.

    Raises:
        RunFailed: Its results could not be written (``OSError``); the partial directory is
            removed, whatever the run raised.
    """
    partial = partial_directory(out)
    if partial.exists():
        shutil.rmtree(partial)
    try:
        summary = record_run(config, partial, progress)
        partial.rename(out)
    except OSError as error:
        shutil.rmtree(partial, ignore_errors=True)  # it may be what fills the disk
        raise RunFailed(
            f"{out}: the run failed writing its results ({error}); nothing of it was kept"
        ) from error
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)
        raise
    return summary


def execute_run(config: RunConfig, out: Path, console: Console | None = None) -> RunSummary:
    """Execute ``config`` into ``out``, which appears only once the run is complete.

    A complete run already in ``out`` with the same configuration is kept and its summary
    returned; one whose files are damaged is redone, as is a leftover partial run (runs are
    deterministic). A lock next to ``out`` (``.<name>.lock``) keeps a second process from
    writing the same run.

    Args:
        config: The run.
        out: The run directory.
        console: Where a progress bar is shown; none if None.

    Raises:
        ConfigError: ``out`` holds something else, or a run of another configuration, or
            another process is writing it, or it is a run folder of a campaign.
        PluginError: A plug-in of the SUT fails on a trial episode
            (:func:`~hazardhunt.campaign.simulations.check_sut`).
        RunFailed: The run could not write its results, or tested nothing (``NothingTested``);
            nothing of it is left.
    """
    campaign = out.absolute().parent.parent
    if out.absolute().parent.name == "runs" and (campaign / "campaign.json").is_file():
        raise ConfigError(
            f"{out}: a run folder of the campaign in {campaign}, which writes its runs itself; "
            "run the campaign, or choose another --out"
        )
    check_sut(config)
    make_directory(out.parent, "--out")
    with exclusive_lock(out.parent / f".{out.name}.lock", out, "run"):
        if out.exists():
            summary = _finished_run(config, out, console)
            if summary is not None:
                return summary
        if console is None:
            return execute_run_atomically(config, out)
        return _with_progress(config, out, console)


def _finished_run(config: RunConfig, out: Path, console: Console | None) -> RunSummary | None:
    """The summary of the run of ``config`` complete in ``out``; None, having removed it, if
    it is damaged.

    Raises:
        ConfigError: ``out`` holds something else, a run of another configuration, or a damaged
            run whose configuration cannot be read.
    """
    if (out / "campaign.json").is_file():  # not a run to redo: a whole campaign
        raise ConfigError(f"{out}: holds a campaign, not a run; choose another --out")
    if not is_finished(out):
        if _written_by(out, config):  # a run of this configuration whose summary.json is lost
            if console is not None:
                console.print(f"{out}: unfinished (no summary.json); running it again")
            shutil.rmtree(out)
            return None
        raise ConfigError(f"{out}: exists and is not a finished run; choose another --out")
    damage = find_damage(out)
    try:
        stored = json.loads((out / "config.json").read_text())["run"]
        found = RunConfig.model_validate(stored, context=STORED)
    except (OSError, ValueError, KeyError, TypeError):  # a ValidationError is a ValueError
        raise ConfigError(
            f"{out}: holds a damaged run ({damage or 'config.json does not read as a run'}); "
            "delete it or choose another --out"
        ) from None
    if found != config:
        raise ConfigError(
            f"{out}: holds a finished run of another configuration "
            f"({first_difference(found, config)}); choose another --out"
        )
    why = f"damaged ({damage})" if damage else played_before_change(config.scenario, out)
    if why is not None:
        if console is not None:
            console.print(f"{out}: {why}; running it again")
        shutil.rmtree(out)
        return None
    if console is not None:
        console.print(f"{out}: already complete")
    summary: RunSummary = json.loads((out / "summary.json").read_text())
    return summary


def _written_by(out: Path, config: RunConfig) -> bool:
    """Whether ``out`` holds the files of a run of ``config`` (its ``config.json`` says so)."""
    try:
        stored = json.loads((out / "config.json").read_text())["run"]
        return RunConfig.model_validate(stored, context=STORED) == config
    except (OSError, ValueError, KeyError, TypeError):
        return False


def make_directory(path: Path, option: str) -> None:
    """Create ``path`` and its parents if they are missing.

    Raises:
        ConfigError: It cannot be created (naming ``option``): a read-only or virtual file
            system such as /proc, no permission.
    """
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise ConfigError(f"{option}: cannot create {path}: {error.strerror or error}") from None


LOG_INTERVAL_S = 600.0
"""Time between two progress lines where the output is not a terminal (a log file, where
progress bars do not show), in s."""


def _with_progress(config: RunConfig, out: Path, console: Console) -> RunSummary:
    """Execute the run with a progress bar on a terminal, or else a line every
    ``LOG_INTERVAL_S``."""
    columns = (
        TextColumn(f"{config.run_id}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn(
            "{task.fields[rate]:.1f} episodes/s, {task.fields[failures]} failures"
            "{task.fields[sut_errors]}"
        ),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
    )
    progress = Progress(*columns, console=console, disable=not console.is_terminal)
    task: TaskID | None = None
    logged_at = time.monotonic()

    def update(state: RunProgress) -> None:
        nonlocal task, logged_at
        if task is None:  # the run has started: the bar stays off an error in its settings
            progress.start()
            task = progress.add_task(
                "run", total=config.episodes, rate=0.0, failures=0, sut_errors=""
            )
        rate = state.episodes_done / state.elapsed_s if state.elapsed_s > 0 else 0.0
        sut_errors = f", [red]{state.sut_errors} SUT errors[/red]" if state.sut_errors else ""
        progress.update(
            task,
            completed=state.episodes_done,
            rate=rate,
            failures=state.failures,
            sut_errors=sut_errors,
        )
        if progress.disable and time.monotonic() - logged_at >= LOG_INTERVAL_S:
            logged_at = time.monotonic()
            console.print(
                f"{config.run_id}: {state.episodes_done:,} of {config.episodes:,} episodes, "
                f"{state.failures:,} failures{sut_errors}, {rate:.1f} episodes/s"
            )

    try:
        return execute_run_atomically(config, out, update)
    finally:
        progress.stop()
