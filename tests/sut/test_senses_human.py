"""A controller with the optional ``sense_human`` (SensesHuman) gets the human's true position
at each control instant, also where the tracking cameras do not see the human; one without it
is called as before."""

import dataclasses

import numpy as np
import pytest

from hazardhunt.sim.effects import SutEffects
from hazardhunt.sim.simulation import Simulation
from hazardhunt.sut.plugins import PluginError, build_controller
from hazardhunt.sut.protocols import SensesHuman
from hazardhunt.sut.pursuit import PursuitController
from hazardhunt.world.scenario import load_scenario

STANDING = np.array([[-1.0, 0.0]] * 5, dtype=np.float32)  # the human stands still


def crossing_with_the_human_hidden():
    """The crossing scenario with a camera-blind zone around the human's start (10, 5)."""
    scenario = load_scenario("crossing")
    zone = np.array([[9.0, 4.0], [11.0, 4.0], [11.0, 6.0], [9.0, 6.0]])
    floor = dataclasses.replace(scenario.floor, blind_zones=(zone,))
    return dataclasses.replace(scenario, floor=floor)


class Sensing(PursuitController):
    def __init__(self) -> None:
        super().__init__()
        self.sensed: list[tuple[float, tuple[float, float], float]] = []
        self.tracked: list[object] = []

    def sense_human(self, time, human_position, radius):
        self.sensed.append((time, tuple(human_position.tolist()), radius))

    def control(self, time, robot, human):
        self.tracked.append(human)
        return super().control(time, robot, human)


class SenseRaises(PursuitController):
    def sense_human(self, time, human_position, radius):
        raise ValueError("no laser")


class SenseTakesTwo(PursuitController):
    def sense_human(self, time, human_position):
        pass


def test_a_sensing_controller_gets_the_true_human_where_the_cameras_do_not_see_it():
    controller = Sensing()
    assert isinstance(controller, SensesHuman)
    simulation = Simulation.build(crossing_with_the_human_hidden(), "none", controller=controller)
    simulation.simulate(STANDING)
    assert controller.tracked
    assert all(human is None for human in controller.tracked)
    assert len(controller.sensed) == len(controller.tracked)  # once before each control call
    times = [time for time, _, _ in controller.sensed]
    assert times == pytest.approx([0.2 * k for k in range(len(times))])
    assert {position for _, position, _ in controller.sensed} == {(10.0, 5.0)}
    assert {radius for _, _, radius in controller.sensed} == {0.25}


def test_the_uncertainties_noise_and_dropped_frames_reach_the_tracks_not_the_true_human():
    controller = Sensing()
    simulation = Simulation.build("crossing", "none", controller=controller)
    simulation.effects = SutEffects(tracking_noise=0.3, dropped_frames=0.5, seed=4)
    simulation.simulate(STANDING)
    tracked = controller.tracked
    assert None in tracked  # frames dropped
    seen = [h.position.tolist() for h in tracked if h is not None]
    assert seen
    assert all(p != [10.0, 5.0] for p in seen)  # noisy
    assert {position for _, position, _ in controller.sensed} == {(10.0, 5.0)}


def test_a_sensing_controller_plays_the_same_episodes_as_one_without_the_method():
    plain, sensing = PursuitController(), Sensing()
    actions = np.random.default_rng(3).uniform(-1, 1, size=(15, 2)).astype(np.float32)
    summaries = []
    for controller in (plain, sensing):
        simulation = Simulation.build("crossing", "none", controller=controller)
        simulation.simulate(actions)
        summaries.append((simulation.summary().outcome, simulation.trajectory()))
    assert summaries[0][0] == summaries[1][0]
    assert [s.robot_x for s in summaries[0][1]] == [s.robot_x for s in summaries[1][1]]


def test_a_sense_human_that_raises_makes_the_episode_a_sut_error():
    simulation = Simulation.build("crossing", "none", controller=SenseRaises())
    assert simulation.simulate(STANDING).outcome == "sut_error"
    assert simulation.summary().controller_errors == ("ValueError: no laser",)


def test_a_sense_human_with_other_parameters_is_one_line_naming_the_signature():
    with pytest.raises(PluginError) as raised:
        build_controller("tests.sut.test_senses_human:SenseTakesTwo")
    assert str(raised.value) == (
        "'tests.sut.test_senses_human:SenseTakesTwo': sense_human(time, human_position) does "
        "not fit the protocol: it must take (time, human_position, radius) (docs/plugins.md)"
    )
