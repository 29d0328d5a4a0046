"""The search spaces of the episode-level testers: what the numbers of one decision mean.

An episode-level searcher proposes a whole episode before it is played, as ``horizon``
decisions of a few numbers in [-1, 1] each. How a decision becomes the human's action is the
search space:

- ``open``: the decision is the action itself, (speed, turn rate), played open loop;
- ``aim``: (speed, bearing around the robot, stand-off from its outline), aimed at the robot
  where it is when the decision is played (:func:`~hazardhunt.testers.aim.aimed_action`);
- ``route``: (speed, share of the robot's route, offset beside it), a walk to a point of the
  robot's route and a wait there (:func:`~hazardhunt.testers.aim.route_action`).

Every space plays the actions it chooses, and the episode records those, so an episode
replays exactly without knowing its space. ``clear_path`` makes any of them keep the human
clear of walls and shelves (:func:`~hazardhunt.testers.clear_path.clear_action`), and makes
the closed-loop ones walk round an obstacle between the human and its target
(:mod:`hazardhunt.world.navigation`) instead of stopping at it.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from hazardhunt.sim.simulation import EpisodeResult, Simulation
from hazardhunt.spec.episode import EpisodeSummary
from hazardhunt.testers.aim import aimed_action, route_action
from hazardhunt.testers.clear_path import clear_action, play_decisions

ToAction = Callable[[Simulation, NDArray[np.floating[Any]], bool], NDArray[np.float32]]
"""A closed-loop space's decision -> action, given whether to walk round obstacles."""

CLOSED_LOOP: dict[str, ToAction] = {"aim": aimed_action, "route": route_action}
"""The spaces whose decisions are turned into actions while they are played."""

DECISION_SIZES = {"open": 2, "aim": 3, "route": 3}
"""Numbers per decision in each search space."""

SPACES = tuple(DECISION_SIZES)
"""The search spaces' names."""

SPACE_CHOICES = (*SPACES, "mixed")
"""The values of a searcher's ``space``: one search space, or all of them in turn."""


def searched_spaces(space: str) -> tuple[str, ...]:
    """The search spaces a searcher's ``space`` (of :data:`SPACE_CHOICES`) takes in turn."""
    return SPACES if space == "mixed" else (space,)


BOUNDARY_VALUES: dict[str, tuple[tuple[float, ...], ...]] = {
    "open": ((-1.0, 0.0, 1.0),),
    # The bearing wraps round (-1 and 1 are both behind the robot): its quarter turns instead.
    "aim": ((-0.5, 0.0, 0.5, 1.0), (-1.0, 0.0, 1.0)),
    "route": ((-1.0, 0.0, 1.0), (-1.0, 0.0, 1.0)),
}
"""Per space, the boundary values of each number of a decision after the speed."""


def boundary_plans(space: str, horizon: int) -> NDArray[np.float64]:
    """A space's boundary values as whole episodes (boundary-value analysis): the human keeps
    one decision throughout, at its top speed, with every other number of the decision at one
    of its :data:`BOUNDARY_VALUES` (-1, 0 or 1; a bearing at its quarter turns); shape (plans,
    ``horizon``, numbers per decision).

    In the closed-loop spaces these are the plain attacks a tester tries first: walk into the
    robot from ahead, behind or either side, or keep 1.5 or 3 m from it there; wait on its
    route, or 3 m to either side of it, at the start, the middle or the goal of its mission,
    where a controller switches modes.
    """
    plans = np.array([(1.0, *values) for values in itertools.product(*BOUNDARY_VALUES[space])])
    return np.repeat(plans[:, None, :], horizon, axis=1)


def play_in_space(
    simulation: Simulation,
    decisions: Sequence[NDArray[np.floating[Any]]] | NDArray[np.floating[Any]],
    space: str,
    keep_trajectory: bool | Callable[[EpisodeSummary], bool] = True,
    clear_path: bool = False,
) -> EpisodeResult:
    """Play one episode from the scenario's start, each decision read in ``space``.

    Raises:
        ValueError: An unknown space.
    """
    if space not in DECISION_SIZES:
        raise ValueError(f"unknown search space {space!r}: one of {', '.join(SPACES)}")
    if space == "open" and not clear_path:
        return simulation.simulate(decisions, keep_trajectory)
    steer = CLOSED_LOOP.get(space)

    def to_action(simulation: Simulation, decision: NDArray[np.floating[Any]]) -> NDArray[Any]:
        action = decision if steer is None else steer(simulation, decision, clear_path)
        return clear_action(simulation, action) if clear_path else np.asarray(action, np.float32)

    return play_decisions(simulation, decisions, to_action, keep_trajectory)
