"""What an episode amounts to, as typed records: its summary, its timing and its trajectory.

These are the one definition of every recorded name: the simulation fills them, the failure
classifier and the loitering rule read them, the result store writes their fields as the
columns of its tables, and the report and the docs name those columns.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from hazardhunt.world.geometry import FloatArray


@dataclass(frozen=True)
class EpisodeSummary:
    """What an episode amounts to (SPEC 7); every value is simulated, none measured on a clock,
    so the same actions give the same summary."""

    outcome: str | None = None
    """How the episode ended (see :class:`~hazardhunt.spec.outcomes.Outcome`); None while it
    goes on."""
    contact_face: str | None = None
    """The robot's face the human touched (``front``, ``rear``, ``left``, ``right``); None
    without a contact."""
    contact_verdict: str = "none"
    """How the contact was judged (see :class:`~hazardhunt.spec.safety.ContactVerdict`):
    ``unsafe``, one of the exceptions, or ``none`` without a contact."""
    decision_steps: int = 0
    """Decisions of the tester played."""
    sim_time: float = 0.0
    """Simulated time, in s."""
    risk_sum: float = 0.0
    """The risk summed over every physics step: the return of the accumulated reward."""
    max_risk: float = 0.0
    """The largest risk of any physics step: the return of the maximum reward."""
    min_clearance: float = float("inf")
    """The smallest gap between human and robot, in m (negative: overlap)."""
    closest_bearing: float = 0.0
    """Where the human was around the robot at the contact, or at the closest approach without
    one: the bearing of the human's centre in the robot's frame, in rad (0 ahead, pi/2 on the
    left, -pi/2 on the right)."""
    closest_robot_speed: float = 0.0
    """The robot's speed then, in m/s."""
    closest_emergency_stop: str = "never"
    """The safety layer's history then: the stop had ``never`` triggered, was ``holding``, or
    had been ``released``."""
    closest_route_share: float = 0.0
    """How far along its route the robot was then: the share of the route's length from its
    start to the route point nearest the robot (0 at the start, 1 at the goal)."""
    closest_human_speed: float = 0.0
    """The human's speed then (over the last physics step), in m/s."""
    emergency_stops: int = 0
    """Emergency stops the safety layer triggered."""
    time_in_field: float = 0.0
    """Time the human spent inside the protective field, in s."""
    controller_calls: int = 0
    """Times the controller was asked for a command."""
    controller_failures: int = 0
    """Commands the controller could not compute (failed, non-finite, or raised)."""
    controller_errors: tuple[str, ...] = ()
    """What went wrong with the controller, ``Type: message``: every exception ``control``
    raised, an unusable return (``UnusableReturnError: ...``), a call over the time limit
    (``TimeLimitError: ...``); ``reset() raised Type: message`` for its ``reset``."""
    safety_layer_errors: tuple[str, ...] = ()
    """The same for the safety layer: ``update``'s exceptions and unusable returns, and
    ``reset() raised Type: message``."""

    def as_row(self) -> dict[str, Any]:
        """The summary as one table row (the errors joined by ``; ``)."""
        row = dataclasses.asdict(self)
        for key in _ERROR_LISTS:
            row[key] = "; ".join(getattr(self, key))
        return row

    @classmethod
    def from_row(cls, row: Mapping[str, Any]) -> EpisodeSummary:
        """A summary from a table row written by :meth:`as_row` (other keys are ignored)."""
        values = _known_fields(cls, row)
        for key in _ERROR_LISTS:
            errors = values.get(key)
            if isinstance(errors, str):
                values[key] = tuple(errors.split("; ")) if errors else ()
        return cls(**values)


_ERROR_LISTS = ("controller_errors", "safety_layer_errors")
"""The summary's lists of errors, one string each in a table."""


