"""Exact planar geometry for discs, the robot's rectangle, half-discs and polygons.

All functions take and return SI units (m, rad). Clearances are signed: positive is the gap
between two shapes, zero is touching, negative is overlap.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def to_body_frame(point: FloatArray, x: float, y: float, heading: float) -> tuple[float, float]:
    """Express a world point in the frame of a body at (x, y) facing ``heading``.

    Returns:
        (forward, left): the point's coordinates along and across the heading, in m.
    """
    return point_in_body_frame(float(point[0]), float(point[1]), x, y, heading)


def point_in_body_frame(
    point_x: float, point_y: float, x: float, y: float, heading: float
) -> tuple[float, float]:
    """:func:`to_body_frame` for the world point (point_x, point_y)."""
    dx = point_x - x
    dy = point_y - y
    cos_h, sin_h = math.cos(heading), math.sin(heading)
    return cos_h * dx + sin_h * dy, -sin_h * dx + cos_h * dy


def rectangle_corners(
    x: float, y: float, heading: float, length: float, width: float
) -> FloatArray:
    """The four corners of a rectangle centred at (x, y), counter-clockwise from front-left."""
    cos_h, sin_h = math.cos(heading), math.sin(heading)
    half_l, half_w = length / 2, width / 2
    local = np.array([[half_l, half_w], [-half_l, half_w], [-half_l, -half_w], [half_l, -half_w]])
    rotation = np.array([[cos_h, -sin_h], [sin_h, cos_h]])
    return np.asarray(local @ rotation.T + np.array([x, y]), dtype=np.float64)


def point_rectangle_clearance(forward: float, left: float, length: float, width: float) -> float:
    """Signed distance from a point given in the rectangle's frame to the rectangle, in m."""
    over_x = abs(forward) - length / 2
    over_y = abs(left) - width / 2
    if over_x <= 0 and over_y <= 0:
        return max(over_x, over_y)
    return math.hypot(max(over_x, 0.0), max(over_y, 0.0))


def rectangle_face(forward: float, left: float, length: float, width: float) -> str:
    """The face of a rectangle nearest a point given in its frame.

    Returns:
        ``"front"``, ``"rear"``, ``"left"`` or ``"right"``. Near a corner, the face whose line
        the point lies further beyond wins; inside, the face the point is closest to.
    """
    over_x = abs(forward) - length / 2
    over_y = abs(left) - width / 2
    if over_x >= over_y:
        return "front" if forward >= 0 else "rear"
    return "left" if left >= 0 else "right"


def point_half_disc_distance(forward: float, left: float, radius: float) -> float:
    """Distance from a point to a half-disc whose straight edge lies on the line forward = 0.

    The half-disc is {(f, l): f >= 0, f^2 + l^2 <= radius^2}; the point is given in the same
    frame. Returns 0 for points inside.
    """
    if forward >= 0:
        return max(math.hypot(forward, left) - radius, 0.0)
    return math.hypot(forward, max(abs(left) - radius, 0.0))


def polygon_edges(polygons: list[FloatArray] | tuple[FloatArray, ...]) -> FloatArray:
    """All edges of the given closed polygons as an array of shape (E, 2, 2): start, end."""
    edges = [np.stack([polygon, np.roll(polygon, -1, axis=0)], axis=1) for polygon in polygons]
    if not edges:
        return np.zeros((0, 2, 2))
    return np.concatenate(edges, axis=0).astype(np.float64)


def nearest_points_on_segments(point: FloatArray, edges: FloatArray) -> FloatArray:
    """For each segment of ``edges`` (E, 2, 2), its point nearest to ``point``: shape (E, 2)."""
    start = edges[:, 0, :]
    direction = edges[:, 1, :] - start
    length_sq = np.einsum("ij,ij->i", direction, direction)
    t = np.einsum("ij,ij->i", point - start, direction) / np.where(length_sq > 0, length_sq, 1.0)
    t = np.clip(t, 0.0, 1.0)
    return np.asarray(start + t[:, None] * direction, dtype=np.float64)


def distances_to_segments(points: FloatArray, edges: FloatArray) -> FloatArray:
    """For each point of ``points`` (P, 2), its distance to the nearest segment of ``edges``
    (E, 2, 2): shape (P,), inf without segments."""
    if len(edges) == 0:
        return np.full(len(points), np.inf)
    start = edges[:, 0, :]
    direction = edges[:, 1, :] - start
    length_sq = np.einsum("ej,ej->e", direction, direction)
    offset = points[:, None, :] - start[None, :, :]
    t = np.einsum("pej,ej->pe", offset, direction) / np.where(length_sq > 0, length_sq, 1.0)
    gap = offset - np.clip(t, 0.0, 1.0)[..., None] * direction[None, :, :]
    return np.asarray(np.sqrt(np.min(np.einsum("pej,pej->pe", gap, gap), axis=1)), dtype=np.float64)


def point_in_polygon(point: FloatArray, polygon: FloatArray) -> bool:
    """Whether a point lies strictly inside a simple polygon (even-odd rule)."""
    px, py = float(point[0]), float(point[1])
    xs, ys = polygon[:, 0], polygon[:, 1]
    xs_next, ys_next = np.r_[xs[1:], xs[:1]], np.r_[ys[1:], ys[:1]]
    straddles = (ys > py) != (ys_next > py)
    with np.errstate(divide="ignore", invalid="ignore"):
        crossing_x = xs + (py - ys) * (xs_next - xs) / (ys_next - ys)
    return bool(np.count_nonzero(straddles & (px < crossing_x)) % 2)
