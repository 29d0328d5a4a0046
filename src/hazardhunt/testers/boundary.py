"""The boundary: from a failure, bisection towards a nearby episode that did not fail.

Where a failure region ends, its mechanism often changes before the failures stop: a human who
walks into the robot's unguarded side just where the field would see them is a different
failure (seen too late, hit while the robot brakes) from one the field never saw, and both lie
next to the episodes in which the field stopped the robot in time. Such a mechanism fills a
thin band that random draws and a search pulled towards the bulk of the failures rarely land
in: with the built-in NMPC behind the 1.25 m field, a human cutting in over the field's edge
(``edge-entry/moving``) came up once in a thousand episodes of a search aimed at the robot,
and 6 times in 275 episodes on bisection lines from the failures of a run
(docs/search-methods.md, "Following failures to their border").

The boundary sampler plays, for a failure any sampler found, the episode's own actions
perturbed a little until one perturbation does not fail, then bisects between the two: each
midpoint that fails becomes the new failure end, each that does not the new far end, so that
the episodes close in on the border from both sides. A line starts from a failure of the
descriptor cell with the fewest lines so far (the sector of the robot it met the human in, the
safety layer's history, the human moving or standing:
:func:`~hazardhunt.testers.mirror.failure_cell`; no taxonomy is needed): one the other
samplers found, or one of its own that was the first in its cell (the rest lie on lines
already followed). It works on the actions the episodes played, read in the open decision
space, so it bisects between episodes of any sampler. It is an arm of the default portfolio
(:mod:`hazardhunt.testers.portfolio`) and proposes nothing until some arm finds a failure.

With ``cell_border``, a line closes in on the border of its failure's cell instead: an
episode counts as on the failure's side only if it fails in the cell the line started in, so
that a failure of another cell ends the search for a far end as an episode that does not fail
does, and bisection lands on the border between two mechanisms as well as on the border of the
failures. Such a far end that fails is itself a failure of a cell the line had not started
from, and starts lines of its own if it is the first in its cell. It finds more failures near
the borders between mechanisms and, on the systems it was not chosen on, not more classes
(docs/search-methods.md, "Bisecting to a cell's border, paying for repeats"): off by default.

With ``saved_ends``, every second line skips the perturbations: its far end is the episode
nearest its failure (in the actions played) in which the safety layer stopped the robot and
nothing failed, one any sampler played. Between a failure the safety layer never saw and an
episode it saved lies the band where it saw the human too late; a system under test without a
safety layer that stops the robot has no such episode, and every line perturbs as before.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pydantic import Field

from hazardhunt.sim.simulation import EpisodeResult
from hazardhunt.spec.failure_classes import MechanismClassifier
from hazardhunt.testers.evaluator import Plan
from hazardhunt.testers.mirror import failure_cell
from hazardhunt.testers.search import SearchContext, SearchParams
from hazardhunt.testers.spaces import DecisionSpace

Cell = tuple[int, int, int]

OPEN = DecisionSpace("open")
"""The actions as played: every episode replays in it exactly."""


class BoundaryParams(SearchParams):
    """The boundary sampler's settings."""

    batch_size: int = Field(default=4, ge=1, le=1000)
    """Bisection lines followed at once (one episode each per batch)."""
    spread: float = Field(default=0.1, gt=0.0, le=2.0, allow_inf_nan=False)
    """Standard deviation of the perturbation that looks for a nearby episode that does not
    fail (actions are in [-1, 1])."""
    tries: int = Field(default=10, ge=1, le=1000)
    """Perturbations a line tries before it gives up on its failure."""
    steps: int = Field(default=8, ge=1, le=50)
    """Bisection steps per line."""
    cell_border: bool = False
    """A line closes in on the border of its failure's descriptor cell rather than of the
    failures: an episode counts as inside only if it fails in the cell the line started in, so
    that its far end may be a failure of another mechanism."""
    saved_ends: bool = False
    """Every second line bisects towards the nearest episode the safety layer saved (an
    emergency stop, no failure) instead of a perturbation of its failure, once there is one."""


@dataclass
class _Line:
    """One bisection line: from a failure (``inside``) towards an episode that did not fail
    (``outside``, None while it is being looked for)."""

    cell: Cell
    inside: NDArray[np.float64]
    outside: NDArray[np.float64] | None = None
    tries: int = 0
    steps: int = 0
    pending: NDArray[np.float64] | None = None
    """The actions of the episode asked for and not yet told."""


