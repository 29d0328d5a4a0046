"""Reward hacking, measured (SPEC 8, the study's Lesson 3).

A tester that farms the accumulated reward learns to *loiter*: the human walks into the
protective field ahead of the robot, the emergency stop triggers, the human steps out so that the
robot restarts, and steps in again; or it stands in the field until the episode stalls. Such an
episode earns a high return without a failure.
"""

from __future__ import annotations

from dataclasses import dataclass

from hazardhunt.spec.episode import EpisodeSummary


@dataclass(frozen=True)
class LoiteringRule:
    """Flags an episode without a failure that kept the robot stopping for the human."""

    min_stops: int = 2
    """Emergency stops in one episode from which stop-and-restart counts as loitering."""
    min_time_in_field: float = 2.0
    """Time the human spends in the field, together with ``min_stops``, in s."""

    def matches(self, summary: EpisodeSummary) -> bool:
        """Whether an episode's summary shows loitering."""
        if summary.outcome == "failure":
            return False
        if summary.outcome == "stall":
            return True
        return (
            summary.emergency_stops >= self.min_stops
            and summary.time_in_field >= self.min_time_in_field
        )

    def describe(self) -> str:
        """The rule in words."""
        return (
            f"no failure, and a stall or at least {self.min_stops} emergency stops with "
            f"{self.min_time_in_field:g} s or more in the field"
        )
