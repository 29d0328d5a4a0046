"""What fills the NMPC's stage parameters every call: the reference along the route, the
obstacle half-planes around the robot's guess (:class:`Obstacles`), the keep-out disc around
the predicted human, and the guesses a solve starts from (a rollout, the braking path)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from hazardhunt.sut.nmpc_problem import (
    KEEP_OUT_EXACT_WEIGHT,
    KEEP_OUT_HUMAN,
    KEEP_OUT_LINEAR_WEIGHT,
    KEEP_OUT_NORMAL,
    KEEP_OUT_RELIEF,
    KEEP_OUT_SIZE,
    REFERENCE_SIZE,
    SPEED,
    STAGE_SIZE,
    YAW_RATE,
    NMPCParams,
    Plan,
)
from hazardhunt.sut.protocols import RobotState
from hazardhunt.sut.route import Route
from hazardhunt.world.floor import FloorMap

FloatArray = NDArray[np.float64]

_DISABLED_OFFSET = -1.0
"""Right-hand side of an unused obstacle slot: with a zero normal the row reads slack >= -1."""
_BOX_MARGIN = 1e-6
"""Growth of the obstacles' bounding boxes in the inside test, in m: far more than the rounding
error of a ray's crossing with an edge."""


def rollout(robot: RobotState, horizon: int, sample_time: float, max_speed: float) -> Plan:
    """A guess without history: straight on at the current speed along the current heading."""
    speed = min(max(robot.speed, 0.0), max_speed)
    distance = speed * sample_time * np.arange(horizon + 1)
    stages = np.zeros((horizon + 1, STAGE_SIZE))
    stages[:, 0] = robot.x + distance * math.cos(robot.heading)
    stages[:, 1] = robot.y + distance * math.sin(robot.heading)
    stages[:, 2] = robot.heading
    stages[:, SPEED] = speed
    stages[0, SPEED] = robot.speed
    stages[0, YAW_RATE] = robot.yaw_rate
    return Plan(stages)


def braking_positions(robot: RobotState, params: NMPCParams, deceleration: float) -> FloatArray:
    """Positions over the horizon while braking straight ahead, shape (N+1, 2), in m."""
    elapsed = params.sample_time * np.arange(params.horizon + 1)
    speed = max(robot.speed, 0.0)
    stop_time = speed / deceleration
    moving = np.minimum(elapsed, stop_time)
    distance = speed * moving - 0.5 * deceleration * moving**2
    direction = np.array([math.cos(robot.heading), math.sin(robot.heading)])
    positions: FloatArray = np.array([robot.x, robot.y]) + distance[:, None] * direction
    return positions


def unwrap(angle: float, near: float) -> float:
    """``angle`` plus the multiple of 2 pi that brings it closest to ``near``, in rad."""
    return angle + 2.0 * math.pi * round((near - angle) / (2.0 * math.pi))


def keep_out_table(
    predicted_human: FloatArray | None, stages: FloatArray, params: NMPCParams
) -> FloatArray:
    """Keep-out parameters of stages 1..N, shape (N, 7): per stage the human position (m), the
    half-plane normal, the weights of the exact (squared-distance) and linearised rows, and the
    relief (1 when no human is visible, else 0).

    At a stage where the guess already puts the robot inside the keep-out disc, the disc is
    replaced by its tangent half-plane facing the robot. Inside, the squared distance is
    concave with no gradient at the human's centre; with a human walking straight at a standing
    robot, the solver stalled there on the symmetric choice of dodging left or right. The linear
    row is scaled by 2 r so that both rows have the same slope at the disc's edge and the slack
    the same units (m^2). Without a human both weights are 0 and the row reads slack + 1 >= 0:
    inactive, rather than a copy of the slack's own bound, which would leave two active
    constraints on one variable.
    """
    table = np.zeros((params.horizon, KEEP_OUT_SIZE))
    if predicted_human is None:
        table[:, KEEP_OUT_RELIEF] = 1.0
        return table
    away = stages[1:, :2] - predicted_human
    distance = np.hypot(away[:, 0], away[:, 1])
    if (distance > 1e-6).all():
        normal = away / distance[:, None]
    else:
        # Where the guess sits on the human, face the robot's current position instead, and
        # where that does too, the way the robot came from.
        fallback = stages[0, :2] - predicted_human
        fallback_distance = np.hypot(fallback[:, 0], fallback[:, 1])
        heading = stages[0, 2]
        backwards = np.array([-math.cos(heading), -math.sin(heading)])
        normal = np.where(
            (distance > 1e-6)[:, None],
            away / np.maximum(distance, 1e-6)[:, None],
            np.where(
                (fallback_distance > 1e-6)[:, None],
                fallback / np.maximum(fallback_distance, 1e-6)[:, None],
                backwards,
            ),
        )
    linear = distance < params.keep_out_radius
    table[:, KEEP_OUT_HUMAN] = predicted_human
    table[:, KEEP_OUT_NORMAL] = normal
    table[:, KEEP_OUT_EXACT_WEIGHT] = ~linear
    table[:, KEEP_OUT_LINEAR_WEIGHT] = linear * (2.0 * params.keep_out_radius)
    return table


