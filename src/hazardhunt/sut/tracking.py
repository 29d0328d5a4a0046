"""Camera tracking of the human: position and heading every tracking period, unless the human
stands in a camera-blind zone."""

from __future__ import annotations

from collections import deque

import numpy as np

from hazardhunt.sut.protocols import FloatArray, TrackedHuman
from hazardhunt.world.floor import FloorMap


class HumanTracker:
    """Keeps the last three consecutive sightings of the human for the controller's prediction."""

    def __init__(self, floor: FloorMap, history: int = 3) -> None:
        self.floor = floor
        self._sightings: deque[tuple[float, FloatArray]] = deque(maxlen=history)

    def reset(self) -> None:
        """Forget all sightings."""
        self._sightings.clear()

    def observe(self, time: float, position: FloatArray, heading: float) -> TrackedHuman | None:
        """Track the human at ``time``.

        Returns:
            What the cameras report, or None when the human is in a blind zone (which also breaks
            the history: the next sighting starts it anew).
        """
        if self.floor.in_blind_zone(position):
            self._sightings.clear()
            return None
        self._sightings.append((time, position.copy()))
        return TrackedHuman(
            time=time,
            position=position.copy(),
            heading=heading,
            recent_positions=np.array([p for _, p in self._sightings]),
            recent_times=np.array([t for t, _ in self._sightings]),
        )
