"""Walking around walls and shelves: where to head next on a shortest way across the floor.

A search space that names a point for the human to go to (beside the robot, on its route)
walks it there in a straight line. With a shelf block in between, the human ends up pressed
against the block, short of the point, for the rest of the episode. :class:`WalkGrid` finds the
way round instead: a grid of the cells where the human disc fits, with the shortest ways to a
target over it (Dijkstra, 8 neighbours). The human heads for the farthest point of that way it
can walk to in a straight line, so it cuts corners as a person would.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from scipy.sparse import csr_matrix

    from hazardhunt.world.floor import FloorMap

CELL = 0.25
"""Side of a grid cell, in m."""

MARGIN = 0.05
"""Clearance from obstacles a cell's centre keeps beyond the disc's radius, in m."""

LOOK_AHEAD = 6.0
"""How far along the way the next point to head for is searched, in m."""

TREES_KEPT = 32
"""Shortest-way trees kept per grid, for the targets used last."""


class WalkGrid:
    """The cells of a floor where a disc of ``radius`` fits, and the shortest ways between them."""

    def __init__(self, floor: FloorMap, radius: float) -> None:
        # SciPy loads here, at the first walk round an obstacle, not with every import of the
        # floor.
        from scipy.ndimage import distance_transform_edt

        self.floor = floor
        self.radius = radius
        self.columns = max(int(floor.width / CELL), 1)
        self.rows = max(int(floor.height / CELL), 1)
        xs = (np.arange(self.columns) + 0.5) * CELL
        ys = (np.arange(self.rows) + 0.5) * CELL
        self.centres = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
        free = np.array(
            [not floor.disc_blocked_at(x, y, radius + MARGIN) for x, y in self.centres.tolist()]
        ).reshape(self.rows, self.columns)
        self.free = free
        # The nearest free cell of every cell, for points that lie in none.
        _, (near_rows, near_columns) = distance_transform_edt(~free, return_indices=True)
        self._nearest_free = (near_rows * self.columns + near_columns).ravel()
        self._graph = _grid_graph(free)
        self._trees: OrderedDict[int, tuple[NDArray[np.int32], NDArray[np.float64]]] = OrderedDict()

    def cell_of(self, point: NDArray[np.floating[Any]]) -> int:
        """The free cell nearest to the cell that holds ``point`` (clamped to the floor)."""
        column = min(max(int(point[0] / CELL), 0), self.columns - 1)
        row = min(max(int(point[1] / CELL), 0), self.rows - 1)
        return int(self._nearest_free[row * self.columns + column])

    def line_clear(self, start: NDArray[np.floating[Any]], end: NDArray[np.floating[Any]]) -> bool:
        """Whether the disc can walk from ``start`` to ``end`` in a straight line (``start``
        itself is not checked: the disc may stand touching an obstacle)."""
        length = math.hypot(end[0] - start[0], end[1] - start[1])
        steps = max(math.ceil(length / (0.5 * self.radius)), 1) if self.radius > 0 else 1
        shares = np.arange(1, steps + 1)[:, None] / steps
        points = np.asarray(start, dtype=np.float64) + shares * (
            np.asarray(end, dtype=np.float64) - start
        )
        return self.floor.discs_clear(points, self.radius)

    def waypoint(
        self, start: NDArray[np.floating[Any]], target: NDArray[np.floating[Any]]
    ) -> tuple[NDArray[np.float64], float]:
        """The point to head for from ``start`` on the way to ``target``, and the length of that
        way, in m. ``target`` itself when the straight line is clear or when no way round
        exists (the human then walks as far as it gets)."""
        goal = np.asarray(target, dtype=np.float64)
        straight = math.hypot(goal[0] - start[0], goal[1] - start[1])
        if self.line_clear(start, goal):
            return goal, straight
        here, there = self.cell_of(start), self.cell_of(goal)
        predecessors, lengths = self._tree(there)
        if not math.isfinite(lengths[here]) or here == there:
            return goal, straight
        way = [here]
        while way[-1] != there and (len(way) - 1) * CELL < LOOK_AHEAD:
            way.append(int(predecessors[way[-1]]))
        # The farthest cell of the way within reach in a straight line, else the next one.
        chosen = way[1]
        for cell in reversed(way[1:]):
            if self.line_clear(start, self.centres[cell]):
                chosen = cell
                break
        point = self.centres[chosen]
        rest = float(lengths[chosen]) + math.hypot(*(goal - self.centres[there]))
        return point.copy(), math.hypot(point[0] - start[0], point[1] - start[1]) + rest

    def _tree(self, target: int) -> tuple[NDArray[np.int32], NDArray[np.float64]]:
        """The shortest ways from every cell to ``target``: predecessors and lengths."""
        if target in self._trees:
            self._trees.move_to_end(target)
            return self._trees[target]
        from scipy.sparse.csgraph import dijkstra

        lengths, predecessors = dijkstra(
            self._graph, directed=False, indices=target, return_predecessors=True
        )
        tree = (predecessors.astype(np.int32), lengths)
        self._trees[target] = tree
        if len(self._trees) > TREES_KEPT:
            self._trees.popitem(last=False)
        return tree


def _grid_graph(free: NDArray[np.bool_]) -> csr_matrix:
    """The edges between neighbouring free cells (diagonals only where both cells beside them
    are free, so that a way never cuts an obstacle's corner), weighted by length."""
    from scipy.sparse import coo_matrix

    rows, columns = free.shape
    index = np.arange(rows * columns).reshape(rows, columns)
    starts: list[NDArray[np.intp]] = []
    ends: list[NDArray[np.intp]] = []
    weights: list[NDArray[np.float64]] = []

    def link(
        where: NDArray[np.bool_], to: NDArray[np.intp], source: NDArray[np.intp], length: float
    ) -> None:
        starts.append(source[where])
        ends.append(to[where])
        weights.append(np.full(int(where.sum()), length))

    east = free[:, :-1] & free[:, 1:]
    link(east, index[:, 1:], index[:, :-1], CELL)
    north = free[:-1, :] & free[1:, :]
    link(north, index[1:, :], index[:-1, :], CELL)
    # A diagonal joins two corners of a block of four free cells.
    block = east[:-1, :] & east[1:, :]
    diagonal = CELL * math.sqrt(2.0)
    link(block, index[1:, 1:], index[:-1, :-1], diagonal)
    link(block, index[1:, :-1], index[:-1, 1:], diagonal)
    size = rows * columns
    return coo_matrix(
        (np.concatenate(weights), (np.concatenate(starts), np.concatenate(ends))),
        shape=(size, size),
    ).tocsr()


def reach(
    floor: FloorMap,
    radius: float,
    start: NDArray[np.floating[Any]],
    direction: NDArray[np.floating[Any]],
    length: float,
) -> float:
    """How far from ``start``, along the unit vector ``direction`` and at most ``length``, a
    disc of ``radius`` keeps ``MARGIN`` clear of every obstacle on ``floor``, as the cells of a
    :class:`WalkGrid` do: to the first place it would not, to a centimetre (0 when it does not
    at ``start``)."""
    origin = np.asarray(start, dtype=np.float64)
    heading = np.asarray(direction, dtype=np.float64)

    def blocked(distance: float) -> bool:
        x, y = origin + distance * heading
        return floor.disc_blocked_at(float(x), float(y), radius + MARGIN)

    step = 0.5 * CELL
    free = 0.0
    while free < length:
        ahead = min(free + step, length)
        if blocked(ahead):
            break
        free = ahead
    else:
        return float(length)
    if free == 0.0 and blocked(0.0):
        return 0.0
    ahead = min(free + step, length)
    while ahead - free > 0.01:
        middle = 0.5 * (free + ahead)
        free, ahead = (free, middle) if blocked(middle) else (middle, ahead)
    return free
