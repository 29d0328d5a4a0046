"""Open-loop sequences played with a clear path: the human is not walked into the shelves, and
the episode replays from the actions it records."""

import math

import numpy as np
import pytest

from hazardhunt.sim.simulation import Simulation
from hazardhunt.sut.pursuit import PursuitController
from hazardhunt.testers.clear_path import clear_action, human_path
from hazardhunt.testers.spaces import DecisionSpace


@pytest.fixture(scope="module")
def sim():
    simulation = Simulation.build("crossing", "1.25m", controller=PursuitController())
    simulation.reset()
    return simulation


def path_of(sim, action):
    speed, turn_rate = sim.decode_action(action)
    return human_path(sim.human_pose, speed, turn_rate, sim.decision_period, sim.physics_step)


def place(sim, pose):
    sim.human_position, sim.human_heading = np.array(pose[:2]), pose[2]


def test_an_action_with_a_clear_path_is_played_as_it_is(sim):
    place(sim, (10.0, 10.0, math.pi / 2))  # the middle of the crossing
    action = np.array([0.7, -0.3], dtype=np.float32)
    np.testing.assert_array_equal(clear_action(sim, action), action)


def test_walking_into_a_shelf_becomes_the_nearest_clear_walk(sim):
    floor, radius = sim.scenario.floor, sim.human_params.radius
    # Facing east, 0.5 m from shelf block SE-2 (x >= 11.5): 2 s straight on would hit it.
    place(sim, (11.5 - 0.5 - radius, 7.0, 0.0))
    wanted = np.array([1.0, 0.0], dtype=np.float32)
    assert not floor.discs_clear(path_of(sim, wanted), radius)
    played = clear_action(sim, wanted)
    assert floor.discs_clear(path_of(sim, played), radius)
    speed, _ = sim.decode_action(played)
    assert speed > 0.5  # it walks on, turning away, rather than stopping


def test_a_cornered_human_turns_on_the_spot(sim):
    place(sim, (0.46, 0.46, math.radians(225)))  # pressed into the south-west corner
    played = clear_action(sim, np.array([1.0, 0.4], dtype=np.float32))
    assert played[0] == -1.0  # standing
    assert played[1] == pytest.approx(0.4)


def test_a_sequence_never_pushes_the_human_against_a_wall_and_replays_from_its_actions(sim):
    rng = np.random.default_rng(0)
    sequence = rng.uniform(-1.0, 1.0, (sim.horizon, 2))
    sequence[:, 0] = 1.0  # full speed all episode: open loop, it runs into the shelves
    sim.reset()
    for action in sequence:
        played = clear_action(sim, action)
        expected_end = path_of(sim, played)[-1]
        if sim.decide(played).outcome is not None:
            break
        # Nothing blocked the human: it is where its arc ends (up to the physics' integration).
        np.testing.assert_allclose(sim.human_position, expected_end, atol=1e-3)

    result = DecisionSpace("open", detour=True).play(sim, sequence, keep_trajectory=False)
    replayed = sim.simulate(result.actions, keep_trajectory=False)
    assert replayed.summary == result.summary
    np.testing.assert_array_equal(replayed.actions, result.actions)
