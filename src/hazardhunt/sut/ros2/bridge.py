"""The built-in controller ``ros2``: the user's ROS 2 node(s) drive the robot, in lock-step
simulated time (docs/ros2.md holds the topic contract).

At each control instant the bridge publishes ``/clock``, the robot's odometry, a simulated
laser scan and the tracked human, stamped in simulated time, and waits for the first
``/cmd_vel`` that arrives after them: that is the node's answer for the instant. No answer within
``timeout`` s of wall-clock time ends the episode as ``sut_error``, and the node is started anew
before the next episode; so is a node that exited.
"""

from __future__ import annotations

import math
import time
import weakref
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from hazardhunt.errors import PluginError
from hazardhunt.sut.protocols import (
    ControlCommand,
    FloatArray,
    RobotParams,
    RobotState,
    TrackedHuman,
)
from hazardhunt.sut.ros2.processes import DomainLease, NodeProcess, stop_all
from hazardhunt.sut.ros2.sensing import ScannerParams, floor_edges, published_grid, scan_ranges
from hazardhunt.sut.ros2.topics import BridgeNode, ros_modules
from hazardhunt.sut.route import Route
from hazardhunt.world.floor import FloorMap

TOPICS = {
    "clock": "/clock",
    "odom": "/odom",
    "scan": "/scan",
    "human": "/human",
    "plan": "/plan",
    "goal": "/goal_pose",
    "map": "/map",
    "cmd_vel": "/cmd_vel",
}
"""The topics the bridge speaks on, by role; ``topics`` in the parameters renames any."""

EPISODE_GAP_NS = 10_000_000_000
"""Simulated time between the end of one episode and the start of the next, at least, in ns:
each episode starts on a whole second at least this long after the last instant published."""

EPISODE_LEAD_NS = 1_000_000
"""How long before an episode's first instant the clock shows its start, when the route, goal
and map are published, in ns."""

ResetMode = Literal["messages", "service", "restart"]


@dataclass
class _Session:
    """What lives as long as the node(s): the ROS context, the bridge's own node and the
    user's processes. Kept apart from the controller so that a finaliser can stop it."""

    lease: DomainLease
    nodes: list[NodeProcess] = field(default_factory=list)
    ros: BridgeNode | None = None
    """The bridge's own node (its rclpy context and topics); None before start."""

    def close(self) -> None:
        stop_all(self.nodes)
        self.nodes = []
        if self.ros is not None:
            self.ros.close()
            self.ros = None
        self.lease.release()


