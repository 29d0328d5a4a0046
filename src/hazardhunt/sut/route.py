"""The robot's reference route: a shortest collision-free polyline through its waypoints.

Planned once per scenario over the static map on a visibility graph of the obstacles inflated
by the robot's half width plus a margin (SPEC 3).
"""

from __future__ import annotations

import itertools
import math
from bisect import bisect_right
from dataclasses import dataclass, field

import networkx as nx
import numpy as np
import shapely
from shapely.geometry import Polygon

from hazardhunt.errors import InputError
from hazardhunt.world.floor import FloorMap
from hazardhunt.world.geometry import FloatArray
from hazardhunt.world.scenario import Scenario


class RoutePlanningError(InputError):
    """No collision-free route exists between two route points."""

    def __init__(self, message: str, stops: tuple[int, ...] = ()) -> None:
        super().__init__(message)
        self.stops = stops
        """The route points at fault, as indices into start, waypoints, goal."""


@dataclass(frozen=True)
class Route:
    """A polyline the robot follows, parameterised by arc length s (m)."""

    points: FloatArray
    """Shape (M, 2), M >= 2: the vertices, start first, goal last, in m."""
    cumulative: FloatArray = field(init=False, repr=False, compare=False)
    """Shape (M,): arc length at each vertex, in m."""
    _arc_lengths: list[float] = field(init=False, repr=False, compare=False)
    """``cumulative`` as Python floats, for scalar queries."""
    _frames: tuple[tuple[float, float, float, float], ...] = field(
        init=False, repr=False, compare=False
    )
    """Per segment its start point and unit direction (x, y, tangent x, tangent y)."""

    def __post_init__(self) -> None:
        points = np.asarray(self.points, dtype=np.float64)
        if points.ndim != 2 or points.shape[0] < 2 or points.shape[1] != 2:
            raise ValueError("a route needs at least two points (x, y)")
        segment_lengths = np.hypot(*np.diff(points, axis=0).T)
        cumulative = np.concatenate([[0.0], np.cumsum(segment_lengths)])
        frames = []
        for (start_x, start_y), (end_x, end_y) in itertools.pairwise(points.tolist()):
            dx, dy = end_x - start_x, end_y - start_y
            norm = max(float(np.hypot(dx, dy)), 1e-12)
            frames.append((start_x, start_y, dx / norm, dy / norm))
        object.__setattr__(self, "points", points)
        object.__setattr__(self, "cumulative", cumulative)
        object.__setattr__(self, "_arc_lengths", cumulative.tolist())
        object.__setattr__(self, "_frames", tuple(frames))

    @property
    def length(self) -> float:
        """Total length, in m."""
        return float(self.cumulative[-1])

    @property
    def goal(self) -> FloatArray:
        """The last point."""
        return np.asarray(self.points[-1], dtype=np.float64)

    def frame_at(self, s: float) -> tuple[float, float, float, float]:
        """The point at arc length s and the unit direction of its segment, as (x, y, tangent
        x, tangent y); beyond either end, the end segment extended."""
        index = bisect_right(self._arc_lengths, s) - 1
        index = min(max(index, 0), len(self._frames) - 1)
        start_x, start_y, tangent_x, tangent_y = self._frames[index]
        along = s - self._arc_lengths[index]
        return start_x + along * tangent_x, start_y + along * tangent_y, tangent_x, tangent_y

    def point_at(self, s: float) -> FloatArray:
        """The point at arc length s; beyond either end, the end segment extended."""
        x, y, _, _ = self.frame_at(s)
        return np.array([x, y])

    def tangent_at(self, s: float) -> FloatArray:
        """Unit direction of the segment at arc length s."""
        _, _, tangent_x, tangent_y = self.frame_at(s)
        return np.array([tangent_x, tangent_y])

    def project(self, point: FloatArray, s_min: float = 0.0, s_max: float = math.inf) -> float:
        """Arc length of the route point nearest to ``point``, searched within [s_min, s_max]."""
        best_s, best_distance = s_min, math.inf
        cumulative = self._arc_lengths
        x, y = float(point[0]), float(point[1])
        for index in range(len(self._frames)):
            start_s, end_s = cumulative[index], cumulative[index + 1]
            if end_s < s_min or start_s > s_max:
                continue
            start = self.points[index]
            direction = self.points[index + 1] - start
            length = end_s - start_s
            t = float(np.dot(point - start, direction)) / max(length * length, 1e-12)
            s = min(max(start_s + t * length, max(start_s, s_min)), min(end_s, s_max))
            nearest_x, nearest_y, _, _ = self.frame_at(s)
            distance = float(np.hypot(nearest_x - x, nearest_y - y))
            if distance < best_distance:
                best_s, best_distance = s, distance
        return best_s


ROUTE_TOLERANCE = 0.01
"""An inflated obstacle with detail finer than this, in m, is planned around as a simpler
polygon that contains it and lies within twice this of it: a dense outline (a round column of
thousands of vertices, a traced wall) then costs no more than a coarse one."""