@dataclass(frozen=True)
class EpisodeTiming:
    """Wall-clock measurements of an episode: kept apart from the summary because they differ
    from run to run."""

    wall_time_s: float = 0.0
    """Time the episode took, in s."""
    solve_time_mean_s: float = 0.0
    """Mean solve time the controller reported per call, in s (0 without calls, and for a
    controller that solves nothing)."""
    solve_time_median_s: float = 0.0
    """Median solve time per call, in s."""
    solve_time_max_s: float = 0.0
    """Longest solve, in s."""

    @classmethod
    def of(cls, wall_time_s: float, solve_times: list[float]) -> EpisodeTiming:
        """The timing of an episode that took ``wall_time_s`` and these solves (s)."""
        if not solve_times:
            return cls(wall_time_s)
        times = np.asarray(solve_times, dtype=np.float64)
        return cls(wall_time_s, float(times.mean()), float(np.median(times)), float(times.max()))


@dataclass(frozen=True)
class TrajectorySample:
    """The episode at one control instant (every 0.2 s) or at its end."""

    time: float
    """Simulated time, in s."""
    human_x: float
    """The human's position east, in m."""
    human_y: float
    """The human's position north, in m."""
    human_heading: float
    """The human's heading, in rad."""
    robot_x: float
    """The robot's centre east, in m."""
    robot_y: float
    """The robot's centre north, in m."""
    robot_heading: float
    """The robot's heading, in rad."""
    robot_speed: float
    """The robot's forward speed, in m/s."""
    robot_yaw_rate: float = 0.0
    """The robot's turn rate, in rad/s."""
    human_visible: bool = True
    """Whether the tracking cameras saw the human."""
    emergency_stop: bool = False
    """Whether the safety layer's emergency stop held."""
    human_in_field: bool = False
    """Whether the human overlapped the protective field."""
    clearance: float = 0.0
    """Gap between human and robot, in m (negative: overlap)."""
    controller_status: str = ""
    """Status of the controller's last command (``ok`` after a successful solve)."""
    controller_failed: bool = False
    """Whether the controller's last command failed (the robot brakes)."""
    solve_time_s: float = 0.0
    """Solve time the controller reported for its last command, in s (measured on the clock:
    differs between runs)."""
    predicted_human: FloatArray | None = None
    """Shape (N, 2): the human positions the controller predicted, in m."""
    planned_positions: FloatArray | None = None
    """Shape (N+1, 2): the robot positions the controller planned, in m."""

    def as_row(self) -> dict[str, Any]:
        """The sample as one table row, its arrays as flat lists (Parquet list columns)."""
        row = {field.name: getattr(self, field.name) for field in dataclasses.fields(self)}
        for key in ("predicted_human", "planned_positions"):
            value = row[key]
            row[key] = None if value is None else np.asarray(value, np.float64).ravel().tolist()
        return row

    @classmethod
    def from_row(cls, row: Mapping[str, Any]) -> TrajectorySample:
        """A sample from a table row written by :meth:`as_row` (other keys are ignored)."""
        values = _known_fields(cls, row)
        for key in ("predicted_human", "planned_positions"):
            value = values.get(key)
            if value is not None:
                values[key] = np.asarray(value, dtype=np.float64).reshape(-1, 2)
        return cls(**values)


TRAJECTORY_COLUMNS = tuple(field.name for field in dataclasses.fields(TrajectorySample))
"""The columns of a stored trajectory, in order."""
SUMMARY_COLUMNS = tuple(field.name for field in dataclasses.fields(EpisodeSummary))
"""The columns an episode's summary gives a table, in order."""
TIMING_COLUMNS = tuple(field.name for field in dataclasses.fields(EpisodeTiming))
"""The wall-clock columns of an episode, in order."""


def _known_fields(record: type[Any], row: Mapping[str, Any]) -> dict[str, Any]:
    names = {field.name for field in dataclasses.fields(record)}
    return {key: _plain(value) for key, value in row.items() if key in names}


def _plain(value: Any) -> Any:
    """A table cell as a Python value: numpy scalars become floats, ints and bools."""
    if isinstance(value, np.generic):
        return value.item()
    return value
