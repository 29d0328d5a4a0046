"""Scripted humans against the real NMPC and safety layer: the outcomes a person would expect."""

import dataclasses
import math

import pytest

from hazardhunt.sim.simulation import Simulation
from hazardhunt.spec.descriptors import describe
from hazardhunt.sut.nmpc import NMPCController
from hazardhunt.sut.safety_layer import FIELD_SETTINGS
from hazardhunt.world.scenario import BUILTIN_SCENARIOS, Pose, load_scenario
from tests.scripted import run, stand_still, steer_towards

NMPC = NMPCController()  # built once: construction is the expensive part


def make(scenario, field, **kwargs):
    return Simulation.build(scenario, field, controller=NMPC, decision_period=0.2, **kwargs)


@pytest.mark.parametrize("field", list(FIELD_SETTINGS))
@pytest.mark.parametrize("name", BUILTIN_SCENARIOS)
def test_without_human_interference_the_robot_reaches_its_goal(name, field):
    # The human waits in the far south-west corner aisle.
    scenario = dataclasses.replace(load_scenario(name), human_start=Pose(0.85, 0.85, 0.0))
    result = run(make(scenario, field), stand_still)
    assert result.outcome == "goal"
    assert result.summary.sim_time < 30.0
    assert result.summary.emergency_stops == 0
    assert result.summary.controller_failures == 0


def test_nmpc_gives_way_to_a_human_crossing_slowly_ahead():
    sim = make("crossing", "none")

    def cross_slowly(sim):
        # Straight north across the main aisle, reaching the route as the robot arrives.
        return 0.6, 0.0

    result = run(sim, cross_slowly)
    rows = sim.trajectory()
    assert result.outcome == "goal"
    assert result.summary.min_clearance > 0.2
    # The robot noticeably slowed below its cruise speed or left its straight route.
    cruising = [r for r in rows if 3.0 < r.time < 14.0]
    slowed = min(r.robot_speed for r in cruising) < 0.8
    steered = max(abs(r.robot_y - 10.0) for r in rows) > 0.3
    assert slowed or steered


def side_attack(sim):
    """Wait beside the main aisle south of the route, then dash into the robot's right side."""
    human_x, human_y, _ = sim.human_pose
    robot = sim.robot
    if robot.x > human_x - 0.45:
        return steer_towards(sim, (robot.x, robot.y), 1.5)
    return steer_towards(sim, (10.0, 8.8), 1.5) if human_y < 8.8 else (0.0, 0.0)


@pytest.mark.parametrize("field", ["none", "1.25m"])
def test_a_human_walking_into_the_robots_side_is_a_failure(field):
    sim = make("crossing", field)
    result = run(sim, side_attack)
    assert result.outcome == "failure"
    assert result.summary.contact_face in {"left", "right"}
    assert result.summary.emergency_stops == 0  # the side is not covered by the field


def test_a_human_stepping_into_the_field_stops_the_robot_then_bumping_it_is_safe():
    sim = make("head-on", "2m")
    stopped = []

    def step_in_then_bump(sim):
        robot = sim.robot
        if sim.emergency_stop and robot.speed == 0.0:
            stopped.append(sim.sim_time)
        if stopped:
            return steer_towards(sim, (robot.x, robot.y), 0.5)
        return steer_towards(sim, (robot.x, robot.y), 0.6)

    result = run(sim, step_in_then_bump)
    assert stopped, "the emergency stop never brought the robot to a standstill"
    assert result.outcome == "safe_contact"
    assert result.summary.contact_verdict == "robot_standing"


def test_a_faster_human_catching_the_robot_from_behind_is_a_safe_contact():
    scenario = dataclasses.replace(load_scenario("overtaking"), human_start=Pose(0.6, 10.0, 0.0))
    sim = make(scenario, "1.25m")
    chasing = []

    def chase(sim):
        robot = sim.robot
        if robot.speed > 0.8 or chasing:  # let the robot get going, then run after it
            chasing.append(sim.sim_time)
            return steer_towards(sim, (robot.x, robot.y), 1.5)
        return 0.0, 0.0

    result = run(sim, chase)
    assert result.outcome == "safe_contact"
    assert result.summary.contact_verdict == "human_from_behind"
    assert result.summary.contact_face == "rear"


def test_a_human_loitering_in_the_field_stalls_the_episode():
    sim = make("head-on", "1.25m")

    def loiter(sim):
        if sim.emergency_stop:
            return 0.0, 0.0  # stay in the field, never touch the robot
        robot = sim.robot
        return steer_towards(sim, (robot.x, robot.y), 0.8)

    result = run(sim, loiter)
    assert result.outcome == "stall"
    assert sim.emergency_stop
    assert result.summary.contact_face is None
    first_stop = next(r.time for r in sim.trajectory() if r.emergency_stop)
    assert result.summary.sim_time == pytest.approx(first_stop + 10.0, abs=0.25)
    assert math.isclose(result.summary.time_in_field, 10.0, abs_tol=0.3)


@pytest.mark.parametrize("field", ["none", "1.25m"])
def test_the_failure_descriptor_places_a_side_attack_on_the_robots_right(field):
    result = run(make("crossing", field), side_attack)
    bearing, robot_speed, emergency_stop, human_speed = describe(result.summary)
    assert -math.pi * 3 / 4 < bearing < -math.pi / 4  # the human came from the south
    assert robot_speed > 0.5
    assert emergency_stop == 0.0  # the field never saw it
    assert human_speed > 1.0  # it ran into the robot
