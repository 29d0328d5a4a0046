"""Scripted humans against the real NMPC and safety layer: the outcomes a person would expect."""

import dataclasses
import math

import pytest

from hazardhunt.env.agv import AGVEnv
from hazardhunt.sut.nmpc import NMPCController
from hazardhunt.sut.safety_layer import FIELD_SETTINGS
from hazardhunt.world.scenario import BUILTIN_SCENARIOS, Pose, load_scenario
from tests.scripted import run, stand_still, steer_towards

NMPC = NMPCController()  # built once: construction is the expensive part


def make(scenario, field, **kwargs):
    return AGVEnv(scenario, field, controller=NMPC, decision_period=0.2, **kwargs)


@pytest.mark.parametrize("field", list(FIELD_SETTINGS))
@pytest.mark.parametrize("name", BUILTIN_SCENARIOS)
def test_without_human_interference_the_robot_reaches_its_goal(name, field):
    # The human waits in the far south-west corner aisle.
    scenario = dataclasses.replace(load_scenario(name), human_start=Pose(0.85, 0.85, 0.0))
    info, _ = run(make(scenario, field), stand_still)
    assert info["outcome"] == "goal"
    assert info["sim_time"] < 30.0
    assert info["estop_count"] == 0
    assert info["summary"]["failed_commands"] == 0


def test_nmpc_gives_way_to_a_human_crossing_slowly_ahead():
    env = make("crossing", "none")

    def cross_slowly(env):
        # Straight north across the main aisle, reaching the route as the robot arrives.
        return 0.6, 0.0

    info, _ = run(env, cross_slowly)
    rows = env.trajectory()
    assert info["outcome"] == "goal"
    assert info["min_clearance"] > 0.2
    # The robot noticeably slowed below its cruise speed or left its straight route.
    cruising = [r for r in rows if 3.0 < r["time"] < 14.0]
    slowed = min(r["robot_speed"] for r in cruising) < 0.8
    steered = max(abs(r["robot_y"] - 10.0) for r in rows) > 0.3
    assert slowed or steered


def side_attack(env):
    """Wait beside the main aisle south of the route, then dash into the robot's right side."""
    human_x, human_y, _ = env.human_pose
    robot = env.robot_state
    if robot.x > human_x - 0.45:
        return steer_towards(env, (robot.x, robot.y), 1.5)
    return steer_towards(env, (10.0, 8.8), 1.5) if human_y < 8.8 else (0.0, 0.0)


@pytest.mark.parametrize("field", ["none", "1.25m"])
def test_a_human_walking_into_the_robots_side_is_a_failure(field):
    env = make("crossing", field)
    info, _ = run(env, side_attack)
    assert info["outcome"] == "failure"
    assert info["summary"]["contact_face"] in {"left", "right"}
    assert info["estop_count"] == 0  # the side is not covered by the field


def test_a_human_stepping_into_the_field_stops_the_robot_then_bumping_it_is_safe():
    env = make("head-on", "2m")
    stopped = []

    def step_in_then_bump(env):
        robot = env.robot_state
        if env.emergency_stop and robot.speed == 0.0:
            stopped.append(env.sim_time)
        if stopped:
            return steer_towards(env, (robot.x, robot.y), 0.5)
        return steer_towards(env, (robot.x, robot.y), 0.6)

    info, _ = run(env, step_in_then_bump)
    assert stopped, "the emergency stop never brought the robot to a standstill"
    assert info["outcome"] == "safe_contact"
    assert info["contact_verdict"] == "robot_standing"


def test_a_faster_human_catching_the_robot_from_behind_is_a_safe_contact():
    scenario = dataclasses.replace(load_scenario("overtaking"), human_start=Pose(0.6, 10.0, 0.0))
    env = make(scenario, "1.25m")
    chasing = []

    def chase(env):
        robot = env.robot_state
        if robot.speed > 0.8 or chasing:  # let the robot get going, then run after it
            chasing.append(env.sim_time)
            return steer_towards(env, (robot.x, robot.y), 1.5)
        return 0.0, 0.0

    info, _ = run(env, chase)
    assert info["outcome"] == "safe_contact"
    assert info["contact_verdict"] == "human_from_behind"
    assert info["summary"]["contact_face"] == "rear"


def test_a_human_loitering_in_the_field_stalls_the_episode():
    env = make("head-on", "1.25m", reward="acc")

    def loiter(env):
        if env.emergency_stop:
            return 0.0, 0.0  # stay in the field, never touch the robot
        robot = env.robot_state
        return steer_towards(env, (robot.x, robot.y), 0.8)

    info, _ = run(env, loiter)
    assert info["outcome"] == "stall"
    assert info["estop"]
    assert info["contact"] is False
    first_stop = next(r["time"] for r in env.trajectory() if r["emergency_stop"])
    assert info["sim_time"] == pytest.approx(first_stop + 10.0, abs=0.25)
    assert math.isclose(info["time_in_field"], 10.0, abs_tol=0.3)
