"""Today's code drives the episodes recorded with the reference code (before the speed work)
exactly as the reference did: the recorded failures and seeded random episodes on every
scenario and field setting (``scripts/record_reference_trajectories.py`` made the file)."""

import json
from pathlib import Path

import numpy as np
import pytest
from scripts.record_reference_trajectories import episode

REFERENCE = np.load(Path(__file__).parent / "reference_trajectories.npz")
INDEX = json.loads(str(REFERENCE["index"]))
TOLERANCE = 1e-9
"""Largest difference allowed in any position (m), heading (rad) or speed (m/s): the same
arithmetic gives the same numbers, so only a different build of the solver's libraries could
move them."""


@pytest.mark.parametrize(("key", "scenario", "field", "period"), INDEX["episodes"])
def test_the_episode_follows_the_reference_trajectory(key, scenario, field, period):
    expected = REFERENCE[f"{key}:trajectory"]
    actual = episode(scenario, field, period, REFERENCE[f"{key}:actions"])
    assert actual.shape == expected.shape, "the episode ended at another time"
    np.testing.assert_allclose(actual, expected, rtol=0.0, atol=TOLERANCE)
