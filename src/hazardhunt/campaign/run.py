"""One run: a tester explores one scenario and field setting for a budget of episodes.

Three ways to execute a run, from the outside in:

- :func:`execute_run`: what ``hazardhunt run`` calls; keeps a finished run of the same
  configuration, refuses anything else in the way, shows a progress bar;
- :func:`execute_run_atomically`: writes into a hidden partial directory and renames it into
  place once complete (what each run of a campaign does);
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

import hazardhunt
from hazardhunt.campaign.config import ConfigError, EnvOptions, RunConfig
from hazardhunt.campaign.plugins import (
    PluginSpec,
    make_classifier,
    make_controller,
    make_plugin_tester,
    make_safety_layer,
)
from hazardhunt.campaign.store import RunStore, write_json_atomic
from hazardhunt.env.agv import AGVEnv
from hazardhunt.sim.simulation import Simulation
from hazardhunt.spec.failure_classes import OTHER
from hazardhunt.spec.outcomes import TerminationParams
from hazardhunt.sut.safety_layer import FieldShape
from hazardhunt.testers import make_tester
from hazardhunt.testers.base import EpisodeRecord, EpisodeRecorder, Tester, reward_of
from hazardhunt.world.scenario import Scenario


@dataclass(frozen=True)
class RunProgress:
    """Where a run stands, after each episode."""

    episodes_done: int
    episodes: int
    failures: int
    elapsed_s: float


ProgressCallback = Callable[[RunProgress], None]


def build_simulation(
    scenario: str | Scenario,
    field: str,
    options: EnvOptions,
    controller: PluginSpec | None = None,
    safety_layer: PluginSpec | None = None,
) -> Simulation:
    """The simulation a run's settings describe: the built-in SUT unless plug-ins are given.

    Raises:
        PluginError: A plug-in does not load.
    """
    return Simulation.build(
        scenario,
        field,
        options.decision_period,
        solver=options.solver,
        controller=None if controller is None else make_controller(controller),
        safety_layer=None if safety_layer is None else make_safety_layer(safety_layer),
        termination=TerminationParams(options.episode_duration, options.stall_duration),
        robot=options.robot,
    )


def simulation_of(config: RunConfig) -> Simulation:
    """The simulation of a run's configuration."""
    return build_simulation(
        config.scenario, config.field, config.env, config.controller, config.safety_layer
    )


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
) -> dict[str, Any]:
    """Run ``config`` and write its results into ``directory`` (created; must not exist).

    Returns:
        The run's summary, also written as ``summary.json`` (the last file written).
    """
    directory.mkdir(parents=True)
    started_at = datetime.now(timezone.utc).isoformat()
    tester = make_run_tester(config)
    simulation = simulation_of(config)
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
            "physics_step": simulation.physics_step,
            "control_period": simulation.controller.control_period,
            "field_shape": asdict(simulation.field),
            "started_at": started_at,
        },
    )
    replay_keys = {
        "scenario": config.scenario,
        "field": config.field,
        "seed": config.seed,
        "decision_period": config.env.decision_period,
    }
    store = RunStore(directory, replay_keys, classifier, simulation.field)
    clock = time.perf_counter()

    def on_episode(record: EpisodeRecord) -> None:
        store.add(record)
        if progress is not None:
            elapsed = time.perf_counter() - clock
            progress(RunProgress(record.episode + 1, config.episodes, store.failure_count, elapsed))

    recorder = EpisodeRecorder(
        AGVEnv.wrapping(simulation, reward_of(tester)),
        on_episode,
        simulation_factory=functools.partial(simulation_of, config),
    )
    try:
        tester.explore(recorder, config.episodes)
    finally:
        recorder.close()  # the worker processes of batches played on several cores
    tester.save(directory / "tester")
    store.close()
    wall_time = time.perf_counter() - clock
    summary = _run_summary(config, store, simulation.field, wall_time, started_at)
    write_json_atomic(directory / "summary.json", summary)
    return summary


def _run_summary(
    config: RunConfig, store: RunStore, field: FieldShape, wall_time: float, started_at: str
) -> dict[str, Any]:
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
        **{f"{outcome}s": outcomes.count(outcome) for outcome in _OUTCOME_COUNTS},
        "first_failure_episode": next(
            (i for i, outcome in enumerate(outcomes) if outcome == "failure"), None
        ),
        "field_shape": asdict(field),
        "classifier": classifier.name,
        "classes": store.classes,
        "classes_found": len(set(store.classes) - {OTHER}),
        "classes_total": len(classifier.classes_for(field)) - 1,
        "wall_time_s": wall_time,
        "episodes_per_s": len(outcomes) / wall_time if wall_time > 0 else 0.0,
        "started_at": started_at,
        "finished_at": datetime.now(timezone.utc).isoformat(),
    }


_OUTCOME_COUNTS = ("failure", "safe_contact", "stall", "timeout", "goal", "sut_error")
"""Outcomes the run summary counts, each as ``<outcome>s``."""


def is_complete(directory: Path) -> bool:
    """Whether a run directory holds a finished run."""
    return (directory / "summary.json").is_file()


def partial_directory(out: Path) -> Path:
    """Where a run into ``out`` is written until it completes."""
    return out.parent / f".{out.name}.partial"


def execute_run_atomically(
    config: RunConfig, out: Path, progress: ProgressCallback | None = None
) -> dict[str, Any]:
    """Execute ``config`` into the hidden partial sibling of ``out`` (discarding any leftover
    there) and rename it to ``out`` once complete; the run's summary."""
    partial = partial_directory(out)
    if partial.exists():
        shutil.rmtree(partial)
    summary = record_run(config, partial, progress)
    partial.rename(out)
    return summary


def execute_run(config: RunConfig, out: Path, console: Console | None = None) -> dict[str, Any]:
    """Execute ``config`` into ``out``, which appears only once the run is complete.

    A complete run already in ``out`` with the same configuration is kept and its summary
    returned; a leftover partial run is discarded and redone (runs are deterministic).

    Args:
        config: The run.
        out: The run directory.
        console: Where a progress bar is shown; none if None.

    Raises:
        ConfigError: ``out`` holds something else, or a run of another configuration.
    """
    if out.exists():
        if is_complete(out):
            if _stored_config(out) != config:
                raise ConfigError(f"{out}: holds a finished run of another configuration")
            summary: dict[str, Any] = json.loads((out / "summary.json").read_text())
            if console is not None:
                console.print(f"{out}: already complete")
            return summary
        raise ConfigError(f"{out}: exists and is not a finished run; choose another --out")
    out.parent.mkdir(parents=True, exist_ok=True)
    if console is None:
        return execute_run_atomically(config, out)
    return _with_progress(config, out, console)


def _stored_config(out: Path) -> RunConfig:
    """The configuration a finished run in ``out`` recorded.

    Raises:
        ConfigError: Its ``config.json`` cannot be read or holds no run configuration.
    """
    path = out / "config.json"
    try:
        return RunConfig.model_validate(json.loads(path.read_text(encoding="utf-8"))["run"])
    except (OSError, ValueError, KeyError, TypeError) as error:
        # ValueError covers a JSON syntax error, bad UTF-8 and pydantic's ValidationError.
        problem = error.strerror if isinstance(error, OSError) else "not a run's configuration"
        raise ConfigError(f"{path}: {problem}; use another --out or delete {out}") from None


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

        return execute_run_atomically(config, out, update)