class BoundarySampler:
    """Bisects between the failures any arm found and nearby episodes that do not fail
    (module docstring)."""

    def __init__(self, params: BoundaryParams, context: SearchContext) -> None:
        self.params = params
        self.objective = context.objective
        self.horizon = context.horizon
        robot = context.simulation.robot_params
        self.moving_speed = MechanismClassifier(robot=robot).moving_speed
        self.rng = np.random.default_rng(context.seed)
        self.failures: dict[Cell, list[NDArray[np.float64]]] = {}
        """The failures heard of, by cell, as actions padded to the horizon."""
        self.lines_started: dict[Cell, int] = {}
        self.lines: list[_Line] = []
        self.lines_done = 0
        self.lines_begun = 0
        self.saved: list[NDArray[np.float64]] = []
        """With ``saved_ends``: the episodes heard of that the safety layer saved, padded."""

    def observe(self, plans: list[Plan], results: list[EpisodeResult]) -> None:
        """Hear what another arm played."""
        self._remember(results, own=False)

    def _remember(self, results: list[EpisodeResult], own: bool) -> None:
        """Keep the failures as starts of lines: all the others found, and of its own only
        those that were the first in their cell (the rest lie on lines already followed); with
        ``saved_ends``, every episode the safety layer saved as a far end."""
        for result in results:
            if not len(result.actions):
                continue
            if not self.objective.hit(result):
                if self.params.saved_ends and result.summary.emergency_stops > 0:
                    self.saved.append(self._padded(result.actions))
                continue
            cell = failure_cell(result.summary, self.moving_speed)
            if own and cell in self.failures:
                continue
            self.failures.setdefault(cell, []).append(self._padded(result.actions))

    def ask(self) -> list[Plan]:
        while len(self.lines) < self.params.batch_size and self.failures:
            cell = min(self.failures, key=lambda c: self.lines_started.get(c, 0))
            found = self.failures[cell]
            start = found[int(self.rng.integers(len(found)))]
            self.lines_started[cell] = self.lines_started.get(cell, 0) + 1
            self.lines_begun += 1
            self.lines.append(_Line(cell, start, outside=self._saved_end(start)))
        for line in self.lines:
            line.pending = self._next(line)
        return [Plan(OPEN, line.pending) for line in self.lines if line.pending is not None]

    def tell(self, plans: list[Plan], results: list[EpisodeResult]) -> None:
        asked = [line for line in self.lines if line.pending is not None]
        for line, result in zip(asked, results, strict=False):
            played = line.pending
            assert played is not None
            line.pending = None
            inside = self._inside(line, result)
            if line.outside is None:
                line.tries += 1
                if not inside:
                    line.outside = played
            elif inside:
                line.inside, line.steps = played, line.steps + 1
            else:
                line.outside, line.steps = played, line.steps + 1
        for line in asked[len(results) :]:
            line.pending = None
        kept = [line for line in self.lines if not self._finished(line)]
        self.lines_done += len(self.lines) - len(kept)
        self.lines = kept
        self._remember(results, own=True)

    def record(self) -> dict[str, Any]:
        return {"lines_done": self.lines_done, "cells_seen": len(self.failures)}

    def _next(self, line: _Line) -> NDArray[np.float64]:
        """The actions of a line's next episode: a perturbation of its failure while it looks
        for a far end, the midpoint of its two ends after."""
        if line.outside is None:
            noise = self.rng.normal(0.0, self.params.spread, line.inside.shape)
            return np.clip(line.inside + noise, -1.0, 1.0)
        return 0.5 * (line.inside + line.outside)

    def _saved_end(self, start: NDArray[np.float64]) -> NDArray[np.float64] | None:
        """The far end of a line begun at ``start``: for every second line with
        ``saved_ends``, the saved episode nearest it; None (look for one) otherwise."""
        if not self.saved or self.lines_begun % 2:
            return None
        distances = [float(np.sum((saved - start) ** 2)) for saved in self.saved]
        return self.saved[int(np.argmin(distances))]

    def _inside(self, line: _Line, result: EpisodeResult) -> bool:
        """Whether an episode of ``line`` lies on its failure's side of the border."""
        if not self.objective.hit(result):
            return False
        if not self.params.cell_border:
            return True
        return failure_cell(result.summary, self.moving_speed) == line.cell

    def _finished(self, line: _Line) -> bool:
        if line.outside is None:
            return line.tries >= self.params.tries
        return line.steps >= self.params.steps

    def _padded(self, actions: NDArray[np.floating[Any]]) -> NDArray[np.float64]:
        """A failure's actions, its last one held to the end of the horizon (the failure
        replays as it was; an episode near it that does not end there goes on walking)."""
        played = np.asarray(actions, dtype=np.float64).reshape(-1, 2)
        if len(played) >= self.horizon:
            return played[: self.horizon].copy()
        rest = np.repeat(played[-1:], self.horizon - len(played), axis=0)
        return np.concatenate([played, rest])
