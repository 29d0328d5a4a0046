"""One run: a tester explores one scenario and field setting for a budget of episodes."""

from __future__ import annotations

import platform
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import hazardhunt
from hazardhunt.campaign.config import EnvOptions, RunConfig
from hazardhunt.campaign.plugins import (
    PluginSpec,
    make_classifier,
    make_controller,
    make_plugin_tester,
    make_safety_layer,
)
from hazardhunt.campaign.store import RunStore, write_json_atomic
from hazardhunt.env.agv import AGVEnv
from hazardhunt.spec.failure_classes import OTHER
from hazardhunt.spec.outcomes import TerminationParams
from hazardhunt.spec.rewards import RewardKind
from hazardhunt.testers import make_tester
from hazardhunt.testers.base import EpisodeRecord, EpisodeRecorder, Tester
from hazardhunt.world.scenario import Scenario


@dataclass(frozen=True)
class RunProgress:
    """Where a run stands, after each episode."""

    episodes_done: int
    episodes: int
    failures: int
    elapsed_s: float


ProgressCallback = Callable[[RunProgress], None]


def make_env(config: RunConfig, reward: RewardKind) -> AGVEnv:
    """The environment a run's configuration describes, with its plug-ins built."""
    return build_env(
        config.scenario, config.field, config.env, reward, config.controller, config.safety_layer
    )


def build_env(
    scenario: str | Scenario,
    field: str,
    options: EnvOptions,
    reward: RewardKind = "max",
    controller: PluginSpec | None = None,
    safety_layer: PluginSpec | None = None,
) -> AGVEnv:
    """An environment from its parts: the built-in SUT unless plug-ins are given.

    Raises:
        PluginError: A plug-in does not load.
    """
    return AGVEnv(
        scenario,
        field,
        reward=reward,
        decision_period=options.decision_period,
        solver=options.solver,
        controller=None if controller is None else make_controller(controller),
        safety_layer=None if safety_layer is None else make_safety_layer(safety_layer),
        termination=TerminationParams(options.episode_duration, options.stall_duration),
    )


def make_run_tester(config: RunConfig) -> Tester:
    """The tester a run's configuration names: a registered one, or a user's plug-in.

    Raises:
        PluginError: A plug-in does not load.
    """
    if config.tester_plugin is None:
        return make_tester(config.tester, config.seed, config.tester_params)
    return make_plugin_tester(config.tester_plugin, config.seed)


def execute_run(
    config: RunConfig, directory: Path, progress: ProgressCallback | None = None
) -> dict[str, Any]:
    """Run ``config`` and write its results into ``directory`` (created; must not exist).

    Returns:
        The run's summary, also written as ``summary.json`` (the last file written).
    """
    directory.mkdir(parents=True)
    started_at = datetime.now(timezone.utc).isoformat()
    tester = make_run_tester(config)
    env = make_env(config, tester.reward)
    classifier = make_classifier(config.classifier, env.robot_params)
    write_json_atomic(
        directory / "config.json",
        {
            "run": config.model_dump(),
            "run_id": config.run_id,
            "reward": tester.reward,
            "hazardhunt_version": hazardhunt.__version__,
            "source_digest": hazardhunt.source_digest(),
            "python": platform.python_version(),
            "physics_step": env.physics_step,
            "control_period": env.controller.control_period,
            "started_at": started_at,
        },
    )
    store = RunStore(
        directory,
        {
            "scenario": config.scenario,
            "field": config.field,
            "seed": config.seed,
            "decision_period": config.env.decision_period,
        },
        classifier,
        env.field_diameter,
    )
    clock = time.perf_counter()

    def on_episode(record: EpisodeRecord) -> None:
        store.add(record)
        if progress is not None:
            progress(
                RunProgress(
                    record.index + 1,
                    config.episodes,
                    store.failure_count,
                    time.perf_counter() - clock,
                )
            )

    recorder = EpisodeRecorder(env, on_episode)
    tester.explore(recorder, config.episodes)
    tester.save(directory / "tester")
    store.close()
    wall_time = time.perf_counter() - clock
    outcomes = [row["outcome"] for row in store.episodes]
    first_failure = next((i for i, o in enumerate(outcomes) if o == "failure"), None)
    summary = {
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
        "first_failure_episode": first_failure,
        "classifier": classifier.name,
        "classes": store.classes,
        "classes_found": len(set(store.classes) - {OTHER}),
        "classes_total": len(classifier.classes_for(env.field_diameter)) - 1,
        "wall_time_s": wall_time,
        "episodes_per_s": len(outcomes) / wall_time if wall_time > 0 else 0.0,
        "started_at": started_at,
        "finished_at": datetime.now(timezone.utc).isoformat(),
    }
    write_json_atomic(directory / "summary.json", summary)
    return summary


def is_complete(directory: Path) -> bool:
    """Whether a run directory holds a finished run."""
    return (directory / "summary.json").is_file()
