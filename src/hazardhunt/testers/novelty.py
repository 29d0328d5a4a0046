"""Novelty: how far a failure lies from the failures already found, in descriptor space.

The remedy the study's future work names for RL testing that re-finds the same failure (Corso et
al. 2019, "Adaptive stress testing with reward augmentation for autonomous vehicle
validation"): reward a failure by its dissimilarity to the failures found before it. The
descriptors are those of :mod:`hazardhunt.spec.descriptors`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from hazardhunt.spec.descriptors import describe, descriptor_distance
from hazardhunt.spec.episode import EpisodeSummary


class FailureArchive:
    """The descriptors of the failures found so far, and novelty against them."""

    def __init__(self, neighbours: int = 3) -> None:
        """Args:
        neighbours: How many nearest failures the novelty averages over (k).
        """
        if neighbours < 1:
            raise ValueError(f"neighbours must be at least 1, not {neighbours}")
        self.neighbours = neighbours
        self.descriptors: list[NDArray[np.float64]] = []

    def __len__(self) -> int:
        return len(self.descriptors)

    def novelty(self, summary: EpisodeSummary) -> float:
        """The mean descriptor distance of an episode to its k nearest failures found so far
        (``inf`` before the first failure; distances are scaled so that about 1 separates
        opposite sides of the robot or different safety-layer histories)."""
        if not self.descriptors:
            return float("inf")
        point = describe(summary)
        distances = sorted(descriptor_distance(point, known) for known in self.descriptors)
        return float(np.mean(distances[: self.neighbours]))

    def add(self, summary: EpisodeSummary) -> None:
        """Remember a failure."""
        self.descriptors.append(describe(summary))
