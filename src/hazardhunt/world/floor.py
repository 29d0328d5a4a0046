"""The shop floor: walls, shelf blocks and camera-blind zones, as polygons."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from hazardhunt.world.geometry import (
    FloatArray,
    distances_to_segments,
    point_in_polygon,
    polygon_edges,
)
from hazardhunt.world.navigation import WalkGrid

if TYPE_CHECKING:
    from hazardhunt.world.rosmap import OccupancyGrid


@dataclass(frozen=True)
class Obstacle:
    """A static obstacle (wall or shelf block) that blocks the human and the robot."""

    name: str
    polygon: FloatArray
    """Shape (K, 2): vertices counter-clockwise, in m."""
    kind: str = "shelf"
    """``"wall"`` or ``"shelf"``."""


@dataclass(frozen=True)
class FloorMap:
    """A shop floor: its extent, its static obstacles and the zones the cameras do not see."""

    name: str
    width: float
    """Extent east, in m (the floor spans x in [0, width])."""
    height: float
    """Extent north, in m (the floor spans y in [0, height])."""
    obstacles: tuple[Obstacle, ...]
    blind_zones: tuple[FloatArray, ...] = ()
    """Polygons (K, 2) where the tracking cameras do not see the human."""
    occupancy: OccupancyGrid | None = field(default=None, repr=False, compare=False)
    """The site map the floor was read from (its obstacles are the map's blocked cells), or
    None for a floor of polygons."""
    edges: FloatArray = field(init=False, repr=False, compare=False)
    """All obstacle edges, shape (E, 2, 2), for fast clearance queries."""
    edge_owner: NDArray[np.intp] = field(init=False, repr=False, compare=False)
    """Shape (E,): index of the obstacle each edge belongs to."""
    bounding_boxes: tuple[tuple[float, float, float, float], ...] = field(
        init=False, repr=False, compare=False
    )
    """Per obstacle (x min, y min, x max, y max), in m."""
    _box_array: FloatArray = field(init=False, repr=False, compare=False)
    """``bounding_boxes`` as an array, shape (N, 4)."""
    _segments: tuple[tuple[tuple[int, float, float, float, float, float, float], ...], ...] = field(
        init=False, repr=False, compare=False
    )
    """Per obstacle its edges as (index into ``edges``, start x, start y, end y, direction x,
    direction y, squared length or 1 for a zero-length edge), Python floats for scalar
    queries."""
    _cells_by_radius: dict[float, _ObstacleCells] = field(init=False, repr=False, compare=False)
    """Per disc radius: which obstacles a disc centred in each cell of a grid over the floor
    may touch (:meth:`_cells`)."""
    _walk_grids: dict[float, WalkGrid] = field(init=False, repr=False, compare=False)
    """Per disc radius: the ways round the obstacles (:meth:`walk_grid`)."""

    def __post_init__(self) -> None:
        polygons = [o.polygon for o in self.obstacles]
        owners = [np.full(len(p), i, dtype=np.intp) for i, p in enumerate(polygons)]
        object.__setattr__(self, "edges", polygon_edges(polygons))
        object.__setattr__(
            self, "edge_owner", np.concatenate(owners) if owners else np.zeros(0, dtype=np.intp)
        )
        boxes = tuple(
            (float(p[:, 0].min()), float(p[:, 1].min()), float(p[:, 0].max()), float(p[:, 1].max()))
            for p in polygons
        )
        object.__setattr__(self, "bounding_boxes", boxes)
        object.__setattr__(self, "_box_array", np.array(boxes, dtype=np.float64).reshape(-1, 4))
        start = self.edges[:, 0, :]
        direction = self.edges[:, 1, :] - start
        length_sq = np.einsum("ij,ij->i", direction, direction)
        rows = np.column_stack(
            [start, self.edges[:, 1, 1], direction, np.where(length_sq > 0, length_sq, 1.0)]
        )
        rows_list = rows.tolist()
        segments = tuple(
            tuple(
                (index, *rows_list[index])
                for index in np.flatnonzero(self.edge_owner == owner).tolist()
            )
            for owner in range(len(self.obstacles))
        )
        object.__setattr__(self, "_segments", segments)
        object.__setattr__(self, "_cells_by_radius", {})
        object.__setattr__(self, "_walk_grids", {})

    def inside_obstacle(self, point: FloatArray) -> bool:
        """Whether a point lies strictly inside any obstacle (even-odd rule, all at once)."""
        if len(self.edges) == 0:
            return False
        px, py = float(point[0]), float(point[1])
        start, end = self.edges[:, 0, :], self.edges[:, 1, :]
        straddles = (start[:, 1] > py) != (end[:, 1] > py)
        with np.errstate(divide="ignore", invalid="ignore"):
            crossing_x = start[:, 0] + (py - start[:, 1]) * (end[:, 0] - start[:, 0]) / (
                end[:, 1] - start[:, 1]
            )
        hits = self.edge_owner[straddles & (px < crossing_x)]
        return bool(np.any(np.bincount(hits, minlength=len(self.obstacles)) % 2))

    def boundary_distance(self, point: FloatArray) -> float:
        """Distance from a point to the nearest obstacle edge, in m (inf without obstacles)."""
        return float(distances_to_segments(point[None, :], self.edges)[0])

    def discs_clear(self, centers: FloatArray, radius: float) -> bool:
        """Whether discs at all of ``centers`` (P, 2) stay on the floor and off every obstacle
        edge (the check for a path sampled finer than the disc's radius).

        The arithmetic of :func:`~hazardhunt.world.geometry.distances_to_segments` on Python
        floats, for the edges of the obstacles whose bounding boxes come near the discs.
        """
        xs, ys = centers[:, 0], centers[:, 1]
        x_min, x_max, y_min, y_max = (
            float(xs.min()),
            float(xs.max()),
            float(ys.min()),
            float(ys.max()),
        )
        on_floor = (
            x_min >= radius
            and y_min >= radius
            and x_max <= self.width - radius
            and y_max <= self.height - radius
        )
        if not on_floor:
            return False
        # Obstacles whose bounding box stays farther than ``radius`` plus a margin far above
        # the rounding error cannot decide the answer: only the others are checked.
        reach = radius + 1e-9
        near = [
            (box, edges)
            for box, edges in zip(self.bounding_boxes, self._segments, strict=True)
            if box[0] - x_max < reach
            and x_min - box[2] < reach
            and box[1] - y_max < reach
            and y_min - box[3] < reach
        ]
        if not near:
            return True
        for x, y in centers.tolist():
            for (box_x_min, box_y_min, box_x_max, box_y_max), edges in near:
                dx = box_x_min - x if x < box_x_min else x - box_x_max if x > box_x_max else 0.0
                dy = box_y_min - y if y < box_y_min else y - box_y_max if y > box_y_max else 0.0
                if dx >= reach or dy >= reach:
                    continue
                if _disc_meets_edges(x, y, radius, edges):
                    return False
        return True

    def obstacle_clearance(self, point: FloatArray) -> float:
        """Distance from a point to the nearest obstacle boundary, negative inside one, in m."""
        distance = self.boundary_distance(point)
        return -distance if self.inside_obstacle(point) else distance

    def nearest_obstacle_point(self, point: FloatArray) -> FloatArray:
        """The point on any obstacle boundary nearest to ``point``.

        The arithmetic of :func:`~hazardhunt.world.geometry.nearest_points_on_segments` on
        Python floats, for the edges of the obstacles whose bounding boxes are near enough to
        hold the nearest point; among edges at the same distance the first one wins.
        """
        if len(self.edges) == 0:
            raise ValueError("the floor has no obstacles")
        x, y = float(point[0]), float(point[1])
        by_box = self._boxes_nearest_first(x, y)
        # Distances are compared with a margin far above their rounding error (in m, relative
        # to the coordinates); the edges within it of the nearest are compared exactly below.
        margin = 1e-9 * (1.0 + abs(x) + abs(y))
        best = math.inf
        candidates: list[tuple[int, float, float, float]] = []
        for box_distance_sq, owner in by_box:
            if box_distance_sq > (best + margin) ** 2:
                break
            for index, start_x, start_y, _, dx, dy, length_sq in self._segments[owner]:
                offset_x, offset_y = x - start_x, y - start_y
                t = (offset_x * dx + offset_y * dy) / length_sq
                t = min(max(t, 0.0), 1.0)
                nearest_x, nearest_y = start_x + t * dx, start_y + t * dy
                gap_x, gap_y = nearest_x - x, nearest_y - y
                distance = math.sqrt(gap_x * gap_x + gap_y * gap_y)
                if distance <= best + margin:
                    candidates.append((index, nearest_x, nearest_y, distance))
                    best = min(best, distance)
        nearest = [c for c in candidates if c[3] <= best + margin]
        if len(nearest) > 1:
            nearest.sort()
            gaps = np.array([(c[1] - x, c[2] - y) for c in nearest])
            nearest = [nearest[int(np.argmin(np.hypot(gaps[:, 0], gaps[:, 1])))]]
        return np.array(nearest[0][1:3])

    def _boxes_nearest_first(self, x: float, y: float) -> list[tuple[float, int]]:
        """The squared distance from (x, y) to each obstacle's bounding box, with the
        obstacle's index, nearest first and ties in the floor's order."""
        if len(self.bounding_boxes) <= _FEW_OBSTACLES:
            by_box = []
            for index, (x_min, y_min, x_max, y_max) in enumerate(self.bounding_boxes):
                dx = x_min - x if x < x_min else x - x_max if x > x_max else 0.0
                dy = y_min - y if y < y_min else y - y_max if y > y_max else 0.0
                by_box.append((dx * dx + dy * dy, index))
            by_box.sort()
            return by_box
        boxes = self._box_array
        dx_array = np.where(
            x < boxes[:, 0], boxes[:, 0] - x, np.where(x > boxes[:, 2], x - boxes[:, 2], 0.0)
        )
        dy_array = np.where(
            y < boxes[:, 1], boxes[:, 1] - y, np.where(y > boxes[:, 3], y - boxes[:, 3], 0.0)
        )
        distances_sq = dx_array * dx_array + dy_array * dy_array
        order = np.argsort(distances_sq, kind="stable")
        return list(zip(distances_sq[order].tolist(), order.tolist(), strict=True))

    def disc_blocked(self, center: FloatArray, radius: float) -> bool:
        """Whether a disc overlaps an obstacle or leaves the floor."""
        return self.disc_blocked_at(float(center[0]), float(center[1]), radius)

    def disc_blocked_at(self, x: float, y: float, radius: float) -> bool:
        """Whether a disc centred at (x, y) overlaps an obstacle or leaves the floor."""
        if not (radius <= x <= self.width - radius and radius <= y <= self.height - radius):
            return True
        limit = radius * radius
        cells = self._cells_by_radius.get(radius) or self._cells(radius)
        for (x_min, y_min, x_max, y_max), edges in cells.near(x, y):
            # A disc at least ``radius`` from an obstacle's bounding box is at least that far
            # from the obstacle and outside it: most queries end here.
            dx = x_min - x if x < x_min else x - x_max if x > x_max else 0.0
            if dx >= radius:
                continue
            dy = y_min - y if y < y_min else y - y_max if y > y_max else 0.0
            if dx * dx + dy * dy < limit and _disc_meets_polygon(x, y, radius, edges):
                return True
        return False

    def _cells(self, radius: float) -> _ObstacleCells:
        """The obstacles a disc of ``radius`` may touch, per cell of a grid over the floor
        (built at the first query for the radius, then kept)."""
        cells = _ObstacleCells(self.width, self.height, radius, self.bounding_boxes, self._segments)
        self._cells_by_radius[radius] = cells
        return cells

    def walk_grid(self, radius: float) -> WalkGrid:
        """The ways round the obstacles for a disc of ``radius`` (built at the first call for
        the radius, then kept)."""
        grid = self._walk_grids.get(radius)
        if grid is None:
            grid = self._walk_grids[radius] = WalkGrid(self, radius)
        return grid

    def on_floor(self, point: FloatArray, margin: float = 0.0) -> bool:
        """Whether a point lies on the floor at least ``margin`` from its outer edge."""
        x, y = float(point[0]), float(point[1])
        return margin <= x <= self.width - margin and margin <= y <= self.height - margin

    def in_blind_zone(self, point: FloatArray) -> bool:
        """Whether the cameras cannot see a point."""
        return any(point_in_polygon(point, zone) for zone in self.blind_zones)


_FEW_OBSTACLES = 64
"""Up to this many obstacles, a scalar query loops over them on Python floats; beyond (a floor
read from a site map), numpy's arrays are faster."""


class _ObstacleCells:
    """A grid of square cells over the floor, each listing the obstacles (bounding box and
    edges) that a disc of a given radius centred in the cell may touch; a disc query then
    looks at a few obstacles instead of all."""

    SIZE = 0.5
    """Side of a cell, in m."""

    def __init__(
        self,
        width: float,
        height: float,
        radius: float,
        boxes: tuple[tuple[float, float, float, float], ...],
        segments: tuple[tuple[tuple[int, float, float, float, float, float, float], ...], ...],
    ) -> None:
        size = self.SIZE
        self.columns = int(width / size) + 1
        rows = int(height / size) + 1
        cells: list[list[tuple[Any, Any]]] = [[] for _ in range(self.columns * rows)]
        # An obstacle is listed in every cell its bounding box, grown by the radius plus a
        # margin far above the rounding error of a cell's index, overlaps.
        reach = radius + 1e-6
        for box, edges in zip(boxes, segments, strict=True):
            x_min, y_min, x_max, y_max = box
            for row in range(max(int((y_min - reach) / size), 0), rows):
                if row * size > y_max + reach:
                    break
                for column in range(max(int((x_min - reach) / size), 0), self.columns):
                    if column * size > x_max + reach:
                        break
                    cells[row * self.columns + column].append((box, edges))
        self.cells = tuple(tuple(cell) for cell in cells)

    def near(
        self, x: float, y: float
    ) -> tuple[tuple[tuple[float, float, float, float], tuple[tuple[float, ...], ...]], ...]:
        """The obstacles a disc centred at (x, y), a point on the floor, may touch, in the
        floor's order."""
        size = self.SIZE
        return self.cells[int(y / size) * self.columns + int(x / size)]


def _disc_meets_edges(
    x: float, y: float, radius: float, edges: tuple[tuple[float, ...], ...]
) -> bool:
    """Whether a disc comes closer than ``radius`` to any of a polygon's edges (its
    ``FloorMap._segments``); the arithmetic of ``distances_to_segments``."""
    for _, start_x, start_y, _, dx, dy, length_sq in edges:
        ox, oy = x - start_x, y - start_y
        t = (ox * dx + oy * dy) / length_sq
        t = min(max(t, 0.0), 1.0)
        gx, gy = ox - t * dx, oy - t * dy
        if math.sqrt(gx * gx + gy * gy) < radius:
            return True
    return False


def _disc_meets_polygon(
    x: float, y: float, radius: float, edges: tuple[tuple[float, ...], ...]
) -> bool:
    """Whether a disc comes closer than ``radius`` to a polygon's boundary or has its centre
    strictly inside (even-odd rule); the arithmetic of ``distances_to_segments`` and
    ``inside_obstacle`` for one point and the polygon's ``FloorMap._segments``."""
    inside = False
    for _, start_x, start_y, end_y, dx, dy, length_sq in edges:
        ox, oy = x - start_x, y - start_y
        t = (ox * dx + oy * dy) / length_sq
        t = min(max(t, 0.0), 1.0)
        gx, gy = ox - t * dx, oy - t * dy
        if math.sqrt(gx * gx + gy * gy) < radius:
            return True
        if (start_y > y) != (end_y > y) and x < start_x + (y - start_y) * dx / dy:
            inside = not inside
    return inside