def reference_table(route: Route, progress: float, params: NMPCParams) -> FloatArray:
    """Reference points, unit tangents and speeds of stages 1..N.

    The reference moves along the route from ``progress`` at the reference speed and brakes at
    the goal deceleration so that it stops at the route's end.

    Returns:
        Shape (N, 5): per stage the point (m), the route's unit tangent there and the speed
        (m/s).
    """
    cruise, deceleration = params.speed_reference, params.goal_deceleration
    length = route.length
    remaining = max(length - progress, 0.0)
    braking_distance = cruise * cruise / (2.0 * deceleration)
    if remaining >= braking_distance:
        stop_time = remaining / cruise + cruise / (2.0 * deceleration)
    else:
        stop_time = math.sqrt(2.0 * remaining / deceleration)
    braking_start = stop_time - cruise / deceleration
    half_deceleration, sample_time = 0.5 * deceleration, params.sample_time
    rows: list[float] = []
    for stage in range(1, params.horizon + 1):
        elapsed = sample_time * stage
        to_stop = stop_time - elapsed
        if to_stop < 0.0:
            to_stop = 0.0
        if elapsed <= braking_start:
            arc_length = length - (cruise * (braking_start - elapsed) + braking_distance)
        else:
            arc_length = length - half_deceleration * (to_stop * to_stop)
        speed = deceleration * to_stop
        rows += (*route.frame_at(arc_length), cruise if cruise <= speed else speed)
    return np.array(rows).reshape(-1, REFERENCE_SIZE)


