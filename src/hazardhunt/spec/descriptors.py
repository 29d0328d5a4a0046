"""Failure descriptors: a few numbers that say how an episode met (or came close to) the robot.

Quality-diversity search spreads its archive over them, novelty rewards distance in them, and
the report clusters failures on a richer set of trajectory features. They come from the
episode's summary alone, so every played episode has them, failure or not:

- ``bearing``: where the human was around the robot's body at the contact (or the closest
  approach), in rad: 0 ahead, pi/2 on the left, +-pi behind, -pi/2 on the right;
- ``robot_speed``: the robot's speed then, in m/s;
- ``emergency_stop``: the safety layer's history then: 0 never triggered, 1 the stop was
  holding (braking), 2 the stop had been released (the robot restarted);
- ``human_speed``: the human's speed then, in m/s: whether it walked into the robot or stood
  in its way.

One more number of the summary can span a quality-diversity archive (:data:`MEASURE_NAMES`),
though novelty does not weigh it: ``route_share``, how far along its route the robot was then
(0 at the start, 1 at the goal), that is where in its mission the robot met the human (driving
off, on the way, docking).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from hazardhunt.spec.episode import EpisodeSummary

DESCRIPTOR_NAMES = ("bearing", "robot_speed", "emergency_stop", "human_speed")
"""The descriptor's entries, in order."""

DESCRIPTOR_BOUNDS = ((-math.pi, math.pi), (0.0, 1.2), (0.0, 2.0), (0.0, 1.5))
"""Each entry's range (the speeds up to the built-in robot's and human's top speeds)."""

WALKING_SPEED = 0.5
"""From this speed on, in m/s, a human counts as walking for the novelty: standing and walking
lie 1 apart, slower and faster walking closer."""

MEASURE_NAMES = (*DESCRIPTOR_NAMES, "route_share")
"""Everything :func:`measures_of` reads: the descriptor and one more entry."""

MEASURE_RANGES = {
    **dict(zip(DESCRIPTOR_NAMES, DESCRIPTOR_BOUNDS, strict=True)),
    "emergency_stop": (-0.5, 2.5),
    "route_share": (0.0, 1.0),
}
"""Each measure's range when it spans an archive's axis: the descriptor's bounds, but with the
safety layer's three codes each in the middle of a cell."""

EMERGENCY_STOP_CODES = {"never": 0.0, "holding": 1.0, "released": 2.0}
"""The safety layer's history as a number."""


def describe(summary: EpisodeSummary) -> NDArray[np.float64]:
    """An episode's descriptor: bearing (rad), robot speed (m/s), emergency-stop history,
    human speed (m/s)."""
    return measures_of(summary, DESCRIPTOR_NAMES)


def measures_of(summary: EpisodeSummary, names: Sequence[str]) -> NDArray[np.float64]:
    """The entries ``names`` (of :data:`MEASURE_NAMES`) of an episode, in that order."""
    values = {
        "bearing": summary.closest_bearing,
        "robot_speed": summary.closest_robot_speed,
        "emergency_stop": EMERGENCY_STOP_CODES[summary.closest_emergency_stop],
        "route_share": summary.closest_route_share,
        "human_speed": summary.closest_human_speed,
    }
    return np.array([values[name] for name in names])


def descriptor_distance(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    """Distance between two descriptors, each entry scaled by its range; bearings wrap, and
    human speeds count up to :data:`WALKING_SPEED`."""
    bearing = abs(math.remainder(float(a[0] - b[0]), 2 * math.pi)) / math.pi
    speed = abs(float(a[1] - b[1])) / DESCRIPTOR_BOUNDS[1][1]
    stop = float(a[2] != b[2])
    walking = abs(min(float(a[3]), WALKING_SPEED) - min(float(b[3]), WALKING_SPEED))
    return math.sqrt(bearing**2 + speed**2 + stop**2 + (walking / WALKING_SPEED) ** 2)
