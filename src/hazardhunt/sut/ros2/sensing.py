"""What the bridge's simulated sensors see: a 2-D laser scan ray-cast against the floor and the
human's disc, and the floor as an occupancy grid. Pure numpy; no ROS 2 here."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely

from hazardhunt.world.floor import FloorMap
from hazardhunt.world.geometry import FloatArray


@dataclass(frozen=True)
class ScannerParams:
    """The simulated 2-D laser scanner, mounted on the robot (defaults: a safety laser scanner's
    usual 270 degrees at 0.5 degree steps, 20 m, at the robot's centre)."""

    x: float = 0.0
    """Mounting position ahead of the robot's centre, in m."""
    y: float = 0.0
    """Mounting position to the left of the robot's centre, in m."""
    yaw: float = 0.0
    """Mounting angle from the robot's heading, in rad (counter-clockwise)."""
    angle_min: float = -0.75 * math.pi
    """First ray's angle from the scanner's axis, in rad."""
    angle_max: float = 0.75 * math.pi
    """Last ray's angle, in rad."""
    angle_increment: float = math.radians(0.5)
    """Angle between two rays, in rad."""
    range_min: float = 0.05
    """Shortest range the scanner reports, in m."""
    range_max: float = 20.0
    """Longest range; a ray that hits nothing nearer reads +inf, in m."""

    def __post_init__(self) -> None:
        if not (self.angle_increment > 0 and self.angle_max >= self.angle_min):
            raise ValueError("scanner: angle_increment must be positive, angle_max >= angle_min")
        if not (0 <= self.range_min < self.range_max):
            raise ValueError("scanner: need 0 <= range_min < range_max")

    @property
    def angles(self) -> FloatArray:
        """The rays' angles from the scanner's axis, in rad."""
        count = math.floor((self.angle_max - self.angle_min) / self.angle_increment + 1e-9) + 1
        return self.angle_min + self.angle_increment * np.arange(count, dtype=np.float64)


def floor_edges(floor: FloorMap) -> FloatArray:
    """The segments a ray can hit: every obstacle edge and the floor's outline, shape (E, 2, 2)."""
    w, h = floor.width, floor.height
    corners = np.array([[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]])
    outline = np.stack([corners, np.roll(corners, -1, axis=0)], axis=1)
    return np.concatenate([floor.edges.reshape(-1, 2, 2), outline])


def scan_ranges(
    edges: FloatArray,
    origin: tuple[float, float],
    heading: float,
    scanner: ScannerParams,
    human: tuple[float, float, float] | None,
) -> FloatArray:
    """The ranges one scan reads, in m (+inf where a ray hits nothing within ``range_max``).

    Args:
        edges: The segments of :func:`floor_edges`.
        origin: The scanner's position in the world, in m.
        heading: The scanner's axis in the world, in rad.
        scanner: Its field of view, resolution and range.
        human: The human's disc as (x, y, radius) in m, or None.
    """
    angles = heading + scanner.angles
    directions = np.stack([np.cos(angles), np.sin(angles)], axis=1)  # (N, 2)
    ox, oy = origin
    starts = edges[:, 0, :] - (ox, oy)  # (E, 2)
    spans = edges[:, 1, :] - edges[:, 0, :]
    denominator = (
        directions[:, None, 0] * spans[None, :, 1] - directions[:, None, 1] * spans[None, :, 0]
    )
    with np.errstate(divide="ignore", invalid="ignore"):
        along_ray = (
            starts[None, :, 0] * spans[None, :, 1] - starts[None, :, 1] * spans[None, :, 0]
        ) / denominator
        along_edge = (
            starts[None, :, 0] * directions[:, None, 1]
            - starts[None, :, 1] * directions[:, None, 0]
        ) / denominator
    hit = (denominator != 0) & (along_ray >= 0) & (along_edge >= 0) & (along_edge <= 1)
    ranges = np.where(hit, along_ray, np.inf).min(axis=1, initial=np.inf)
    if human is not None:
        hx, hy, radius = human[0] - ox, human[1] - oy, human[2]
        ahead = directions[:, 0] * hx + directions[:, 1] * hy
        discriminant = ahead**2 - (hx * hx + hy * hy - radius * radius)
        with np.errstate(invalid="ignore"):
            near = ahead - np.sqrt(discriminant)
        ranges = np.where((discriminant >= 0) & (near >= 0), np.minimum(ranges, near), ranges)
    ranges = np.where(ranges < scanner.range_min, scanner.range_min, ranges)
    return np.where(ranges > scanner.range_max, np.inf, ranges)


OCCUPIED, FREE = 100, 0
"""The OccupancyGrid values of a cell inside an obstacle and of a free one."""


def published_grid(floor: FloorMap, resolution: float) -> tuple[np.ndarray, int, int, float]:
    """The occupancy grid the bridge publishes of ``floor``: a site map's own grid, at its own
    resolution and with its unknown cells (-1), for a floor read from a ROS map; any other floor
    rasterised at ``resolution`` (:func:`occupancy`).

    Returns:
        The cells row by row from the south (int8, as OccupancyGrid.data), width and height in
        cells, and the side of a cell in m.
    """
    if floor.occupancy is not None:
        grid = floor.occupancy
        return grid.cells.ravel(), grid.columns, grid.rows, grid.resolution
    return (*occupancy(floor, resolution), resolution)


def occupancy(floor: FloorMap, resolution: float) -> tuple[np.ndarray, int, int]:
    """The floor as a grid of ``resolution`` m cells from (0, 0): a cell whose centre lies in an
    obstacle is :data:`OCCUPIED`, any other :data:`FREE`.

    Returns:
        The cells row by row from the south (int8, as OccupancyGrid.data), width and height in
        cells.
    """
    columns = max(math.ceil(floor.width / resolution - 1e-9), 1)
    rows = max(math.ceil(floor.height / resolution - 1e-9), 1)
    xs = (np.arange(columns) + 0.5) * resolution
    ys = (np.arange(rows) + 0.5) * resolution
    grid_x, grid_y = np.meshgrid(xs, ys)
    occupied = np.zeros(grid_x.shape, dtype=bool)
    for obstacle in floor.obstacles:
        polygon = shapely.Polygon(obstacle.polygon)
        occupied |= shapely.contains_xy(polygon, grid_x, grid_y)
    cells = np.where(occupied, OCCUPIED, FREE).astype(np.int8)
    return cells.ravel(), columns, rows
