"""Open-loop action sequences that do not walk the human into a wall.

An episode-level searcher proposes a whole episode as a sequence of actions before it is played,
so it cannot see where the human will stand. About a fifth of the moving decisions of a random
open-loop sequence push the human against a wall or shelf, where it slides or stops: budget
spent on episodes in which the human does less than the search asked of it. The random tester
avoids this by drawing each action until its path is clear (SPEC 5); here an open-loop sequence
gets the same treatment deterministically: every decision whose path would touch a static
obstacle is replaced, while it is played, by the nearest action whose path is clear. The
actions played are what the episode records, so it replays exactly without this module.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from hazardhunt.sim.simulation import EpisodeResult, Simulation
from hazardhunt.spec.episode import EpisodeSummary

TURN_CHOICES = np.linspace(-1.0, 1.0, 9)
"""Normalised turn rates a blocked action may change to, nearest to the wanted one first."""

SPEED_SHARES = (1.0, 0.5)
"""Shares of the wanted speed tried, in order, before the human turns on the spot."""


def human_path(
    pose: tuple[float, float, float], speed: float, turn_rate: float, duration: float, step: float
) -> NDArray[np.float64]:
    """Positions of an unblocked human holding (speed, turn rate), one per physics step."""
    x, y, heading = pose
    times = np.arange(1, round(duration / step) + 1) * step
    if abs(turn_rate) < 1e-9:
        return np.stack(
            [x + speed * times * math.cos(heading), y + speed * times * math.sin(heading)], axis=1
        )
    radius = speed / turn_rate
    headings = heading + turn_rate * times
    return np.stack(
        [
            x + radius * (np.sin(headings) - math.sin(heading)),
            y - radius * (np.cos(headings) - math.cos(heading)),
        ],
        axis=1,
    )


def clear_action(simulation: Simulation, action: NDArray[np.floating[Any]]) -> NDArray[np.float32]:
    """``action`` if the human's path over the next decision period is clear of every static
    obstacle where it stands in ``simulation``; otherwise the nearest clear action: the same
    speed (then half of it) with the nearest clear turn rate, else turning on the spot at the
    wanted rate (always clear)."""
    wanted = np.clip(np.asarray(action, dtype=np.float64).reshape(2), -1.0, 1.0)
    turns = TURN_CHOICES[np.argsort(np.abs(TURN_CHOICES - wanted[1]), kind="stable")]
    for share in SPEED_SHARES:
        normalised_speed = share * (wanted[0] + 1.0) - 1.0
        for turn in (wanted[1], *turns) if share == 1.0 else turns:
            candidate = np.array([normalised_speed, turn], dtype=np.float32)
            if _clear(simulation, candidate):
                return candidate
    return np.array([-1.0, wanted[1]], dtype=np.float32)


def _clear(simulation: Simulation, action: NDArray[np.float32]) -> bool:
    speed, turn_rate = simulation.decode_action(action)
    path = human_path(
        simulation.human_pose,
        speed,
        turn_rate,
        simulation.decision_period,
        simulation.physics_step,
    )
    return simulation.scenario.floor.discs_clear(path, simulation.human_params.radius)


def play_decisions(
    simulation: Simulation,
    decisions: Sequence[NDArray[np.floating[Any]]] | NDArray[np.floating[Any]],
    to_action: Callable[[Simulation, NDArray[np.floating[Any]]], NDArray[np.float32]],
    keep_trajectory: bool | Callable[[EpisodeSummary], bool] = True,
) -> EpisodeResult:
    """Play one episode from the scenario's start, each of ``decisions`` turned into the action
    ``to_action`` gives for it at the moment it is played."""
    simulation.reset()
    for decision in decisions:
        if simulation.decide(to_action(simulation, np.asarray(decision))).outcome is not None:
            break
    return simulation.result(keep_trajectory)