class Ros2Controller:
    """The robot's controller is the user's ROS 2 node(s), started from ``command``."""

    def __init__(
        self,
        command: str | Sequence[str],
        control_period: float = 0.2,
        timeout: float = 2.0,
        startup_timeout: float = 30.0,
        reset: ResetMode = "messages",
        reset_service: str = "/reset",
        topics: Mapping[str, str] | None = None,
        scanner: Mapping[str, float] | None = None,
        map_resolution: float = 0.05,
        grace: float = 3.0,
    ) -> None:
        """Check the parameters; the node(s) start at the first :meth:`reset`.

        Args:
            command: The node's command line (``"python my_node.py"``, ``"ros2 run pkg
                node"``), or a list of command lines, one per node.
            control_period: Time between two control instants, in s of simulated time.
            timeout: Wall-clock time the node has to answer an instant, in s.
            startup_timeout: Wall-clock time a node has to start and subscribe, in s.
            reset: How a node learns that an episode starts: ``"messages"``, from the latched
                route, goal and map published anew; ``"service"``, also a call of
                ``reset_service`` (``std_srvs/srv/Empty``) the bridge waits for; ``"restart"``,
                the node is started anew for every episode.
            reset_service: The reset service's name.
            topics: Topic names by role (keys of :data:`TOPICS`), instead of the defaults.
            scanner: Fields of :class:`~hazardhunt.sut.ros2.sensing.ScannerParams`.
            map_resolution: Cell size of the published occupancy grid, in m (a floor read
                from a site map is published as that map's grid).
            grace: Time a node has to exit after SIGINT before it is killed, in s.

        Raises:
            PluginError: A parameter is wrong, or ROS 2's Python packages are not installed.
        """
        commands = [command] if isinstance(command, str) else list(command)
        if not commands or not all(isinstance(c, str) and c.strip() for c in commands):
            raise PluginError("ros2: command must be a command line or a list of them")
        for name, value in (
            ("control_period", control_period),
            ("timeout", timeout),
            ("startup_timeout", startup_timeout),
            ("map_resolution", map_resolution),
            ("grace", grace),
        ):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
                raise PluginError(f"ros2: {name} must be a positive number, not {value!r}")
        if reset not in ("messages", "service", "restart"):
            raise PluginError(
                f"ros2: reset must be 'messages', 'service' or 'restart', not {reset!r}"
            )
        unknown = sorted(set(topics or {}) - set(TOPICS))
        if unknown:
            raise PluginError(
                f"ros2: topics: unknown role {unknown[0]!r} (roles: {', '.join(TOPICS)})"
            )
        try:
            self.scanner = ScannerParams(**(scanner or {}))
        except (TypeError, ValueError) as error:
            raise PluginError(f"ros2: scanner: {error}") from None
        ros_modules()  # the missing extra is a one-line error now, not at the first episode
        self.commands = commands
        self.control_period = float(control_period)
        self.timeout, self.startup_timeout = float(timeout), float(startup_timeout)
        self.reset_mode: ResetMode = reset
        self.reset_service = reset_service
        self.topics = {**TOPICS, **(topics or {})}
        self.map_resolution, self.grace = float(map_resolution), float(grace)
        self._session: _Session | None = None
        self._finalizer: weakref.finalize[Any, Any] | None = None
        self._restart = False
        self._offset_ns = 0
        self._last_ns = 0
        self._floor: FloorMap | None = None
        self._edges: np.ndarray | None = None
        self._map_message: Any = None
        self._radius = 0.25
        self._sensed: tuple[float, tuple[float, float, float]] | None = None
        """The instant and the human's true disc (x, y, radius) from :meth:`sense_human`."""

    # ------------------------------------------------------------------ protocol
    def reset(self, floor: FloorMap, route: Route, robot: RobotState, params: RobotParams) -> None:
        """Start the node(s) if they are not running (or anew, in ``"restart"`` mode), move the
        clock to the next episode's start and publish the route, goal and map.

        Raises:
            RuntimeError: A node did not start, exited or did not subscribe in time.
        """
        if self._restart or self.reset_mode == "restart" or not self._running():
            self.close()
        if self._session is None:
            self._start()
        assert self._session is not None
        assert self._session.ros is not None
        ros = self._session.ros
        self._session.lease.touch()
        self._restart = False
        self._sensed = None
        if floor is not self._floor:
            self._floor, self._edges = floor, floor_edges(floor)
            cells, columns, rows, resolution = published_grid(floor, self.map_resolution)
            self._map_message = ros.map_message(cells, columns, rows, resolution)
        start = -(-(self._last_ns + EPISODE_GAP_NS) // 1_000_000_000) * 1_000_000_000
        self._offset_ns = self._last_ns = start
        # Just before the first instant: a node's timer due at the first instant fires then.
        ros.publish_clock(start - EPISODE_LEAD_NS)
        ros.publish_episode(self._map_message, route, start, self.startup_timeout)
        if self.reset_mode == "service":
            ros.call_reset(self.reset_service, self.startup_timeout, self._check_nodes)

    def sense_human(self, time: float, human_position: FloatArray, radius: float) -> None:
        """Take the human's true position for the next instant's scan (the laser sees the real
        human, wherever the tracking cameras place it or lose it)."""
        x, y = (float(value) for value in human_position)
        self._sensed = (time, (x, y, float(radius)))

    def control(self, time: float, robot: RobotState, human: TrackedHuman | None) -> ControlCommand:
        """Publish this instant's messages and return the node's answer.

        Raises:
            RuntimeError: A node exited or did not answer within ``timeout``.
        """
        if self._session is None or self._session.ros is None:
            raise RuntimeError("reset() must be called before control()")
        ros = self._session.ros
        stamp = self._offset_ns + round(time * 1e9)
        self._last_ns = max(self._last_ns, stamp)
        ranges = self._scan(time, robot, human) if ros.scan_wanted() else None
        started = _monotonic()
        ros.drain()
        ros.publish_instant(stamp, robot, ranges, self.scanner, human)
        try:
            speed, yaw_rate = ros.answer(self.timeout, self._check_nodes)
        except RuntimeError:
            self._restart = True
            raise
        return ControlCommand(speed=speed, yaw_rate=yaw_rate, solve_time_s=_monotonic() - started)

    def _scan(self, time: float, robot: RobotState, human: TrackedHuman | None) -> FloatArray:
        """This instant's ranges, ray-cast from the scanner's pose on the robot."""
        heading, mount = robot.heading, self.scanner
        origin = (
            robot.x + math.cos(heading) * mount.x - math.sin(heading) * mount.y,
            robot.y + math.sin(heading) * mount.x + math.cos(heading) * mount.y,
        )
        assert self._edges is not None
        disc = self._scanned_human(time, human)
        return scan_ranges(self._edges, origin, heading + mount.yaw, mount, disc)

    def _scanned_human(
        self, time: float, human: TrackedHuman | None
    ) -> tuple[float, float, float] | None:
        """The human's disc in this instant's scan: the true one given for ``time`` by
        :meth:`sense_human` (as the simulation does), else the tracked one."""
        if self._sensed is not None and self._sensed[0] == time:
            return self._sensed[1]
        return None if human is None else (*human.position.tolist(), self._radius)

    # ------------------------------------------------------------------ nodes
    def close(self) -> None:
        """Stop the node(s) and the bridge's own ROS node (idempotent; also at exit)."""
        if self._finalizer is not None:
            self._finalizer()
            self._finalizer = None
        self._session = None

    def _running(self) -> bool:
        session = self._session
        return session is not None and all(node.exit_code is None for node in session.nodes)

    def _start(self) -> None:
        session = _Session(DomainLease())
        self._session = session
        self._finalizer = weakref.finalize(self, session.close)
        session.ros = BridgeNode(session.lease.domain_id, self.topics)
        for command in self.commands:
            try:
                session.nodes.append(NodeProcess(command, session.lease.domain_id, self.grace))
            except Exception as error:
                self.close()
                raise RuntimeError(str(error)) from None
        try:
            session.ros.wait_for_nodes(self.startup_timeout, self._check_nodes)
        except RuntimeError:
            self.close()
            raise

    def _check_nodes(self) -> None:
        """Raises RuntimeError if a node has exited."""
        assert self._session is not None
        for node in self._session.nodes:
            code = node.exit_code
            if code is not None:
                raise RuntimeError(f"node {node.command!r} exited with code {code}")


def _monotonic() -> float:
    return time.perf_counter()
