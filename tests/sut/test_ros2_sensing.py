"""The ROS 2 bridge's simulated sensors, without ROS: the laser scan's ranges to walls, shelves
and the human, and the floor as an occupancy grid."""

import math

import numpy as np
import pytest

from hazardhunt.sut.ros2.sensing import (
    FREE,
    OCCUPIED,
    ScannerParams,
    floor_edges,
    occupancy,
    published_grid,
    scan_ranges,
)
from hazardhunt.world.floor import FloorMap, Obstacle
from hazardhunt.world.rosmap import UNKNOWN, OccupancyGrid, grid_floor

BOX = Obstacle("box", np.array([[6.0, 4.0], [8.0, 4.0], [8.0, 6.0], [6.0, 6.0]]))
FLOOR = FloorMap("room", 10.0, 10.0, (BOX,))


def ranges_at(angles, origin=(2.0, 5.0), heading=0.0, human=None, **scanner):
    params = ScannerParams(**scanner)
    ranges = scan_ranges(floor_edges(FLOOR), origin, heading, params, human)
    return {a: ranges[int(np.argmin(np.abs(params.angles - a)))] for a in angles}


def test_the_scan_reads_the_distance_to_the_nearest_shelf_or_wall_along_each_ray():
    seen = ranges_at([0.0, math.pi / 2, -math.pi / 2, math.pi / 4])
    assert seen[0.0] == pytest.approx(4.0)  # the box's west face at x = 6
    assert seen[math.pi / 2] == pytest.approx(5.0)  # the north wall at y = 10
    assert seen[-math.pi / 2] == pytest.approx(5.0)
    assert seen[math.pi / 4] == pytest.approx(5.0 * math.sqrt(2))  # the north wall, diagonally


def test_the_human_disc_shadows_what_lies_behind_it_and_the_heading_turns_the_rays():
    assert ranges_at([0.0], human=(4.0, 5.0, 0.25))[0.0] == pytest.approx(1.75)
    turned = ranges_at([0.0], heading=math.pi / 2, human=(4.0, 5.0, 0.25))
    assert turned[0.0] == pytest.approx(5.0)  # facing north, the human is to the right


def test_a_ray_beyond_range_max_reads_infinity_and_the_default_scanner_spans_270_degrees():
    assert ranges_at([0.0], range_max=3.0)[0.0] == math.inf
    angles = ScannerParams().angles
    assert len(angles) == 541
    assert angles[0] == pytest.approx(-0.75 * math.pi)
    assert angles[-1] == pytest.approx(0.75 * math.pi)


def test_the_occupancy_grid_marks_the_cells_inside_obstacles():
    cells, columns, rows = occupancy(FLOOR, 0.5)
    assert (columns, rows) == (20, 20)
    grid = cells.reshape(rows, columns)
    assert grid[10, 14] == OCCUPIED  # centre (7.25, 5.25) lies in the box
    assert grid[10, 11] == FREE  # (5.75, 5.25) lies west of it
    assert int((grid == OCCUPIED).sum()) == 16  # 2 m x 2 m in 0.5 m cells


def test_a_floor_read_from_a_site_map_is_published_as_that_maps_own_grid():
    # Row 0 is the south: an unknown cell stays unknown (-1), as map_server publishes it,
    # and the map's resolution is kept whatever map_resolution says.
    cells = np.array([[FREE, OCCUPIED, FREE], [UNKNOWN, FREE, FREE]], dtype=np.int8)
    site = grid_floor("site", OccupancyGrid(0.1, (-4.5, -2.25, 0.0), cells))
    data, columns, rows, resolution = published_grid(site, 0.05)
    assert (columns, rows, resolution) == (3, 2, 0.1)
    assert data.tolist() == [FREE, OCCUPIED, FREE, UNKNOWN, FREE, FREE]
    assert published_grid(FLOOR, 0.5)[1:] == (20, 20, 0.5)  # a polygon floor is rasterised
