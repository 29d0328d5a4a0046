"""The plug-in points of the system under test: what a controller and a safety layer look like.

:class:`~hazardhunt.world.bodies.RobotState` and ``RobotParams`` are re-exported here, as a
controller needs them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from hazardhunt.sut.route import Route
from hazardhunt.world.bodies import RobotParams, RobotState
from hazardhunt.world.floor import FloorMap

FloatArray = NDArray[np.float64]

__all__ = [
    "ControlCommand",
    "Controller",
    "FloatArray",
    "RobotParams",
    "RobotState",
    "SafetyLayer",
    "SafetyStatus",
    "SensesHuman",
    "TrackedHuman",
]


@dataclass(frozen=True)
class TrackedHuman:
    """What the tracking cameras report about the human at one tracking instant.

    ``recent_positions`` and ``recent_times`` hold up to the last three consecutive tracked
    positions (oldest first, the current one last); a gap in visibility starts them anew.
    """

    time: float
    """Tracking instant, in s of simulated time."""
    position: FloatArray
    """Current position (x, y), in m."""
    heading: float
    """Current heading, in rad."""
    recent_positions: FloatArray
    """Shape (k, 2), k in 1..3: the last tracked positions, oldest first, in m."""
    recent_times: FloatArray
    """Shape (k,): the instants of ``recent_positions``, in s."""


@dataclass(frozen=True)
class ControlCommand:
    """A controller's answer for one control period, with what it wants recorded."""

    speed: float
    """Commanded forward speed, in m/s."""
    yaw_rate: float
    """Commanded turn rate, in rad/s."""
    status: str = "ok"
    """Solver or controller status; ``"ok"`` when the command came from a successful solve."""
    failed: bool = False
    """True when the controller could not compute a command and asked for a brake."""
    solve_time_s: float = 0.0
    """Wall time of the optimisation, in s (0 for controllers that do not solve anything)."""
    planned_positions: FloatArray | None = None
    """Shape (N+1, 2): the robot positions the controller plans over its horizon, in m."""
    predicted_human: FloatArray | None = None
    """Shape (N, 2): the human positions the controller predicted over its horizon, in m."""
    extras: dict[str, float] = field(default_factory=dict)
    """Further numbers the controller wants recorded (iterations, cost, slack, ...)."""


@runtime_checkable
class Controller(Protocol):
    """A robot controller: called once every ``control_period`` while it is in charge.

    While the safety layer holds an emergency stop, the controller is not called; it resumes
    from whatever state the robot is in when the stop is released.
    """

    control_period: float
    """Time between two calls, in s."""

    def reset(self, floor: FloorMap, route: Route, robot: RobotState, params: RobotParams) -> None:
        """Forget the previous episode; the robot starts at ``robot`` and follows ``route``.

        Args:
            floor: The static map (walls, shelves, camera-blind zones).
            route: The reference path from the start through the waypoints to the goal.
            robot: The robot's state at the start.
            params: The robot's dimensions and limits (size, speeds, accelerations).
        """
        ...

    def control(self, time: float, robot: RobotState, human: TrackedHuman | None) -> ControlCommand:
        """Compute the command for the next control period.

        Args:
            time: Simulated time, in s.
            robot: The robot's measured state.
            human: The tracked human, or None when the cameras do not see it.

        Returns:
            The command. A controller that cannot compute one returns a command with
            ``failed=True`` (the robot then brakes); it should not raise.
        """
        ...


@runtime_checkable
class SensesHuman(Protocol):
    """An optional extension of :class:`Controller`, for a controller that simulates a sensor
    of its own on the robot (the ROS 2 bridge's laser scanner): it also gets the human's true
    position. A controller without this method is called as before.

    The simulation calls :meth:`sense_human` at each control instant, just before ``control``
    with the same ``time``. The position is the human's true one at that instant: the tracking
    cameras' blind zones, and the tracking noise, latency and dropped frames of ``estimate``'s
    uncertainties, do not apply to it (they apply to ``control``'s ``human``).
    """

    def sense_human(self, time: float, human_position: FloatArray, radius: float) -> None:
        """Take the human's true position at ``time``.

        Args:
            time: Simulated time, in s (the next ``control`` call's).
            human_position: The human's centre (x, y), in m.
            radius: The human disc's radius, in m.
        """
        ...


@dataclass(frozen=True)
class SafetyStatus:
    """The safety layer's verdict at one physics step."""

    emergency_stop: bool
    """True while the stop overrides the controller."""
    human_in_field: bool
    """True while the human disc overlaps the protective field."""


@runtime_checkable
class SafetyLayer(Protocol):
    """A safety function that may override the controller with an emergency stop."""

    def reset(self) -> None:
        """Forget the previous episode."""
        ...

    def update(
        self, time: float, robot: RobotState, human_position: FloatArray, radius: float
    ) -> SafetyStatus:
        """Check the protective field at one physics step (simulated ``time`` in s), for a
        human disc of ``radius`` m."""
        ...
