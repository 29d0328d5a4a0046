"""Your robot's navigation node, as hazardhunt's ``ros2`` controller runs it (hazardhunt's
docs/ros2.md has the topic contract). Written by ``hazardhunt new-sut --ros2``; put your own
control law in ``MyNode.command``.

It answers each odometry message on ``/odom`` with one velocity command on ``/cmd_vel``
(``geometry_msgs/Twist``). As written it follows the route on ``/plan`` at a steady speed by
steering towards the route point ``lookahead`` m ahead, and stops while the laser scan on
``/scan`` sees something closer than ``stop_distance`` m in front of it: replace that with
your own. Plain rclpy and standard messages; nothing of hazardhunt.
"""

from __future__ import annotations

import math

import numpy as np
import rclpy
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry, Path
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import LaserScan


def nanoseconds(stamp: Time) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def yaw_of(odometry: Odometry) -> float:
    """The heading a planar pose's quaternion holds, in rad."""
    q = odometry.pose.pose.orientation
    return 2.0 * math.atan2(q.z, q.w)


class MyNode(Node):
    def __init__(self) -> None:
        super().__init__("my_node")
        self.speed: float = self.declare_parameter("speed", 1.0).value
        self.lookahead: float = self.declare_parameter("lookahead", 1.2).value
        self.stop_distance: float = self.declare_parameter("stop_distance", 1.0).value
        self.max_yaw_rate: float = self.declare_parameter("max_yaw_rate", 0.5).value
        latched = QoSProfile(
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
        self.route: np.ndarray | None = None
        self.scans: dict[int, LaserScan] = {}
        self.waiting: dict[int, Odometry] = {}
        self.commands = self.create_publisher(Twist, "cmd_vel", 10)
        self.create_subscription(Path, "plan", self.on_plan, latched)
        self.create_subscription(LaserScan, "scan", self.on_scan, 10)
        self.create_subscription(Odometry, "odom", self.on_odometry, 10)

    def on_plan(self, path: Path) -> None:
        """A new episode's route."""
        self.route = np.array([(p.pose.position.x, p.pose.position.y) for p in path.poses])
        self.scans.clear()
        self.waiting.clear()

    # The scan and the odometry of one instant may arrive in either order: answer an odometry
    # message once the scan of the same stamp is there.
    def on_scan(self, scan: LaserScan) -> None:
        self.scans[nanoseconds(scan.header.stamp)] = scan
        self.answer()

    def on_odometry(self, odometry: Odometry) -> None:
        self.waiting[nanoseconds(odometry.header.stamp)] = odometry
        self.answer()

    def answer(self) -> None:
        for stamp in sorted(self.waiting.keys() & self.scans.keys()):
            odometry, scan = self.waiting.pop(stamp), self.scans.pop(stamp)
            speed, yaw_rate = self.command(odometry, scan)
            message = Twist()
            message.linear.x, message.angular.z = float(speed), float(yaw_rate)
            self.commands.publish(message)

    def command(self, odometry: Odometry, scan: LaserScan) -> tuple[float, float]:
        """Your control law: the speed (m/s) and turn rate (rad/s) for this instant."""
        if self.route is None:
            return 0.0, 0.0
        x, y = odometry.pose.pose.position.x, odometry.pose.pose.position.y
        heading = yaw_of(odometry)
        # The route point nearest the robot, then the one lookahead metres further on.
        distances = np.hypot(self.route[:, 0] - x, self.route[:, 1] - y)
        target = self.route[-1]
        for index in range(int(np.argmin(distances)), len(self.route)):
            if distances[index] >= self.lookahead:
                target = self.route[index]
                break
        forward = math.cos(heading) * (target[0] - x) + math.sin(heading) * (target[1] - y)
        left = -math.sin(heading) * (target[0] - x) + math.cos(heading) * (target[1] - y)
        curvature = 2.0 * left / max(forward * forward + left * left, 1e-9)
        # Stop while something is closer than stop_distance within 30 degrees of straight ahead.
        angles = scan.angle_min + scan.angle_increment * np.arange(len(scan.ranges))
        ahead = np.asarray(scan.ranges)[np.abs(angles) < math.radians(30)]
        if ahead.size and float(ahead.min()) < self.stop_distance:
            return 0.0, 0.0
        yaw_rate = min(max(self.speed * curvature, -self.max_yaw_rate), self.max_yaw_rate)
        return self.speed, yaw_rate


def main() -> None:
    rclpy.init()
    node = MyNode()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):  # SIGINT: the run has ended
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
