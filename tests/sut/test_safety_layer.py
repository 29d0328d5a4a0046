import math
from pathlib import Path

import numpy as np
import pytest
import shapely
from shapely.geometry import Point, Polygon, box

from hazardhunt.sut.safety_layer import (
    FIELD_SETTINGS,
    FieldShape,
    LaserSafetyLayer,
    field_shape,
)
from hazardhunt.world.bodies import RobotState
from hazardhunt.world.scenario import load_scenario

ROBOT = RobotState(x=0.0, y=0.0, heading=0.0, speed=1.0, yaw_rate=0.0)
STANDING = RobotState(x=0.0, y=0.0, heading=0.0, speed=0.0, yaw_rate=0.0)
EXAMPLES = Path(__file__).parents[2] / "examples"
FRONT_FACE = 0.32
"""Half the built-in robot's length: the front face's distance ahead of its centre, in m."""


def in_field(setting, point, robot=ROBOT):
    layer = LaserSafetyLayer.for_field(FIELD_SETTINGS[setting])
    return layer.human_in_field(robot, np.array(point), 0.25)


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
    assert layer.update(0.0, ROBOT, inside, 0.25).emergency_stop
    # The human leaves, but the robot still rolls: the stop holds.
    assert layer.update(0.05, ROBOT, outside, 0.25).emergency_stop
    # Standing, but the human is back in the field: still holds.
    assert layer.update(0.1, STANDING, inside, 0.25).emergency_stop
    assert not layer.update(0.15, STANDING, outside, 0.25).emergency_stop


def test_with_a_response_time_the_brake_engages_that_much_later_even_if_the_human_left():
    layer = LaserSafetyLayer(2.0, response_time=0.15)
    inside, outside = np.array([1.0, 0.0]), np.array([5.0, 0.0])
    status = layer.update(1.0, ROBOT, inside, 0.25)
    assert status.human_in_field
    assert not status.emergency_stop
    assert not layer.update(1.05, ROBOT, outside, 0.25).emergency_stop
    assert not layer.update(1.10, ROBOT, outside, 0.25).emergency_stop
    assert layer.update(1.15, ROBOT, outside, 0.25).emergency_stop  # 0.15 s after the entry
    assert not layer.update(1.20, STANDING, outside, 0.25).emergency_stop


def test_no_field_never_stops():
    layer = LaserSafetyLayer(None)
    assert not layer.update(0.0, ROBOT, np.array([0.5, 0.0]), 0.25).emergency_stop


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


def study_field(diameter, side_margin=0.0):
    """The field drawn with shapely, independently of the layer's own geometry: a half-disc
    on the front face (a 1,024-gon) and the side bands as boxes."""
    radius = diameter / 2
    angles = np.linspace(-math.pi / 2, math.pi / 2, 1025)
    arc = [(FRONT_FACE + radius * math.cos(a), radius * math.sin(a)) for a in angles]
    shapes = [Polygon(arc)]
    if side_margin > 0:
        shapes.append(box(-FRONT_FACE, 0.25, FRONT_FACE, 0.25 + side_margin))
        shapes.append(box(-FRONT_FACE, -0.25 - side_margin, FRONT_FACE, -0.25))
    return shapely.union_all(shapes)


@pytest.mark.parametrize(("diameter", "side_margin"), [(1.25, 0.0), (2.0, 0.0), (1.25, 0.4)])
def test_the_layer_sees_the_human_exactly_where_the_drawn_field_is(diameter, side_margin):
    field = study_field(diameter, side_margin)
    layer = LaserSafetyLayer(diameter, side_margin=side_margin)
    checked = 0
    for point in np.random.default_rng(0).uniform(-2.0, 2.5, size=(2000, 2)):
        distance = field.distance(Point(point))
        if abs(distance - 0.25) < 1e-3:
            continue  # on the boundary, where the drawn polygon's chords decide
        assert layer.human_in_field(ROBOT, point, 0.25) == (distance < 0.25), point
        checked += 1
    assert checked > 1900


def test_bad_field_shapes_are_errors():
    with pytest.raises(ValueError, match="side_margin must be >= 0"):
        LaserSafetyLayer(1.25, side_margin=-0.1)
    with pytest.raises(ValueError, match="diameter must be a positive number"):
        LaserSafetyLayer(0.0)
    with pytest.raises(ValueError, match="response_time must be >= 0"):
        FieldShape(1.25, response_time=math.inf)


def test_a_scenario_defines_field_shapes_of_its_own():
    scenario = load_scenario(EXAMPLES / "loading_dock" / "dock_crossing.toml")
    assert field_shape(scenario, "sides") == FieldShape(1.25, 0.4)
    assert field_shape(scenario, "2m") == FieldShape(2.0)
    with pytest.raises(ValueError, match=r"unknown field 'wide': use one of none, 1\.25m, 2m"):
        field_shape(scenario, "wide")


@pytest.mark.parametrize(
    ("table", "expected"),
    [
        ({"side_margin": -1}, "fields.wide.side_margin: side_margin must be >= 0"),
        ({"diamter": 1.0}, "fields.wide.diamter: unknown key"),
        ({"response_time": "fast"}, "fields.wide.response_time: must be a number"),
    ],
)
def test_a_bad_field_table_names_the_file_and_the_key(table, expected):
    scenario = load_scenario("crossing")
    broken = type(scenario)(**{**vars(scenario), "fields": {"wide": table}})
    with pytest.raises(ValueError, match=expected) as caught:
        field_shape(broken, "wide")
    assert scenario.source in str(caught.value)


def test_a_scenario_cannot_redefine_a_built_in_field():
    scenario = load_scenario("crossing")
    broken = type(scenario)(**{**vars(scenario), "fields": {"2m": {"diameter": 3.0}}})
    with pytest.raises(ValueError, match="'2m' is a built-in field setting"):
        field_shape(broken, "none")
