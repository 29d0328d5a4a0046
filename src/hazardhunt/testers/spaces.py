"""Decision spaces: what the numbers of one decision mean, and how a whole episode of them plays.

An episode-level searcher proposes a whole episode before it is played, as ``horizon``
decisions of a few numbers in [-1, 1] each. A :class:`DecisionSpace` says how a decision becomes
the human's action:

- ``open``: the decision is the action itself, (speed, turn rate), played open loop;
- ``aim``: (speed, bearing around the robot, stand-off from its outline), aimed at the robot
  where it is when the decision is played (:func:`~hazardhunt.testers.aim.aimed_action`);
- ``route``: (speed, share of the robot's route, offset beside it), a walk to a point of the
  robot's route and a wait there (:func:`~hazardhunt.testers.aim.route_action`);
- ``ambush``: (speed, share of the route, offset beside it, lead, place on the robot's side),
  a wait beside the route and a run at the robot's side as it passes
  (:func:`~hazardhunt.testers.aim.ambush_action`).

``detour`` makes any of them keep the human clear of walls and shelves
(:func:`~hazardhunt.testers.clear_path.clear_action`), and makes the closed-loop ones walk round
an obstacle between the human and its target (:mod:`hazardhunt.world.navigation`) instead of
stopping at it. ``fit_offsets`` makes ``route`` and ``ambush`` pull a point beside the route
that lies in a wall or a shelf back towards the route, to where the human fits: beside a 3 m
aisle, an offset of up to 3 m then means "up to the aisle's edge".

A :class:`SearchSpace` is what a searcher is configured with: one kind, or ``mixed`` (every
kind in turn), the detour, the fitted offsets, and whether the search starts from the plain
attacks (:meth:`DecisionSpace.plain_attacks`). In a campaign file: ``space = "aim"`` or
``space = { kind = "ambush", detour = true, plain_attacks = true, fit_offsets = true }``.

Every space plays the actions it chooses, and the episode records those, so an episode replays
exactly without knowing its space.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, field_validator, model_validator

from hazardhunt.sim.simulation import EpisodeResult, Simulation
from hazardhunt.spec.episode import EpisodeSummary
from hazardhunt.testers.aim import aimed_action, ambush_action, route_action
from hazardhunt.testers.clear_path import clear_action, play_decisions

DecisionKind = Literal["open", "aim", "route", "ambush"]
"""How one decision's numbers are read."""

MIXED_KINDS: tuple[DecisionKind, ...] = ("open", "aim", "route")
"""The decision spaces' kinds ``mixed`` takes, in its order."""

DECISION_KINDS: tuple[DecisionKind, ...] = (*MIXED_KINDS, "ambush")
"""The decision spaces' kinds."""

SPACE_KINDS = (*DECISION_KINDS, "mixed")
"""The values of a searcher's space kind: one decision space, or all of them in turn."""

_SIZES: dict[str, int] = {"open": 2, "aim": 3, "route": 3, "ambush": 5}

_MIRRORED_NUMBER = {"open": 1, "aim": 1, "route": 2, "ambush": 2}
"""Per kind, the number of a decision whose sign mirrors it left for right: the turn rate, the
bearing around the robot, the offset beside its route (where the ambush waits)."""

_BOUNDARY_VALUES: dict[str, tuple[tuple[float, ...], ...]] = {
    "open": ((-1.0, 0.0, 1.0),),
    # The bearing wraps round (-1 and 1 are both behind the robot): its quarter turns instead.
    "aim": ((-0.5, 0.0, 0.5, 1.0), (-1.0, 0.0, 1.0)),
    "route": ((-1.0, 0.0, 1.0), (-1.0, 0.0, 1.0)),
    # On the route itself (offset 0) an ambush is the route's wait in the robot's way; the
    # plain ambushes run at the middle of the robot's side.
    "ambush": ((-1.0, 0.0, 1.0), (-1.0, 1.0), (-1.0, 0.0, 1.0), (0.0,)),
}
"""Per kind, the boundary values of each number of a decision after the speed."""


