"""The ways round walls and shelves a human walking to a point takes (clear_path)."""

import math

import numpy as np
import pytest

from hazardhunt.world.floor import FloorMap, Obstacle
from hazardhunt.world.navigation import MARGIN, reach
from hazardhunt.world.scenario import load_scenario

RADIUS = 0.25


def walk(floor: FloorMap, start, target, step=0.2, limit=400):
    """Positions of a point that heads for each waypoint in turn, ``step`` at a time."""
    grid = floor.walk_grid(RADIUS)
    here, path = np.asarray(start, dtype=float), []
    for _ in range(limit):
        point, _ = grid.waypoint(here, np.asarray(target, dtype=float))
        gap = point - here
        distance = math.hypot(*gap)
        here = point.copy() if distance <= step else here + step * gap / distance
        path.append(here.copy())
        if math.hypot(*(here - target)) < 1e-9:
            break
    return np.array(path)


def wall_with_a_gap() -> FloorMap:
    """A 10 m x 10 m floor split by a wall at x 5, open only at its north end (y 8 to 10)."""
    wall = Obstacle("wall", np.array([[4.9, 0.0], [5.1, 0.0], [5.1, 8.0], [4.9, 8.0]]), "wall")
    return FloorMap("split", 10.0, 10.0, (wall,))


def test_a_target_in_plain_sight_is_walked_to_straight():
    floor = load_scenario("crossing").floor
    target = np.array([10.0, 12.0])
    point, length = floor.walk_grid(RADIUS).waypoint(np.array([10.0, 6.0]), target)
    np.testing.assert_array_equal(point, target)
    assert length == pytest.approx(6.0)


def test_a_target_behind_a_wall_is_reached_through_the_gap_without_touching_it():
    floor = wall_with_a_gap()
    start, target = np.array([2.0, 2.0]), np.array([8.0, 2.0])
    path = walk(floor, start, target)
    np.testing.assert_allclose(path[-1], target)
    assert path[:, 1].max() > 8.0  # through the gap
    assert not any(floor.disc_blocked(p, RADIUS) for p in path)
    # The way is short: little more than up to the gap, across and down again.
    walked = np.sum(np.hypot(*np.diff(np.vstack([start, path]), axis=0).T))
    assert walked < 2 * math.hypot(3.0, 6.5) + 1.0


def test_the_length_of_the_way_counts_the_detour():
    floor = wall_with_a_gap()
    _, length = floor.walk_grid(RADIUS).waypoint(np.array([2.0, 2.0]), np.array([8.0, 2.0]))
    assert 2 * math.hypot(3.0, 6.3) - 0.5 < length < 2 * math.hypot(3.0, 6.8) + 1.0


def test_a_target_nobody_can_reach_is_headed_for_straight():
    # Walled in completely: there is no way round, so the human walks as far as it gets.
    wall = Obstacle("wall", np.array([[4.9, 0.0], [5.1, 0.0], [5.1, 10.0], [4.9, 10.0]]), "wall")
    floor = FloorMap("closed", 10.0, 10.0, (wall,))
    target = np.array([8.0, 2.0])
    point, _ = floor.walk_grid(RADIUS).waypoint(np.array([2.0, 2.0]), target)
    np.testing.assert_array_equal(point, target)


def test_the_grid_is_built_once_per_radius():
    floor = wall_with_a_gap()
    assert floor.walk_grid(RADIUS) is floor.walk_grid(RADIUS)
    assert floor.walk_grid(0.3) is not floor.walk_grid(RADIUS)


def test_the_reach_ends_where_the_disc_would_come_within_the_margin_of_a_wall():
    floor = wall_with_a_gap()
    east = np.array([1.0, 0.0])
    # From x 2 towards the wall at x 4.9: the disc keeps MARGIN clear up to x 4.9 - r - MARGIN.
    far = reach(floor, RADIUS, np.array([2.0, 2.0]), east, 6.0)
    assert far == pytest.approx(4.9 - RADIUS - MARGIN - 2.0, abs=0.01)
    assert not floor.disc_blocked_at(2.0 + far, 2.0, RADIUS + MARGIN)
    # Short of the wall, or through the gap, the whole length.
    assert reach(floor, RADIUS, np.array([2.0, 2.0]), east, 1.0) == 1.0
    assert reach(floor, RADIUS, np.array([2.0, 9.0]), east, 6.0) == 6.0
    # Where the disc does not fit to begin with, nothing.
    assert reach(floor, RADIUS, np.array([5.0, 2.0]), east, 3.0) == 0.0
