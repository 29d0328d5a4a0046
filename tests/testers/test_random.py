"""The random tester: reproducible runs, and actions that keep the human off the shelves."""

import math

import numpy as np
import pytest

from hazardhunt.sim.simulation import Simulation
from hazardhunt.sut.pursuit import PursuitController
from hazardhunt.testers.clear_path import human_path
from hazardhunt.testers.random_sampling import RandomTester


@pytest.fixture(scope="module")
def sim():
    # The controller plays no part in choosing actions; pure pursuit builds instantly.
    simulation = Simulation.build("crossing", "1.25m", controller=PursuitController())
    simulation.reset()
    return simulation


def path_of(sim, pose, action):
    speed, turn_rate = sim.decode_action(action)
    return human_path(pose, speed, turn_rate, sim.decision_period, sim.physics_step)


def choices(tester, sim, pose, count):
    """``count`` actions the tester chooses for a human standing at ``pose``."""
    sim.human_position, sim.human_heading = np.array(pose[:2]), pose[2]
    return np.array([tester.choose(sim) for _ in range(count)])


def test_a_human_facing_a_nearby_shelf_never_walks_into_it(sim):
    floor, radius = sim.scenario.floor, sim.human_params.radius
    # Facing east, 0.5 m from shelf block SE-2 (x >= 11.5): walking on for 2 s would hit it.
    pose = (11.5 - 0.5 - radius, 7.0, 0.0)
    assert not floor.discs_clear(path_of(sim, pose, [1.0, 0.0]), radius)
    tester = RandomTester(seed=0)
    actions = choices(tester, sim, pose, 100)
    for action in actions:
        assert floor.discs_clear(path_of(sim, pose, action), radius)
    # Turning away or walking slowly is clear: the human keeps moving, not standing still.
    assert np.mean(actions[:, 0] == -1.0) < 0.05


def test_a_cornered_human_turns_on_the_spot_instead_of_freezing(sim):
    # Pressed into the south-west corner aisle, facing the wall: no walk is clear, so every
    # draw fails and the fallback turns in place at varying rates.
    pose = (0.46, 0.46, math.radians(225))
    tester = RandomTester(seed=0, attempts=1)
    actions = choices(tester, sim, pose, 50)
    fallbacks = actions[actions[:, 0] == -1.0]
    assert len(fallbacks) > 0
    assert np.std(fallbacks[:, 1]) > 0.2


def test_in_open_space_actions_cover_the_whole_action_space(sim):
    pose = (10.0, 10.0, math.pi / 2)  # the middle of the crossing, facing north
    tester = RandomTester(seed=0)
    actions = choices(tester, sim, pose, 400)
    assert np.all(actions.min(axis=0) < -0.95)
    assert np.all(actions.max(axis=0) > 0.95)
    assert np.abs(actions.mean(axis=0)).max() < 0.15
