"""The bridge's own ROS 2 node: a context of its own on the leased domain, its publishers, its
``/cmd_vel`` subscription and the standard messages it builds from the simulation's state.

Only this module (and :mod:`hazardhunt.sut.ros2.bridge` through it) imports ROS 2's packages, and
only when a bridge is built.
"""

from __future__ import annotations

import itertools
import math
import os
import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from hazardhunt.errors import PluginError
from hazardhunt.sut.protocols import RobotState, TrackedHuman
from hazardhunt.sut.ros2.processes import confined
from hazardhunt.sut.ros2.sensing import ScannerParams
from hazardhunt.sut.route import Route

INSTALL_HINT = "pip install 'hazardhunt[ros2]'"
"""What brings ROS 2's Python client and messages (the ``ros2`` extra)."""

FRAMES = {"map": "map", "odom": "odom", "robot": "base_link", "human": "human"}
"""The frame ids the messages name (the odometry frame coincides with the map's)."""


def ros_modules() -> dict[str, Any]:
    """ROS 2's Python client and the message modules the bridge uses.

    Raises:
        PluginError: They are not installed.
    """
    try:
        import rclpy
        from builtin_interfaces.msg import Time
        from geometry_msgs.msg import PoseStamped, Twist
        from nav_msgs.msg import OccupancyGrid, Odometry, Path
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import LaserScan
    except ImportError as error:
        raise PluginError(
            f"ros2: ROS 2's Python packages are not installed ({error}); install them with "
            f"{INSTALL_HINT}"
        ) from None
    return {
        "rclpy": rclpy,
        "Time": Time,
        "PoseStamped": PoseStamped,
        "Twist": Twist,
        "OccupancyGrid": OccupancyGrid,
        "Odometry": Odometry,
        "Path": Path,
        "Clock": Clock,
        "LaserScan": LaserScan,
    }