class Obstacles:
    """The floor's obstacle polygons as flat edge arrays, for queries vectorised over the horizon.

    Every polygon is padded to the same number of edges K with zero-length edges at its first
    vertex: they never straddle a ray and their nearest point is a vertex, so they change neither
    the inside test nor the distance. Per-edge arrays stack x over y where both are needed, so
    that one numpy operation treats both coordinates.
    """

    def __init__(self, floor: FloorMap) -> None:
        polygons = [np.asarray(o.polygon, dtype=np.float64) for o in floor.obstacles]
        self.count = len(polygons)
        self.edges_per_obstacle = max((len(p) for p in polygons), default=0)
        padded_starts = np.zeros((self.count, self.edges_per_obstacle, 2))
        padded_ends = np.zeros((self.count, self.edges_per_obstacle, 2))
        for index, polygon in enumerate(polygons):
            size = len(polygon)
            padded_starts[index, :size] = polygon
            padded_ends[index, :size] = np.roll(polygon, -1, axis=0)
            padded_starts[index, size:] = padded_ends[index, size:] = polygon[0]
        starts, ends = padded_starts.reshape(-1, 2), padded_ends.reshape(-1, 2)
        self.start_x, self.start_y = starts[:, 0], starts[:, 1]
        self.end_y = ends[:, 1]
        self.delta_x, self.delta_y = (ends - starts).T
        self.starts = np.ascontiguousarray(starts.T)[:, None, :]
        """Shape (2, 1, E): the edges' start points, x row over y row, in m."""
        self.deltas = np.ascontiguousarray((ends - starts).T)[:, None, :]
        """Shape (2, 1, E): the edges' vectors from start to end, in m."""
        length_sq = self.delta_x**2 + self.delta_y**2
        degenerate = length_sq == 0.0
        self.inverse_length_sq = np.where(
            degenerate, 0.0, 1.0 / np.where(degenerate, 1.0, length_sq)
        )
        length = np.sqrt(length_sq)
        # Vertices run counter-clockwise: the outward normal is the edge direction turned right.
        safe_length = np.where(degenerate, 1.0, length)
        self.outward = np.stack(
            [
                np.where(degenerate, 0.0, self.delta_y / safe_length),
                np.where(degenerate, 0.0, -self.delta_x / safe_length),
            ]
        )
        """Shape (2, E): the edges' unit outward normals (zero for padding edges)."""
        self.slope = np.where(
            self.delta_y != 0.0,
            self.delta_x / np.where(self.delta_y != 0.0, self.delta_y, 1.0),
            0.0,
        )
        boxes = np.array(floor.bounding_boxes).reshape(-1, 4)
        low, high = boxes[:, :2], boxes[:, 2:]
        self.box_low = (low.T - _BOX_MARGIN)[:, None, :]
        """Shape (2, 1, C): each obstacle's bounding box's lower x and y less a margin, in m."""
        self.box_high = (high.T + _BOX_MARGIN)[:, None, :]
        """Shape (2, 1, C): each obstacle's bounding box's upper x and y plus a margin, in m."""
        self._first_edges: dict[int, tuple[NDArray[np.intp], NDArray[np.intp]]] = {}

    def _offsets(self, count: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """Index offsets for ``count`` points: of each obstacle's first edge in the flattened
        (points, edges) arrays, shape (count, obstacles), and of each point's row in the
        flattened (points, obstacles) arrays, shape (count, 1)."""
        offsets = self._first_edges.get(count)
        if offsets is None:
            edges = self.count * self.edges_per_obstacle
            first_edge = np.arange(count)[:, None] * edges + self.edges_per_obstacle * np.arange(
                self.count
            )
            offsets = first_edge, np.arange(count)[:, None] * self.count
            self._first_edges[count] = offsets
        return offsets

    def half_planes(
        self, points: FloatArray, inflation: float, slots: int
    ) -> tuple[FloatArray, FloatArray]:
        """Half-planes that keep each point ``inflation`` m off its ``slots`` nearest obstacles.

        For a point p and an obstacle, with q the obstacle's boundary point nearest to p and n the
        unit normal at q pointing away from the obstacle (towards p when p lies outside), the
        half-plane is ``n . p >= n . q + inflation``. For a convex obstacle it contains no point
        of the inflated obstacle. Unused slots get a zero normal and a negative offset.

        Args:
            points: Shape (N, 2): the predicted positions, in m.
            inflation: Clearance to keep, in m.
            slots: Number M of obstacles per point.

        Returns:
            Normals (N, M, 2) and offsets (N, M), in m.
        """
        count = len(points)
        used = min(slots, self.count)
        if used == 0:
            return np.zeros((count, slots, 2)), np.full((count, slots), _DISABLED_OFFSET)
        point = points.T[:, :, None]  # (2, N, 1)
        px, py = point[0], point[1]
        # Nearest point of every edge: (2, N, E) arrays hold the x and y parts.
        to = point - self.starts
        products = to * self.deltas
        along = products[0] + products[1]
        along *= self.inverse_length_sq
        np.minimum(np.maximum(along, 0.0, out=along), 1.0, out=along)
        gap = to - along * self.deltas
        squares = gap * gap
        distance_sq = squares[0] + squares[1]
        first_edge, first_obstacle = self._offsets(count)
        # Per point and obstacle its nearest edge, as an index into the flattened (N, E) arrays.
        nearest = distance_sq.reshape(count, self.count, -1).argmin(axis=2) + first_edge
        distance = np.sqrt(distance_sq.take(nearest))
        chosen = np.argsort(distance, axis=1)[:, :slots] + first_obstacle
        edge = nearest.take(chosen)
        distance = distance.take(chosen)
        gap = gap.reshape(2, -1).take(edge, axis=1)
        # Even-odd rule on a ray towards +x: inside points get the normal flipped outwards. A
        # point outside an obstacle's (slightly grown) bounding box crosses its boundary an even
        # number of times, so the rule only runs when some point lies within a box.
        sign: FloatArray | float = 1.0
        in_box = (point > self.box_low) & (point < self.box_high)
        if (in_box[0] & in_box[1]).any():
            straddles = (self.start_y > py) != (self.end_y > py)
            hits = straddles & (px < self.start_x + to[1] * self.slope)
            crossings = hits.reshape(count, self.count, -1).sum(axis=2)
            sign = np.where(crossings.take(chosen) % 2 == 1, -1.0, 1.0)
        apart = distance > 1e-9
        if apart.all():
            normal = gap * (sign / distance)  # (2, N, used)
        else:
            # On the boundary the gap has no direction: take the edge's outward normal.
            scale = np.where(apart, sign / np.where(apart, distance, 1.0), 0.0)
            outward = self.outward.take(edge % self.outward.shape[1], axis=1)
            normal = np.where(apart, gap * scale, outward)
        along_normal = normal * (point - gap)  # the nearest points' parts along the normals
        offsets = along_normal[0] + along_normal[1] + inflation
        normals = normal.transpose(1, 2, 0)
        if used < slots:
            normals = np.concatenate([normals, np.zeros((count, slots - used, 2))], axis=1)
            disabled = np.full((count, slots - used), _DISABLED_OFFSET)
            offsets = np.concatenate([offsets, disabled], axis=1)
        return normals, offsets
