"""An example controller to test with hazardhunt: pure pursuit with a naive stop rule.

The robot steers towards the route point ``lookahead`` metres ahead of it and drives at
``cruise_speed``; it stops whenever the tracked human stands within ``stop_distance`` metres
ahead of its front, inside its own lane. The rule looks only ahead: a human walking into the
robot's side, or stepping in front of it closer than it can brake, is not covered, and
hazardhunt finds those failures within a few hundred episodes (docs/plugins.md).

Run it:

    hazardhunt run --scenario crossing --field none --tester random --episodes 300 \\
        --controller cautious_pursuit:CautiousPursuit --controller-param stop_distance=1.0 \\
        --out runs/cautious

(from this folder, or with it on PYTHONPATH).
"""

from __future__ import annotations

import math

import numpy as np

from hazardhunt.sut.protocols import ControlCommand, RobotParams, RobotState, TrackedHuman
from hazardhunt.sut.route import Route
from hazardhunt.world.floor import FloorMap


class CautiousPursuit:
    """Pure pursuit along the route; stops for a human right ahead (the Controller protocol)."""

    def __init__(
        self,
        cruise_speed: float = 1.0,
        lookahead: float = 1.0,
        stop_distance: float = 1.0,
        max_yaw_rate: float = 1.0,
    ) -> None:
        if cruise_speed <= 0 or lookahead <= 0 or stop_distance < 0:
            raise ValueError("cruise_speed and lookahead must be positive, stop_distance >= 0")
        self.cruise_speed = cruise_speed
        self.lookahead = lookahead
        self.stop_distance = stop_distance
        self.max_yaw_rate = max_yaw_rate
        self.control_period = 0.2  # seconds between two calls
        self._route: Route | None = None
        self._robot = RobotParams()
        self._progress = 0.0

    def reset(self, floor: FloorMap, route: Route, robot: RobotState, params: RobotParams) -> None:
        """A new episode: remember the route, the robot's size and where it is on the route."""
        self._route = route
        self._robot = params
        self._progress = route.project(np.array([robot.x, robot.y]))

    def control(self, time: float, robot: RobotState, human: TrackedHuman | None) -> ControlCommand:
        """Speed and yaw rate for the next 0.2 s."""
        route = self._route
        if route is None:
            raise RuntimeError("reset() must be called before control()")
        self._progress = route.project(
            np.array([robot.x, robot.y]), self._progress, self._progress + 2.0
        )
        if route.length - self._progress < 0.05:
            return ControlCommand(speed=0.0, yaw_rate=0.0)  # at the goal
        if human is not None and self._human_ahead(robot, human):
            return ControlCommand(speed=0.0, yaw_rate=0.0, status="stopped for human")
        target = route.point_at(min(self._progress + self.lookahead, route.length))
        dx, dy = float(target[0]) - robot.x, float(target[1]) - robot.y
        bearing = math.atan2(dy, dx) - robot.heading
        bearing = math.atan2(math.sin(bearing), math.cos(bearing))
        distance = max(math.hypot(dx, dy), 1e-6)
        speed = min(self.cruise_speed, 2.0 * (route.length - self._progress))
        yaw_rate = 2.0 * speed * math.sin(bearing) / distance  # pure pursuit curvature x speed
        yaw_rate = max(-self.max_yaw_rate, min(self.max_yaw_rate, yaw_rate))
        return ControlCommand(speed=speed, yaw_rate=yaw_rate)

    def _human_ahead(self, robot: RobotState, human: TrackedHuman) -> bool:
        """Whether the human stands within stop_distance ahead of the front, in the lane."""
        dx, dy = float(human.position[0]) - robot.x, float(human.position[1]) - robot.y
        forward = dx * math.cos(robot.heading) + dy * math.sin(robot.heading)
        left = -dx * math.sin(robot.heading) + dy * math.cos(robot.heading)
        ahead = forward - self._robot.length / 2
        return 0.0 <= ahead <= self.stop_distance and abs(left) <= self._robot.width
