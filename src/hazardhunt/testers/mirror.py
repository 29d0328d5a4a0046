"""The mirror: a failure found on one side of the robot, tried on its other side.

A robot that fails for a human on its left often fails the same way on its right, and a search
that found one seldom looks for the other. The mirror plays, for a failure any sampler found,
the same episode mirrored left for right, one episode per side checked; it is an arm of the
default portfolio (:mod:`hazardhunt.testers.portfolio`).
"""

from __future__ import annotations

import math
from typing import Any

from pydantic import Field

from hazardhunt.sim.simulation import EpisodeResult
from hazardhunt.spec.descriptors import EMERGENCY_STOP_CODES
from hazardhunt.spec.episode import EpisodeSummary
from hazardhunt.spec.failure_classes import MechanismClassifier
from hazardhunt.testers.evaluator import Plan
from hazardhunt.testers.search import SearchContext, SearchParams

BEARING_CELLS = 8
"""Sectors around the robot in a descriptor cell."""


def failure_cell(summary: EpisodeSummary, moving_speed: float) -> tuple[int, int, int]:
    """The descriptor cell of a failure: the sector of the robot it met the human in (of
    :data:`BEARING_CELLS`), the safety layer's history, and whether the human was moving."""
    sector = math.floor((summary.closest_bearing + math.pi) / math.tau * BEARING_CELLS)
    return (
        sector % BEARING_CELLS,
        int(EMERGENCY_STOP_CODES[summary.closest_emergency_stop]),
        int(summary.closest_human_speed > moving_speed),
    )


def mirrored_cell(cell: tuple[int, int, int]) -> tuple[int, int, int]:
    """The cell on the robot's other side (the bearing's sign flipped)."""
    sector, stop, moving = cell
    return (BEARING_CELLS - 1 - sector, stop, moving)


class MirrorParams(SearchParams):
    """The mirror's settings."""

    attempts: int = Field(default=2, ge=1, le=100)
    """Failures per descriptor cell whose mirror image is played."""


class MirrorSampler:
    """Plays, for a failure any arm found, the same episode mirrored left for right
    (:meth:`~hazardhunt.testers.spaces.DecisionSpace.mirrored`) while no failure has been seen
    in the cell on the robot's other side: a robot that fails for a human on its left is
    checked on its right at the cost of one episode. It proposes nothing until some arm finds
    a failure."""

    def __init__(self, params: MirrorParams, context: SearchContext) -> None:
        self.params = params
        self.objective = context.objective
        robot = context.simulation.robot_params
        self.moving_speed = MechanismClassifier(robot=robot).moving_speed
        self.filled: set[tuple[int, int, int]] = set()
        self.attempts: dict[tuple[int, int, int], int] = {}
        self.queue: list[tuple[tuple[int, int, int], Plan]] = []

    def observe(self, plans: list[Plan], results: list[EpisodeResult]) -> None:
        """Hear what another arm played."""
        for plan, result in zip(plans, results, strict=False):
            if not self.objective.hit(result):
                continue
            cell = failure_cell(result.summary, self.moving_speed)
            self.filled.add(cell)
            target = mirrored_cell(cell)
            if target in self.filled or self.attempts.get(target, 0) >= self.params.attempts:
                continue
            self.attempts[target] = self.attempts.get(target, 0) + 1
            mirrored = plan.space.mirrored(plan.decisions)
            self.queue.append((target, Plan(plan.space, mirrored)))

    def ask(self) -> list[Plan]:
        waiting = [(cell, plan) for cell, plan in self.queue if cell not in self.filled]
        self.queue = []
        return [plan for _, plan in waiting]

    def tell(self, plans: list[Plan], results: list[EpisodeResult]) -> None:
        self.observe(plans, results)

    def record(self) -> dict[str, Any]:
        return {"cells_seen": len(self.filled)}
