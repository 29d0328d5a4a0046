"""The compiled fatrop solver: the same trajectories as CasADi's interpreted solver, a disk
cache, and a fallback when nothing can be compiled."""

import dataclasses
import json
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hazardhunt.sim.simulation import Simulation
from hazardhunt.sut import compiled
from hazardhunt.sut.nmpc import NMPCController, NMPCParams

RECORDED = json.loads((Path(__file__).parents[1] / "spec" / "recorded_failures.json").read_text())[
    "examples"
]


def replay(example: dict, controller: NMPCController) -> pd.DataFrame:
    """The recorded episode's trajectory, without the solve times measured on the clock."""
    simulation = Simulation.build(
        example["scenario"],
        example["field"],
        decision_period=example["decision_period"],
        controller=controller,
    )
    result = simulation.simulate(np.asarray(example["actions"], dtype=np.float32))
    rows = [dataclasses.asdict(sample) for sample in result.trajectory]
    return pd.DataFrame(rows).drop(columns="solve_time_s")


def test_compiled_and_interpreted_solvers_drive_recorded_episodes_identically():
    fast = NMPCController(NMPCParams(compiled=True))
    reference = NMPCController(NMPCParams(compiled=False))
    assert fast._problem.compiled is not None
    assert reference._problem.compiled is None
    for name, example in sorted(RECORDED.items()):
        expected, actual = replay(example, reference), replay(example, fast)
        # Same arithmetic: every state, command and plan is bit for bit equal.
        plans = ["predicted_human", "planned_positions"]
        pd.testing.assert_frame_equal(
            actual.drop(columns=plans), expected.drop(columns=plans), check_exact=True, obj=name
        )
        for column in plans:
            for mine, theirs in zip(actual[column], expected[column], strict=True):
                assert np.array_equal(mine, theirs, equal_nan=True), (name, column)
        assert (actual["controller_status"] == "ok").mean() > 0.5, name


def test_a_second_controller_loads_the_compiled_solver_from_the_cache(monkeypatch, tmp_path):
    monkeypatch.setenv("HAZARDHUNT_CACHE", str(tmp_path))
    NMPCController(NMPCParams(horizon=8))  # compiles into the empty cache
    assert len(list((tmp_path / "solvers").glob("*.so"))) == 2  # warm and cold solver
    compiled._libraries.clear()  # as in a new process

    def no_compiler(*args, **kwargs):
        raise AssertionError("compiled again instead of loading the cached library")

    monkeypatch.setattr(subprocess, "Popen", no_compiler)
    controller = NMPCController(NMPCParams(horizon=8))
    assert controller._problem.compiled is not None


def test_without_a_compiler_the_interpreted_solver_runs_with_a_warning(monkeypatch, tmp_path):
    monkeypatch.setenv("HAZARDHUNT_CACHE", str(tmp_path))
    monkeypatch.setenv("CC", "no-such-compiler")

    with pytest.warns(UserWarning, match="no C compiler"):
        controller = NMPCController(NMPCParams(horizon=6))

    assert controller._problem.compiled is None
