"""Failure descriptors: a few numbers that say how an episode met (or came close to) the robot.

Quality-diversity search spreads its archive over them, novelty rewards distance in them, and
the report clusters failures on a richer set of trajectory features. They come from the
episode's summary alone, so every played episode has them, failure or not:

- ``bearing``: where the human was around the robot's body at the contact (or the closest
  approach), in rad: 0 ahead, pi/2 on the left, +-pi behind, -pi/2 on the right;
- ``robot_speed``: the robot's speed then, in m/s;
- ``emergency_stop``: the safety layer's history then: 0 never triggered, 1 the stop was
  holding (braking), 2 the stop had been released (the robot restarted).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from hazardhunt.spec.episode import EpisodeSummary

DESCRIPTOR_NAMES = ("bearing", "robot_speed", "emergency_stop")
"""The descriptor's entries, in order."""

DESCRIPTOR_BOUNDS = ((-math.pi, math.pi), (0.0, 1.2), (0.0, 2.0))
"""Each entry's range (the robot's speed up to the built-in robot's top speed)."""

EMERGENCY_STOP_CODES = {"never": 0.0, "holding": 1.0, "released": 2.0}
"""The safety layer's history as a number."""


def describe(summary: EpisodeSummary) -> NDArray[np.float64]:
    """An episode's descriptor: bearing (rad), robot speed (m/s), emergency-stop history."""
    return np.array(
        [
            summary.closest_bearing,
            summary.closest_robot_speed,
            EMERGENCY_STOP_CODES[summary.closest_emergency_stop],
        ]
    )


def descriptor_distance(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    """Distance between two descriptors, each entry scaled by its range; bearings wrap."""
    bearing = abs(math.remainder(float(a[0] - b[0]), 2 * math.pi)) / math.pi
    speed = abs(float(a[1] - b[1])) / DESCRIPTOR_BOUNDS[1][1]
    stop = float(a[2] != b[2])
    return math.sqrt(bearing**2 + speed**2 + stop**2)
