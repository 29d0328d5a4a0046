"""Today's code drives the recorded episodes exactly as the reference did: the recorded failures
and seeded random episodes on every scenario and field setting. With today's NMPC settings
against the file recorded when they were chosen, and with the settings before that
(``PREVIOUS_TUNING``) against the file recorded with the code before the speed work (see
``scripts/record_reference_trajectories.py``)."""

import json
from pathlib import Path

import numpy as np
import pytest
from scripts.record_reference_trajectories import PREVIOUS_TUNING, episode

from hazardhunt.sut.nmpc import NMPCController

REFERENCE = np.load(Path(__file__).parent / "reference_trajectories.npz")
INDEX = json.loads(str(REFERENCE["index"]))
PREVIOUS = np.load(Path(__file__).parent / "reference_trajectories_previous_tuning.npz")
PREVIOUS_INDEX = json.loads(str(PREVIOUS["index"]))
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


@pytest.fixture(scope="module")
def previous_controller() -> NMPCController:
    return NMPCController(PREVIOUS_TUNING)


@pytest.mark.parametrize(("key", "scenario", "field", "period"), PREVIOUS_INDEX["episodes"])
def test_the_previous_settings_follow_their_reference_trajectory(
    key, scenario, field, period, previous_controller
):
    expected = PREVIOUS[f"{key}:trajectory"]
    actual = episode(scenario, field, period, PREVIOUS[f"{key}:actions"], previous_controller)
    assert actual.shape == expected.shape, "the episode ended at another time"
    np.testing.assert_allclose(actual, expected, rtol=0.0, atol=TOLERANCE)
