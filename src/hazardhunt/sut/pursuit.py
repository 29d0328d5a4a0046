"""A pure-pursuit route follower: a plain, fast controller with no human awareness.

It is the reference point for "a controller that ignores the human": tests of the physics, the
safety layer and the specification use it so that they do not depend on the NMPC.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hazardhunt.sut.protocols import ControlCommand, RobotState, TrackedHuman
from hazardhunt.sut.route import Route
from hazardhunt.world.bodies import RobotParams
from hazardhunt.world.floor import FloorMap


@dataclass(frozen=True)
class PursuitParams:
    """Tuning of the route follower."""

    speed: float = 1.0
    """Cruise speed, in m/s."""
    lookahead: float = 1.0
    """Distance ahead on the route the robot steers towards, in m."""
    control_period: float = 0.2
    """Time between two commands, in s."""


class PursuitController:
    """Follows the route at cruise speed by steering towards a look-ahead point."""

    def __init__(self, params: PursuitParams = PursuitParams(), robot: RobotParams = RobotParams()):
        self.params = params
        self.robot = robot
        self.control_period = params.control_period
        self._route: Route | None = None
        self._progress = 0.0

    def reset(self, floor: FloorMap, route: Route, robot: RobotState, params: RobotParams) -> None:
        """Start following ``route`` from the robot's position."""
        self.robot = params
        self._route = route
        self._progress = route.project(np.array([robot.x, robot.y]))

    def control(self, time: float, robot: RobotState, human: TrackedHuman | None) -> ControlCommand:
        """Steer towards the look-ahead point; the human is ignored."""
        if self._route is None:
            raise RuntimeError("reset() must be called before control()")
        position = np.array([robot.x, robot.y])
        self._progress = self._route.project(position, self._progress, self._progress + 2.0)
        target = self._route.point_at(self._progress + self.params.lookahead)
        forward = math.cos(robot.heading) * (target[0] - robot.x) + math.sin(robot.heading) * (
            target[1] - robot.y
        )
        left = -math.sin(robot.heading) * (target[0] - robot.x) + math.cos(robot.heading) * (
            target[1] - robot.y
        )
        distance_sq = max(forward * forward + left * left, 1e-9)
        curvature = 2.0 * left / distance_sq
        speed = min(self.params.speed, self.robot.max_speed)
        yaw_rate = float(
            np.clip(speed * curvature, -self.robot.max_yaw_rate, self.robot.max_yaw_rate)
        )
        return ControlCommand(speed=speed, yaw_rate=yaw_rate)
