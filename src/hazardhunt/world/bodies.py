"""Physical parameters of the two bodies on the floor: the robot (AGV) and the human."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class RobotParams:
    """The AGV: a rectangle on a unicycle base (SPEC 2).

    The pose (x, y, heading) is the centre of the rectangle; heading points along its long axis.
    """

    length: float = 0.64
    """Length along the heading, in m."""
    width: float = 0.5
    """Width across the heading, in m."""
    max_speed: float = 1.2
    """Largest forward speed, in m/s (the robot never drives backwards)."""
    max_yaw_rate: float = 0.5
    """Largest absolute turn rate, in rad/s."""
    max_acceleration: float = 1.0
    """Largest absolute change of speed, in m/s^2."""
    max_yaw_acceleration: float = 3.0
    """Largest absolute change of turn rate, in rad/s^2."""
    emergency_deceleration: float = 7.5
    """Braking deceleration of the safety layer's emergency stop, in m/s^2."""
    goal_tolerance: float = 0.3
    """Distance to the goal at which the robot has arrived, in m."""

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, not {value!r}")
            limit = ROBOT_LIMITS[name]
            if value > limit:
                raise ValueError(f"{name} must be at most {limit:g}, not {value!r}")

    @property
    def half_diagonal(self) -> float:
        """Radius of the smallest disc around the rectangle, in m."""
        return math.hypot(self.length / 2, self.width / 2)


ROBOT_LIMITS = {
    "length": 10.0,
    "width": 10.0,
    "max_speed": 10.0,
    "max_yaw_rate": 10.0,
    "max_acceleration": 50.0,
    "max_yaw_acceleration": 100.0,
    "emergency_deceleration": 100.0,
    "goal_tolerance": 10.0,
}
"""The largest value of each robot parameter (m, m/s, rad/s, m/s², rad/s²): far beyond any
mobile robot on a shop floor, so that a typo (a length of 1e6 m) is refused when read."""


@dataclass(frozen=True)
class RobotState:
    """The robot's pose and speeds: what the physics advances and the controller measures."""

    x: float
    """Position east, in m (centre of the robot's rectangle)."""
    y: float
    """Position north, in m."""
    heading: float
    """Heading, in rad, counter-clockwise from east."""
    speed: float
    """Forward speed, in m/s."""
    yaw_rate: float
    """Turn rate, in rad/s."""


@dataclass(frozen=True)
class HumanParams:
    """The simulated human: a disc on unicycle kinematics (SPEC 2)."""

    radius: float = 0.25
    """Radius of the disc, in m."""
    max_speed: float = 1.5
    """Largest walking speed, in m/s."""
    max_turn_rate: float = math.pi / 2
    """Largest absolute turn rate, in rad/s."""
