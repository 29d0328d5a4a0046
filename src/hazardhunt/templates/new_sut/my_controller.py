"""Your controller, as hazardhunt tests it: replace the logic in ``control`` with your own.

It follows hazardhunt's Controller protocol (``hazardhunt.sut.protocols.Controller``): a
``control_period``, a ``reset`` at the start of every episode and a ``control`` call every
``control_period`` seconds of simulated time. As written, it is a pure-pursuit route follower
that stops while the tracked human is close: a reasonable start, and not a safe one. Run the
campaign next to this file (README.md) to see how it fails.

To put your own system under test, call into it from ``reset`` and ``control``: your planner,
your ROS node's logic, a learned policy. Keep the robot's limits in ``reset``'s ``params``
rather than in constants here: they come from the campaign file (``[env.robot]``).
"""

from __future__ import annotations

import math

import numpy as np

from hazardhunt.sut.protocols import ControlCommand, RobotParams, RobotState, TrackedHuman
from hazardhunt.sut.route import Route
from hazardhunt.world.floor import FloorMap


class MyController:
    """Pure pursuit along the route; stops while the human is within ``stop_distance``."""

    def __init__(
        self, lookahead: float = 1.2, stop_distance: float = 1.0, control_period: float = 0.1
    ) -> None:
        """Args:
        lookahead: How far ahead along the route the robot steers to, in m.
        stop_distance: Gap between the robot's body and the human at which it stops, in m.
        control_period: Seconds between two calls, a multiple of the 0.05 s physics step.

        The campaign file sets them (``[controller] params``).
        """
        if lookahead <= 0 or stop_distance < 0:
            raise ValueError("lookahead must be positive and stop_distance at least 0")
        self.lookahead = lookahead
        self.stop_distance = stop_distance
        self.control_period = control_period
        self.params = RobotParams()
        self.route: Route | None = None
        self.progress = 0.0  # how far along the route the robot is, in m

    def reset(self, floor: FloorMap, route: Route, robot: RobotState, params: RobotParams) -> None:
        """A new episode: the floor, the route to the goal, the robot's start, size and limits."""
        self.params = params
        self.route = route
        self.progress = route.project(np.array([robot.x, robot.y]))

    def control(self, time: float, robot: RobotState, human: TrackedHuman | None) -> ControlCommand:
        """The speed (m/s) and turn rate (rad/s) for the next control period.

        ``human`` is None while the cameras do not see the human (a blind zone).
        """
        route = self.route
        if route is None:
            raise RuntimeError("control() before reset()")
        position = np.array([robot.x, robot.y])
        # Searching only a little ahead keeps the progress from jumping to a later leg.
        self.progress = route.project(position, self.progress, self.progress + 1.0)
        remaining = route.length - self.progress
        if remaining < self.params.goal_tolerance / 2:
            return ControlCommand(speed=0.0, yaw_rate=0.0, status="at goal")

        # --- your logic goes here ---------------------------------------------------------
        if human is not None and self._gap_to(human, robot) < self.stop_distance:
            return ControlCommand(speed=0.0, yaw_rate=0.0, status="stopped for the human")
        # Pure pursuit: the arc through the route point a lookahead ahead.
        target = route.point_at(min(self.progress + self.lookahead, route.length))
        dx, dy = float(target[0]) - robot.x, float(target[1]) - robot.y
        bearing = math.atan2(dy, dx) - robot.heading
        bearing = math.atan2(math.sin(bearing), math.cos(bearing))
        curvature = 2 * math.sin(bearing) / max(math.hypot(dx, dy), 1e-6)  # 1/m
        # As fast as the robot may go, slow enough to turn onto that arc and to stop at the goal.
        speed = min(
            self.params.max_speed,
            self.params.max_yaw_rate / max(abs(curvature), 1e-6),
            math.sqrt(2 * self.params.max_acceleration * remaining),
        )
        yaw_rate = max(-self.params.max_yaw_rate, min(self.params.max_yaw_rate, speed * curvature))
        return ControlCommand(speed=speed, yaw_rate=yaw_rate)

    def _gap_to(self, human: TrackedHuman, robot: RobotState) -> float:
        """Distance from the human's tracked position to the robot's body (a disc around it),
        in m."""
        distance = math.hypot(
            float(human.position[0]) - robot.x, float(human.position[1]) - robot.y
        )
        return distance - self.params.half_diagonal