def inflated_obstacles(floor: FloorMap, inflation: float) -> list[Polygon]:
    """The floor's obstacles grown by ``inflation`` m, with square corners; an outline with
    detail finer than :data:`ROUTE_TOLERANCE` is simplified first and grown by that much more,
    so that it still holds everything within ``inflation`` of the obstacle.

    A floor read from a site map has its blocked cells merged into one outline per connected
    group first: the corners where two rectangles of cells meet are no corners to plan around."""
    outlines = [Polygon(obstacle.polygon) for obstacle in floor.obstacles]
    if floor.occupancy is not None and outlines:
        merged = shapely.union_all(outlines)
        outlines = list(getattr(merged, "geoms", [merged]))
    blocked = []
    for outline in outlines:
        simplified = outline.simplify(ROUTE_TOLERANCE)
        if simplified.equals(outline):
            blocked.append(outline.buffer(inflation, join_style="mitre"))
        else:
            # Every point of the outline lies within the tolerance of the simplified one.
            grown = simplified.buffer(inflation + ROUTE_TOLERANCE, join_style="mitre")
            blocked.append(grown)
    return blocked


def plan_route(
    floor: FloorMap,
    start: FloatArray,
    waypoints: FloatArray,
    goal: FloatArray,
    inflation: float,
) -> Route:
    """Shortest polyline from ``start`` through ``waypoints`` to ``goal`` that keeps ``inflation``
    metres from every obstacle.

    Raises:
        RoutePlanningError: When a route point lies inside an inflated obstacle or two
            consecutive route points cannot be connected; its ``stops`` say which (indices
            into start, waypoints, goal).
    """
    blocked = inflated_obstacles(floor, inflation)
    # Shrink by a hair so that paths along an inflated boundary or through its corners count
    # as free; the visibility-graph nodes sit a hair outside each corner for the same reason.
    solid = shapely.union_all([p.buffer(-1e-6, join_style="mitre") for p in blocked])
    shapely.prepare(solid)
    corners = [
        corner
        for polygon in blocked
        for corner in _convex_corners(polygon.buffer(1e-4, join_style="mitre"))
        if floor.on_floor(corner) and not solid.contains(shapely.Point(corner))
    ]
    stops = [np.asarray(p, dtype=np.float64) for p in [start, *waypoints, goal]]
    for index, stop in enumerate(stops):
        if solid.contains(shapely.Point(stop)):
            raise RoutePlanningError(
                f"route point ({stop[0]:.2f}, {stop[1]:.2f}) lies within {inflation:.2f} m of an "
                "obstacle",
                (index,),
            )
    route = [stops[0]]
    for index, (origin, target) in enumerate(itertools.pairwise(stops)):
        try:
            route.extend(_shortest_leg(origin, target, corners, solid)[1:])
        except RoutePlanningError as error:
            raise RoutePlanningError(str(error), (index, index + 1)) from error
    deduplicated = [route[0]] + [
        p for previous, p in itertools.pairwise(route) if np.hypot(*(p - previous)) > 1e-9
    ]
    return Route(np.array(deduplicated))


def _convex_corners(polygon: Polygon) -> list[FloatArray]:
    """The vertices of ``polygon``'s outline where it turns outwards: the only places a
    shortest path around it bends (on a hole's outline, where the polygon reaches into it)."""
    corners = []
    for ring, outwards in [(polygon.exterior, 1.0), *((hole, -1.0) for hole in polygon.interiors)]:
        points = np.asarray(ring.coords)[:-1]
        incoming = points - np.roll(points, 1, axis=0)
        outgoing = np.roll(points, -1, axis=0) - points
        turn = incoming[:, 0] * outgoing[:, 1] - incoming[:, 1] * outgoing[:, 0]
        if not ring.is_ccw:
            turn = -turn
        corners.extend(points[outwards * turn > 0])
    return corners


def _shortest_leg(
    origin: FloatArray, target: FloatArray, corners: list[FloatArray], solid: shapely.Geometry
) -> list[FloatArray]:
    nodes = np.array([origin, target, *corners])
    graph = nx.Graph()
    graph.add_nodes_from(range(len(nodes)))
    for i in range(len(nodes) - 1):
        others = np.arange(i + 1, len(nodes))
        segments = shapely.linestrings(
            np.stack([np.broadcast_to(nodes[i], (len(others), 2)), nodes[others]], axis=1)
        )
        visible = others[~shapely.intersects(solid, segments)]
        lengths = np.hypot(*(nodes[visible] - nodes[i]).T)
        graph.add_weighted_edges_from(
            (i, int(j), float(length)) for j, length in zip(visible, lengths, strict=True)
        )
    try:
        path = nx.shortest_path(graph, 0, 1, weight="weight")
    except nx.NetworkXNoPath as error:
        raise RoutePlanningError(
            f"no collision-free path from ({origin[0]:.2f}, {origin[1]:.2f}) to "
            f"({target[0]:.2f}, {target[1]:.2f})"
        ) from error
    return [nodes[i] for i in path]


ROUTE_MARGIN = 0.25
"""Clearance the reference route keeps from obstacles beyond the robot's half width, in m."""


def scenario_route(scenario: Scenario, robot_width: float) -> Route:
    """The route a robot ``robot_width`` wide drives in ``scenario``: from its start through its
    waypoints to its goal, ``ROUTE_MARGIN`` clear of the obstacles beyond its half width.

    Raises:
        RoutePlanningError: The robot cannot get there (see :func:`plan_route`).
    """
    return plan_route(
        scenario.floor,
        scenario.robot_start.position,
        scenario.waypoints,
        scenario.goal,
        robot_width / 2 + ROUTE_MARGIN,
    )
