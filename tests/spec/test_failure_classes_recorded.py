"""Failure classes reached by the search: failures hazardhunt's testers found, pinned as the
human's recorded action sequences and replayed against the real NMPC."""

import json
from pathlib import Path

import numpy as np
import pytest

from hazardhunt.sim.simulation import Simulation
from hazardhunt.spec.failure_classes import MechanismClassifier
from hazardhunt.sut.nmpc import NMPCController

RECORDED = json.loads((Path(__file__).parent / "recorded_failures.json").read_text())["examples"]
NMPC = NMPCController()  # built once: construction is the expensive part


def recorded_simulation(example: dict) -> Simulation:
    """The simulation a recorded failure was played on (with the shared NMPC)."""
    return Simulation.build(
        example["scenario"],
        example["field"],
        decision_period=example["decision_period"],
        controller=NMPC,
    )


@pytest.mark.parametrize("name", sorted(RECORDED))
def test_a_recorded_human_reaches_the_class(name):
    example = RECORDED[name]
    simulation = recorded_simulation(example)
    result = simulation.simulate(np.asarray(example["actions"], dtype=np.float32))
    assert result.outcome == "failure"
    assert result.summary.sim_time == pytest.approx(example["sim_time"])
    label = MechanismClassifier().classify(result.trajectory, result.summary, simulation.field)
    assert label == name