class BridgeNode:
    """The bridge's own ROS node in a context of its own on the leased domain: its publishers,
    its ``/cmd_vel`` subscription and the messages it builds."""

    def __init__(self, domain_id: int, topics: Mapping[str, str]) -> None:
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        from rclpy.signals import SignalHandlerOptions

        modules = ros_modules()
        self.m = modules
        rclpy = modules["rclpy"]
        # The middleware reads its settings from this process's environment at init.
        confined_environment = confined(os.environ, domain_id)
        for key in set(os.environ) - set(confined_environment):
            del os.environ[key]
        os.environ.update(confined_environment)
        self.context = rclpy.Context()
        rclpy.init(
            context=self.context,
            domain_id=domain_id,
            signal_handler_options=SignalHandlerOptions.NO,  # Ctrl-C stays hazardhunt's
        )
        self.node = rclpy.create_node(
            "hazardhunt_bridge",
            context=self.context,
            start_parameter_services=False,
            enable_rosout=False,
        )
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        stream = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        latched = QoSProfile(
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
        node, m = self.node, modules
        self.clock = node.create_publisher(m["Clock"], topics["clock"], stream)
        self.odom = node.create_publisher(m["Odometry"], topics["odom"], stream)
        self.scan = node.create_publisher(m["LaserScan"], topics["scan"], stream)
        self.human = node.create_publisher(m["Odometry"], topics["human"], stream)
        self.plan = node.create_publisher(m["Path"], topics["plan"], latched)
        self.goal = node.create_publisher(m["PoseStamped"], topics["goal"], latched)
        self.map = node.create_publisher(m["OccupancyGrid"], topics["map"], latched)
        self.commands = node.create_subscription(
            m["Twist"], topics["cmd_vel"], self._on_command, stream
        )
        self.topics = topics
        self.types = {
            role: _type_name(m[name])
            for role, name in (
                ("clock", "Clock"), ("odom", "Odometry"), ("scan", "LaserScan"),
                ("human", "Odometry"), ("plan", "Path"), ("goal", "PoseStamped"),
                ("map", "OccupancyGrid"), ("cmd_vel", "Twist"),
            )
        }  # fmt: skip
        """The message type of each role's topic, as ROS names it (``geometry_msgs/msg/Twist``)."""
        self._received: list[tuple[float, float]] = []

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=0)
        self.node.destroy_node()
        self.context.try_shutdown()

    def _on_command(self, message: Any) -> None:
        self._received.append((float(message.linear.x), float(message.angular.z)))

    def wait_for_nodes(self, seconds: float, check: Callable[[], None]) -> None:
        """Until the user's nodes publish ``/cmd_vel`` and take odometry (up to ``seconds``).

        Raises:
            RuntimeError: They did not in time, one exited, or one uses a topic of the bridge's
                with another message type.
        """
        deadline = time.monotonic() + seconds
        while not (self.commands_matched() and self.odom.get_subscription_count() > 0):
            check()
            self._check_types()
            if time.monotonic() > deadline:
                raise RuntimeError(
                    f"no node subscribed to {self.topics['odom']} and published "
                    f"{self.topics['cmd_vel']} within {seconds:g} s (startup_timeout)"
                )
            self.executor.spin_once(timeout_sec=0.05)
        self._check_types()

    def _check_types(self) -> None:
        """Raises RuntimeError if a node publishes or subscribes to one of the bridge's topics
        with a message type other than the bridge's (the two would never hear each other)."""
        for role, message_type in self.types.items():
            topic = self.topics[role]
            if role == "cmd_vel":
                endpoints, verb = self.node.get_publishers_info_by_topic(topic), "publishes"
            else:
                endpoints, verb = self.node.get_subscriptions_info_by_topic(topic), "subscribes to"
            for endpoint in endpoints:
                if endpoint.topic_type != message_type:
                    known = not endpoint.node_name.startswith("_NODE_NAME_UNKNOWN")
                    node = f"node {endpoint.node_name!r}" if known else "a node"
                    raise RuntimeError(
                        f"{node} {verb} {topic} as {endpoint.topic_type}, not {message_type}"
                    )

    def scan_wanted(self) -> bool:
        """Whether a node subscribes to the scan (else it is neither ray-cast nor published:
        a message no subscriber is matched to goes nowhere)."""
        return bool(self.scan.get_subscription_count() > 0)

    def commands_matched(self) -> bool:
        return bool(self.node.count_publishers(self.topics["cmd_vel"]) > 0)

    # ------------------------------------------------------------------ messages
    def _stamp(self, nanoseconds: int) -> Any:
        return self.m["Time"](sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000)

    def map_message(self, cells: np.ndarray, columns: int, rows: int, resolution: float) -> Any:
        grid = self.m["OccupancyGrid"]()
        grid.header.frame_id = FRAMES["map"]
        grid.info.resolution = float(resolution)
        grid.info.width, grid.info.height = columns, rows
        grid.info.origin.orientation.w = 1.0
        grid.data = cells.tolist()
        return grid

    def publish_clock(self, nanoseconds: int) -> None:
        clock = self.m["Clock"]()
        clock.clock = self._stamp(nanoseconds)
        self.clock.publish(clock)

    def _pose(self, x: float, y: float, heading: float, stamp: Any) -> Any:
        pose = self.m["PoseStamped"]()
        pose.header.stamp, pose.header.frame_id = stamp, FRAMES["map"]
        pose.pose.position.x, pose.pose.position.y = float(x), float(y)
        pose.pose.orientation.z = math.sin(heading / 2)
        pose.pose.orientation.w = math.cos(heading / 2)
        return pose

    def publish_episode(self, grid: Any, route: Route, start_ns: int, seconds: float) -> None:
        """The latched route, goal and map of an episode starting at ``start_ns``, and wait
        (up to ``seconds``) until every subscriber has them."""
        stamp = self._stamp(start_ns)
        points = route.points.tolist()
        path = self.m["Path"]()
        path.header.stamp, path.header.frame_id = stamp, FRAMES["map"]
        headings = [math.atan2(b[1] - a[1], b[0] - a[0]) for a, b in itertools.pairwise(points)]
        headings.append(headings[-1])
        path.poses = [
            self._pose(x, y, h, stamp) for (x, y), h in zip(points, headings, strict=True)
        ]
        grid.header.stamp = stamp
        self.map.publish(grid)
        goal_x, goal_y = points[-1]
        self.goal.publish(self._pose(goal_x, goal_y, headings[-1], stamp))
        self.plan.publish(path)
        for publisher in (self.map, self.goal, self.plan):
            publisher.wait_for_all_acked(self.m["rclpy"].duration.Duration(seconds=seconds))

    def publish_instant(
        self,
        nanoseconds: int,
        robot: RobotState,
        ranges: np.ndarray | None,
        scanner: ScannerParams,
        human: TrackedHuman | None,
    ) -> None:
        """Scan (unless ``ranges`` is None), (when tracked) the human and odometry at one
        instant, then ``/clock``: a timer on simulated time that fires at the instant finds its
        data, unless it comes late."""
        stamp = self._stamp(nanoseconds)
        odometry = self.m["Odometry"]()
        odometry.header.stamp, odometry.header.frame_id = stamp, FRAMES["odom"]
        odometry.child_frame_id = FRAMES["robot"]
        odometry.pose.pose = self._pose(robot.x, robot.y, robot.heading, stamp).pose
        odometry.twist.twist.linear.x = float(robot.speed)
        odometry.twist.twist.angular.z = float(robot.yaw_rate)
        if ranges is not None:
            scan = self.m["LaserScan"]()
            scan.header.stamp, scan.header.frame_id = stamp, FRAMES["robot"]
            scan.angle_min, scan.angle_max = scanner.angle_min, float(scanner.angles[-1])
            scan.angle_increment = scanner.angle_increment
            scan.range_min, scan.range_max = scanner.range_min, scanner.range_max
            scan.ranges = ranges.astype(np.float32)
            self.scan.publish(scan)
        if human is not None:
            self.human.publish(self._human(human, stamp))
        self.odom.publish(odometry)
        self.publish_clock(nanoseconds)

    def _human(self, human: TrackedHuman, stamp: Any) -> Any:
        """The tracked human as Odometry: pose in the map, velocity in its own frame (x along
        its heading) from its last two tracked positions (zero after a gap)."""
        message = self.m["Odometry"]()
        message.header.stamp, message.header.frame_id = stamp, FRAMES["map"]
        message.child_frame_id = FRAMES["human"]
        x, y = human.position.tolist()
        message.pose.pose = self._pose(x, y, human.heading, stamp).pose
        if len(human.recent_times) >= 2:
            (x0, y0), (x1, y1) = human.recent_positions[-2:].tolist()
            elapsed = float(human.recent_times[-1] - human.recent_times[-2])
            vx, vy = (x1 - x0) / elapsed, (y1 - y0) / elapsed
            cos_h, sin_h = math.cos(human.heading), math.sin(human.heading)
            message.twist.twist.linear.x = cos_h * vx + sin_h * vy
            message.twist.twist.linear.y = -sin_h * vx + cos_h * vy
        return message

    # ------------------------------------------------------------------ answers
    def drain(self) -> None:
        """Take and drop every command that arrived before this instant."""
        while True:
            count = len(self._received)
            self.executor.spin_once(timeout_sec=0)
            if len(self._received) == count:
                break
        self._received.clear()

    def answer(self, seconds: float, check: Callable[[], None]) -> tuple[float, float]:
        """The first command after this instant's messages, waiting up to ``seconds``.

        Raises:
            RuntimeError: None came in time, or a node exited.
        """
        deadline = time.monotonic() + seconds
        while not self._received:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                check()
                raise RuntimeError(f"no {self.topics['cmd_vel']} within {seconds:g} s (timeout)")
            self.executor.spin_once(timeout_sec=min(remaining, 0.1))
            if not self._received:
                check()
        return self._received[0]

    def call_reset(self, name: str, seconds: float, check: Callable[[], None]) -> None:
        """Call the node's ``std_srvs/srv/Empty`` reset service and wait for its answer.

        Raises:
            RuntimeError: No such service answered within ``seconds``.
        """
        from std_srvs.srv import Empty

        client = self.node.create_client(Empty, name)
        try:
            deadline = time.monotonic() + seconds
            while not client.service_is_ready():
                check()
                if time.monotonic() > deadline:
                    raise RuntimeError(f"no reset service {name} within {seconds:g} s")
                self.executor.spin_once(timeout_sec=0.05)
            future = client.call_async(Empty.Request())
            while not future.done():
                check()
                if time.monotonic() > deadline:
                    raise RuntimeError(f"reset service {name} did not answer in {seconds:g} s")
                self.executor.spin_once(timeout_sec=0.05)
        finally:
            self.node.destroy_client(client)


def _type_name(message_class: type) -> str:
    """A message class's type as ROS names it: ``geometry_msgs/msg/Twist``."""
    return f"{message_class.__module__.split('.')[0]}/msg/{message_class.__name__}"
