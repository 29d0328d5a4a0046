import math

import numpy as np
import pytest

from hazardhunt.world.bodies import RobotParams, RobotState
from hazardhunt.world.geometry import distances_to_segments
from hazardhunt.world.kinematics import move_human, step_robot
from hazardhunt.world.scenario import load_scenario

FLOOR = load_scenario("crossing").floor


def walk(position, heading, speed, turn_rate, seconds):
    x, y = position
    for _ in range(round(seconds / 0.05)):
        x, y, heading, *_ = move_human(x, y, heading, speed, turn_rate, 0.05, FLOOR, 0.25)
    return np.array([x, y]), heading


def test_human_walks_straight_in_free_space():
    position, _ = walk((10.0, 10.0), 0.0, 1.0, 0.0, 1.0)
    assert position == pytest.approx([11.0, 10.0])


def test_human_is_stopped_by_a_shelf_and_never_enters_it():
    # Walking south from the main aisle into shelf block SW-2 (top face at y = 8.5).
    position, _ = walk((5.0, 10.0), -math.pi / 2, 1.5, 0.0, 5.0)
    assert position[1] >= 8.5 + 0.25 - 1e-9
    assert FLOOR.obstacle_clearance(position) >= 0.25 - 1e-9


def test_human_slides_along_a_wall_when_walking_into_it_at_an_angle():
    # Heading south-east into the shelf top face: the eastward part of the motion survives.
    position, _ = walk((3.0, 9.5), -math.pi / 4, 1.5, 0.0, 3.0)
    assert position[1] == pytest.approx(8.75, abs=0.08)
    assert position[0] > 5.5


def test_robot_respects_acceleration_and_speed_limits():
    params = RobotParams()
    motion = step_robot(RobotState(0.0, 0.0, 0.0, 0.0, 0.0), 5.0, 5.0, 0.05, params)
    assert motion.speed == pytest.approx(0.05)  # 1 m/s^2 for 0.05 s
    assert motion.yaw_rate == pytest.approx(0.15)  # 3 rad/s^2 for 0.05 s
    for _ in range(100):
        motion = step_robot(motion, 5.0, 5.0, 0.05, params)
    assert motion.speed == pytest.approx(1.2)
    assert motion.yaw_rate == pytest.approx(0.5)


def test_emergency_stop_brakes_at_7_5_and_stops_turning():
    motion = step_robot(
        RobotState(0, 0, 0, 1.0, 0.3), 1.0, 0.3, 0.05, RobotParams(), emergency_stop=True
    )
    assert motion.speed == pytest.approx(1.0 - 7.5 * 0.05)
    assert motion.yaw_rate == 0.0
    # From 1 m/s the robot stands within three physics steps and never backs up.
    for _ in range(3):
        motion = step_robot(
            RobotState(motion.x, motion.y, motion.heading, motion.speed, 0.0),
            1.0,
            0.0,
            0.05,
            RobotParams(),
            True,
        )
    assert motion.speed == 0.0


def test_disc_blocked_agrees_with_the_edge_arrays_everywhere_on_the_floor():
    # The scalar fast path must answer exactly as the vectorised distance and even-odd tests.
    floor = load_scenario("crossing").floor
    rng = np.random.default_rng(3)
    points = rng.uniform(-0.5, 20.5, size=(4000, 2))
    radius = 0.25
    blocked = [floor.disc_blocked(p, radius) for p in points]
    distances = distances_to_segments(points, floor.edges)
    expected = [
        not floor.on_floor(p, radius) or d < radius or floor.inside_obstacle(p)
        for p, d in zip(points, distances, strict=True)
    ]
    assert blocked == expected
    assert 0.2 < np.mean(blocked) < 0.8  # both answers are exercised


def test_discs_clear_agrees_with_the_edge_arrays_on_paths_and_at_touching_distance():
    # Skipping obstacles by their bounding boxes must answer exactly as the distances to
    # every edge, also for discs that touch a shelf or miss it by a hair.
    floor = load_scenario("crossing").floor
    rng = np.random.default_rng(4)
    radius = 0.25
    paths = [
        rng.uniform(0.0, 20.0, size=2) + np.cumsum(rng.normal(scale=0.05, size=(40, 2)), axis=0)
        for _ in range(600)
    ]
    along_shelf = np.linspace(2.0, 8.0, 40)  # above shelf block SW-2, whose top is y = 8.5
    touching = [
        np.column_stack([along_shelf, np.full(40, 8.5 + radius + gap)])
        for gap in (0.0, 1e-12, -1e-12)
    ]
    clear = [floor.discs_clear(path, radius) for path in paths + touching]
    expected = [
        bool(
            np.all(path >= radius)
            and np.all(path[:, 0] <= floor.width - radius)
            and np.all(path[:, 1] <= floor.height - radius)
            and np.all(distances_to_segments(path, floor.edges) >= radius)
        )
        for path in paths + touching
    ]
    assert clear == expected
    assert clear[-3:] == [True, True, False]
    assert 0.2 < np.mean(clear) < 0.8  # both answers are exercised
