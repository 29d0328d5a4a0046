import math

import numpy as np
import pytest

from hazardhunt.world.geometry import (
    distances_to_segments,
    point_half_disc_distance,
    point_in_polygon,
    point_rectangle_clearance,
    rectangle_corners,
    rectangle_face,
    to_body_frame,
)

LENGTH, WIDTH = 0.64, 0.5


def disc_clearance(center, x=0.0, y=0.0, heading=0.0, radius=0.25):
    """Clearance between a human disc at ``center`` and the robot's rectangle at (x, y)."""
    forward, left = to_body_frame(np.array(center), x, y, heading)
    return point_rectangle_clearance(forward, left, LENGTH, WIDTH) - radius


@pytest.mark.parametrize(
    ("center", "expected"),
    [
        ((1.0, 0.0), 1.0 - 0.32 - 0.25),  # ahead of the front face
        ((0.0, -1.0), 1.0 - 0.25 - 0.25),  # beside the right face
        ((0.32 + 0.3, 0.25 + 0.4), 0.5 - 0.25),  # off the front-left corner: 3-4-5 triangle
        ((0.0, 0.0), -0.25 - 0.25),  # centre inside: deepest penetration
    ],
)
def test_disc_rectangle_clearance_matches_hand_computation(center, expected):
    assert disc_clearance(center) == pytest.approx(expected)


def test_clearance_follows_the_robot_heading():
    # Robot facing north: a human 1 m north is in front of it, 0.43 m from its front face.
    clearance = disc_clearance([5.0, 6.0], 5.0, 5.0, math.pi / 2)
    assert clearance == pytest.approx(1.0 - 0.32 - 0.25)
    forward, left = to_body_frame(np.array([5.0, 6.0]), 5.0, 5.0, math.pi / 2)
    assert (forward, left) == pytest.approx((1.0, 0.0))


@pytest.mark.parametrize(
    ("point", "face"),
    [((1.0, 0.1), "front"), ((-1.0, 0.0), "rear"), ((0.1, 0.6), "left"), ((0.0, -0.6), "right")],
)
def test_rectangle_face(point, face):
    assert rectangle_face(*point, LENGTH, WIDTH) == face


def test_half_disc_distance():
    assert point_half_disc_distance(0.5, 0.0, 1.0) == 0.0  # inside
    assert point_half_disc_distance(2.0, 0.0, 1.0) == pytest.approx(1.0)  # beyond the arc
    assert point_half_disc_distance(-0.5, 0.0, 1.0) == pytest.approx(0.5)  # behind the edge
    assert point_half_disc_distance(-0.3, 1.4, 1.0) == pytest.approx(0.5)  # off the edge's end


def test_rectangle_corners_and_point_in_polygon():
    corners = rectangle_corners(1.0, 2.0, 0.0, 2.0, 1.0)
    assert corners[0] == pytest.approx([2.0, 2.5])
    assert point_in_polygon(np.array([1.0, 2.0]), corners)
    assert not point_in_polygon(np.array([2.5, 2.0]), corners)


def test_distances_to_segments_of_many_points_at_once():
    edges = np.array([[[0.0, 0.0], [4.0, 0.0]], [[4.0, 0.0], [4.0, 3.0]]])
    points = np.array([[2.0, 1.0], [5.0, 1.5], [7.0, 7.0], [4.0, 0.0]])
    assert distances_to_segments(points, edges) == pytest.approx([1.0, 1.0, 5.0, 0.0])
