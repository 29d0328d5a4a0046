"""The worker side of the peer benchmark: play episodes, run hazardhunt's testers.

Every worker process builds the simulation of a case once, on first use, and keeps it. An
episode is one point: the human's open-loop actions, ``horizon`` decisions of (speed, turn
rate) in [-1, 1], flattened to one vector. Its score is the episode's maximum risk; a failure
is classified from its trajectory by the mechanism classifier, as hazardhunt's runs do.

Imports only ``hazardhunt.sim`` and ``hazardhunt.spec`` (no torch, no stable-baselines3), so
it runs in the peers' own virtual environment.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from hazardhunt.sim import Simulation
from hazardhunt.spec.descriptors import describe
from hazardhunt.spec.failure_classes import MechanismClassifier

FAILURE = "failure"


@dataclass(frozen=True)
class Case:
    """A scenario and a protective-field setting, written ``scenario:field``."""

    scenario: str
    field: str

    @classmethod
    def parse(cls, text: str) -> Case:
        scenario, colon, field = text.rpartition(":")
        if not colon or not scenario or not field:
            raise ValueError(f"a case is scenario:field, e.g. crossing:1.25m, not {text!r}")
        return cls(scenario, field)

    def __str__(self) -> str:
        return f"{self.scenario}:{self.field}"


@dataclass(frozen=True)
class Evaluation:
    """What the search methods and the table need from one played episode."""

    max_risk: float
    """The episode's maximum risk: >= 100 with an unsafe contact, else exp(-clearance) or 0."""
    outcome: str | None
    bearing: float
    """Where the human was around the robot at the contact or closest approach, in rad."""
    robot_speed: float
    """The robot's speed then, in m/s."""
    failure_class: str | None
    """The mechanism class of a failure; None for any other outcome."""

    @property
    def failed(self) -> bool:
        return self.outcome == FAILURE


_simulations: dict[Case, tuple[Simulation, MechanismClassifier]] = {}
"""This process's simulation of each case it has played."""


def _simulation(case: Case) -> tuple[Simulation, MechanismClassifier]:
    if case not in _simulations:
        simulation = Simulation.build(case.scenario, case.field)
        _simulations[case] = (simulation, MechanismClassifier(robot=simulation.robot_params))
    return _simulations[case]


def horizon(case: Case) -> int:
    """Decisions in a full episode of ``case``: the point's length is twice this."""
    return _simulation(case)[0].horizon


def evaluate(case: Case, point: NDArray[np.float64]) -> Evaluation:
    """Play the episode whose actions are ``point`` (clipped to [-1, 1]) from the case's start."""
    simulation, classifier = _simulation(case)
    actions = np.clip(np.asarray(point, dtype=np.float64), -1.0, 1.0).reshape(-1, 2)
    result = simulation.simulate(actions, keep_trajectory=lambda s: s.outcome == FAILURE)
    summary = result.summary
    bearing, robot_speed = describe(summary)[:2]
    failure_class = None
    if summary.outcome == FAILURE and result.trajectory is not None:
        failure_class = classifier.classify(result.trajectory, summary, simulation.field)
    return Evaluation(
        max_risk=float(summary.max_risk),
        outcome=summary.outcome,
        bearing=float(bearing),
        robot_speed=float(robot_speed),
        failure_class=failure_class,
    )


def evaluate_batch(case: Case, points: NDArray[np.float64]) -> list[Evaluation]:
    """:func:`evaluate` for each row of ``points``, in order."""
    return [evaluate(case, point) for point in points]


@dataclass(frozen=True)
class TesterRun:
    """One run of a hazardhunt tester through its command line, in hazardhunt's own venv."""

    tester: str
    """A registered name (random, ppo-max, ...) or ``package.module:Class``, optionally with
    parameters in brackets: ``cem[space=aim,population=10]``."""
    case: Case
    seed: int
    episodes: int
    hazardhunt: Path
    """The ``hazardhunt`` executable of the venv that has the testers' dependencies."""
    source: Path
    """The ``src`` folder put first on the tester's PYTHONPATH: the same code the peers play."""


def tester_spec(text: str) -> tuple[str, list[str]]:
    """``cem[space=aim,population=10]`` as the tester's name and its ``KEY=VALUE`` parameters.

    Raises:
        ValueError: Brackets that do not close, or a parameter without ``=``.
    """
    name, bracket, rest = text.partition("[")
    if not bracket:
        return text, []
    if not rest.endswith("]") or not name:
        raise ValueError(f"tester {text!r}: write NAME[KEY=VALUE,...]")
    params = [param.strip() for param in rest[:-1].split(",") if param.strip()]
    bad = [param for param in params if "=" not in param]
    if bad:
        raise ValueError(f"tester {text!r}: {bad[0]!r} is not KEY=VALUE")
    return name, params


def run_tester(run: TesterRun) -> dict[str, Any]:
    """``hazardhunt run ... --json`` into a scratch directory; its ``summary.json``."""
    with tempfile.TemporaryDirectory(prefix="hazardhunt-peers-") as scratch:
        out = Path(scratch) / re.sub(r"[^A-Za-z0-9_.-]", "_", run.tester)
        name, params = tester_spec(run.tester)
        command = [
            str(run.hazardhunt),
            "run",
            f"--scenario={run.case.scenario}",
            f"--field={run.case.field}",
            f"--tester={name}",
            *[f"--tester-param={param}" for param in params],
            f"--episodes={run.episodes}",
            f"--seed={run.seed}",
            f"--out={out}",
            "--json",
        ]
        path = os.pathsep.join(filter(None, [str(run.source), os.environ.get("PYTHONPATH")]))
        completed = subprocess.run(
            command,
            env=os.environ | {"PYTHONPATH": path},
            capture_output=True,
            text=True,
            check=False,
        )
        if completed.returncode != 0:
            raise RuntimeError(
                f"{' '.join(command)} exited with {completed.returncode}:\n{completed.stderr}"
            )
        summary: dict[str, Any] = json.loads((out / "summary.json").read_text())
    return summary
