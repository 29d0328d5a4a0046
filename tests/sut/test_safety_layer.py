import math

import numpy as np
import pytest

from hazardhunt.sut.protocols import RobotState
from hazardhunt.sut.safety_layer import FIELD_SETTINGS, LaserSafetyLayer
from hazardhunt.world.geometry import point_half_disc_distance, to_body_frame
from hazardhunt.world.scenario import field_shape, load_scenario

ROBOT = RobotState(x=0.0, y=0.0, heading=0.0, speed=1.0, yaw_rate=0.0)


def in_field(setting, point, robot=ROBOT):
    return LaserSafetyLayer(FIELD_SETTINGS[setting]).human_in_field(robot, np.array(point), 0.25)


@pytest.mark.parametrize(
    ("setting", "reach"),
    [("1.25m", 0.32 + 0.625 + 0.25), ("2m", 0.32 + 1.0 + 0.25)],
)
def test_the_field_reaches_half_its_diameter_ahead_of_the_front_face(setting, reach):
    assert in_field(setting, (reach - 0.01, 0.0))
    assert not in_field(setting, (reach + 0.01, 0.0))


@pytest.mark.parametrize("setting", list(FIELD_SETTINGS))
def test_the_robots_sides_and_rear_are_not_covered(setting):
    assert not in_field(setting, (0.0, 0.26 + 0.25))  # touching distance of the left side
    assert not in_field(setting, (0.0, -0.26 - 0.25))
    assert not in_field(setting, (-0.6, 0.0))


def test_the_field_turns_with_the_robot():
    north = RobotState(x=0.0, y=0.0, heading=math.pi / 2, speed=1.0, yaw_rate=0.0)
    assert in_field("2m", (0.0, 1.0), north)
    assert not in_field("2m", (1.0, 0.0), north)


def test_the_stop_holds_until_the_robot_stands_and_the_field_is_free():
    layer = LaserSafetyLayer(2.0)
    inside, outside = np.array([1.0, 0.0]), np.array([5.0, 0.0])
    assert layer.update(ROBOT, inside, 0.25).emergency_stop
    # The human leaves, but the robot still rolls: the stop holds.
    assert layer.update(ROBOT, outside, 0.25).emergency_stop
    standing = RobotState(x=0.0, y=0.0, heading=0.0, speed=0.0, yaw_rate=0.0)
    # Standing, but the human is back in the field: still holds.
    assert layer.update(standing, inside, 0.25).emergency_stop
    assert not layer.update(standing, outside, 0.25).emergency_stop


def test_no_field_never_stops():
    layer = LaserSafetyLayer(None)
    assert not layer.update(ROBOT, np.array([0.5, 0.0]), 0.25).emergency_stop


def test_unknown_setting_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown field '3m'"):
        field_shape(load_scenario("crossing"), "3m")


def test_side_bands_cover_the_robots_sides_up_to_their_width():
    layer = LaserSafetyLayer(1.25, side_margin=0.4)
    reach = 0.25 + 0.4 + 0.25  # half the width, the band, the human's radius
    for side in (1.0, -1.0):
        assert layer.human_in_field(ROBOT, np.array([0.0, side * (reach - 0.01)]), 0.25)
        assert not layer.human_in_field(ROBOT, np.array([0.0, side * (reach + 0.01)]), 0.25)
    # Along the whole body, from the rear face to the front face, and no further back.
    assert layer.human_in_field(ROBOT, np.array([-0.3, 0.6]), 0.25)
    assert not layer.human_in_field(ROBOT, np.array([-0.32 - 0.26, 0.6]), 0.25)
    # The front field is unchanged.
    assert layer.human_in_field(ROBOT, np.array([0.32 + 0.625 + 0.24, 0.0]), 0.25)


def test_without_side_bands_the_layer_is_the_studys():
    # The study's field: the human disc overlaps the half-disc ahead of the front face.
    rng = np.random.default_rng(0)
    layer = LaserSafetyLayer(1.25)
    for point in rng.uniform(-2.0, 2.0, size=(500, 2)):
        forward, left = to_body_frame(point, ROBOT.x, ROBOT.y, ROBOT.heading)
        study = point_half_disc_distance(forward - 0.32, left, 0.625) < 0.25
        assert layer.human_in_field(ROBOT, point, 0.25) == study


def test_bad_field_shapes_are_errors():
    with pytest.raises(ValueError, match="side_margin must be >= 0"):
        LaserSafetyLayer(1.25, side_margin=-0.1)
    with pytest.raises(ValueError, match="diameter must be positive or None"):
        LaserSafetyLayer(0.0)
