"""Failure classes reached by the search: failures hazardhunt's testers found, pinned as the
human's recorded action sequences and replayed against the real NMPC."""

import json
from pathlib import Path

import numpy as np
import pytest

from hazardhunt.env.agv import AGVEnv
from hazardhunt.spec.failure_classes import MechanismClassifier
from hazardhunt.sut.nmpc import NMPCController

RECORDED = json.loads((Path(__file__).parent / "recorded_failures.json").read_text())["examples"]
NMPC = NMPCController()  # built once: construction is the expensive part


@pytest.mark.parametrize("name", sorted(RECORDED))
def test_a_recorded_human_reaches_the_class(name):
    example = RECORDED[name]
    env = AGVEnv(
        example["scenario"],
        example["field"],
        controller=NMPC,
        decision_period=example["decision_period"],
    )
    env.reset(seed=0)
    for action in example["actions"]:
        _, _, terminated, truncated, info = env.step(np.asarray(action, dtype=np.float32))
        if terminated or truncated:
            break
    assert info["outcome"] == "failure"
    assert info["sim_time"] == pytest.approx(example["sim_time"])
    label = MechanismClassifier().classify(env.trajectory(), info["summary"], env.field_diameter)
    assert label == name
