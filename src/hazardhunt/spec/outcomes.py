"""How an episode ends (SPEC 4): the six outcomes and the termination rule."""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

from hazardhunt.spec.safety import ContactVerdict


class Outcome(str, Enum):
    """The outcome of an episode."""

    GOAL = "goal"
    """The robot reached its goal."""
    FAILURE = "failure"
    """An unsafe contact: the robot endangered the human."""
    SAFE_CONTACT = "safe_contact"
    """A contact covered by an exception of the safety specification."""
    TIMEOUT = "timeout"
    """The episode's simulated time ran out."""
    STALL = "stall"
    """The emergency stop held for too long in a row."""
    SUT_ERROR = "sut_error"
    """The system under test failed: a controller that could not command, or a controller or
    safety layer that raised, returned something unusable or outlasted its time limit."""


MAX_EPISODE_DURATION = 3600.0
"""The longest episode, in s of simulated time."""


@dataclass(frozen=True)
class TerminationParams:
    """When an episode ends."""

    episode_duration: float = 30.0
    """Simulated time after which the episode times out, in s."""
    stall_duration: float = 10.0
    """Continuous emergency-stop time after which the episode stalls, in s."""


def episode_outcome(
    verdict: ContactVerdict,
    goal_reached: bool,
    sim_time: float,
    emergency_stop_duration: float,
    sut_error: bool,
    params: TerminationParams = TerminationParams(),
) -> Outcome | None:
    """The outcome that ends the episode after this physics step, or None to go on.

    A contact takes precedence over everything else: it is what the search is after.
    """
    if verdict is ContactVerdict.UNSAFE:
        return Outcome.FAILURE
    if verdict is not ContactVerdict.NONE:
        return Outcome.SAFE_CONTACT
    if sut_error:
        return Outcome.SUT_ERROR
    if goal_reached:
        return Outcome.GOAL
    # Compare with a tolerance: time accumulates in float steps of 0.05 s.
    if emergency_stop_duration >= params.stall_duration - 1e-9:
        return Outcome.STALL
    if sim_time >= params.episode_duration - 1e-9:
        return Outcome.TIMEOUT
    return None