@dataclass(frozen=True)
class DecisionSpace:
    """One way of reading a decision's numbers as the human's action."""

    kind: DecisionKind = "open"
    """``open``, ``aim``, ``route`` or ``ambush`` (module docstring)."""
    detour: bool = False
    """Whether the human keeps clear of walls and shelves, and walks round them to a target."""
    fit_offsets: bool = False
    """Whether a point beside the robot's route (``route``, ``ambush``) that the human does not
    fit at is pulled back towards the route to the last place it fits
    (:func:`~hazardhunt.testers.aim.route_point`)."""

    @property
    def size(self) -> int:
        """Numbers per decision."""
        return _SIZES[self.kind]

    def action(
        self, simulation: Simulation, decision: NDArray[np.floating[Any]]
    ) -> NDArray[np.float32]:
        """The normalised (speed, turn rate) action ``decision`` stands for where the human and
        the robot are in ``simulation`` now."""
        if self.kind == "open":
            action = decision
        elif self.kind == "aim":
            action = aimed_action(simulation, decision, self.detour)
        elif self.kind == "route":
            action = route_action(simulation, decision, self.detour, self.fit_offsets)
        else:
            action = ambush_action(simulation, decision, self.detour, self.fit_offsets)
        if self.detour:
            return clear_action(simulation, action)
        return np.asarray(action, np.float32)

    def play(
        self,
        simulation: Simulation,
        decisions: Sequence[NDArray[np.floating[Any]]] | NDArray[np.floating[Any]],
        keep_trajectory: bool | Callable[[EpisodeSummary], bool] = True,
    ) -> EpisodeResult:
        """Play one episode from the scenario's start, each decision read in this space (an
        episode still going when they run out is returned as it stands, outcome None)."""
        if self.kind == "open" and not self.detour:
            return simulation.simulate(decisions, keep_trajectory)
        return play_decisions(simulation, decisions, self.action, keep_trajectory)

    def mirrored(self, decisions: NDArray[np.floating[Any]]) -> NDArray[np.float64]:
        """``decisions`` mirrored left for right: turning the other way, coming at the robot's
        other side, standing on the other side of its route."""
        mirrored = np.array(decisions, dtype=np.float64)
        mirrored[..., _MIRRORED_NUMBER[self.kind]] *= -1.0
        return mirrored

    def plain_attacks(self, horizon: int) -> NDArray[np.float64]:
        """The space's boundary values as whole episodes (boundary-value analysis): the human
        keeps one decision throughout, at its top speed, with every other number of the
        decision at -1, 0 or 1 (a bearing at its quarter turns); shape (plans, ``horizon``,
        :attr:`size`).

        In the closed-loop spaces these are the plain attacks a tester tries first: walk into
        the robot from ahead, behind or either side, or keep 1.5 or 3 m from it there (12 in
        ``aim``); wait on its route, or 3 m to either side of it, at the start, the middle or
        the goal of its mission, where a controller switches modes (9 in ``route``); wait 3 m
        to either side of the route there and run at the robot's side 3 m before it comes
        abreast, as it does or 3 m after (18 in ``ambush``); with :attr:`fit_offsets`, 3 m
        or the aisle's edge, whichever is nearer.
        """
        values = itertools.product(*_BOUNDARY_VALUES[self.kind])
        plans = np.array([(1.0, *numbers) for numbers in values])
        return np.repeat(plans[:, None, :], horizon, axis=1)


class SearchSpace(BaseModel):
    """Where a searcher searches: its decision space(s), the detour, and the plain attacks."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)

    kind: Literal["open", "aim", "route", "ambush", "mixed"] | tuple[DecisionKind, ...] = "open"
    """One decision space's kind, or several taking turns, the failures found in one counting
    as known in the others: ``mixed`` is ``open``, ``aim`` and ``route``, a list names its own
    (``["aim", "ambush"]``)."""
    detour: bool = False
    """Whether the human keeps clear of walls and shelves, and walks round them to a target."""
    plain_attacks: bool = False
    """Whether the search starts with each decision space's plain attacks
    (:meth:`DecisionSpace.plain_attacks`: 3, 12, 9 and 18 episodes)."""
    fit_offsets: bool = False
    """Whether a point beside the robot's route (``route``, ``ambush``) that lies in a wall or
    a shelf is pulled back towards the route, to the last place the human fits: in an aisle
    narrower than the offsets, its edge. Without it the human walks to the free place nearest
    the point, behind the shelf as often as not."""

    @model_validator(mode="before")
    @classmethod
    def _from_kind(cls, data: Any) -> Any:
        """A bare kind or list of kinds (``space = "aim"``, ``space = ["aim", "ambush"]``) is
        that with the other settings' defaults."""
        return {"kind": data} if isinstance(data, str | list | tuple) else data

    @field_validator("kind", mode="before")
    @classmethod
    def _known_kinds(cls, kind: Any) -> Any:
        """One kind of :data:`SPACE_KINDS`, or a list of distinct :data:`DECISION_KINDS`."""
        if isinstance(kind, list | tuple):
            unknown = [each for each in kind if each not in DECISION_KINDS]
            if unknown or not kind or len(set(kind)) != len(kind):
                raise ValueError(
                    f"a list of kinds names each of {', '.join(DECISION_KINDS)} at most once "
                    f"and one at least, not {list(kind)!r}"
                )
            return tuple(kind)
        if kind not in SPACE_KINDS:
            raise ValueError(
                f"must be one of {', '.join(SPACE_KINDS)} or a list of kinds, not {kind!r}"
            )
        return kind

    @property
    def decision_spaces(self) -> tuple[DecisionSpace, ...]:
        """The decision spaces searched, in the order they take turns."""
        if isinstance(self.kind, tuple):
            kinds = self.kind
        else:
            kinds = MIXED_KINDS if self.kind == "mixed" else (self.kind,)
        return tuple(DecisionSpace(kind, self.detour, self.fit_offsets) for kind in kinds)

    @property
    def largest_size(self) -> int:
        """The most numbers per decision of the spaces searched."""
        return max(space.size for space in self.decision_spaces)
