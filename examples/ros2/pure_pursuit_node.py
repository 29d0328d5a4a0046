"""A pure-pursuit route follower as a ROS 2 node: what a user's navigation node looks like to
hazardhunt's ``ros2`` controller (docs/ros2.md).

It follows the route on ``/plan`` at cruise speed by steering towards the route point
``lookahead`` metres ahead, and ignores the human: hazardhunt's in-process
``hazardhunt.sut.pursuit:PursuitController`` in ROS 2's terms, plain rclpy and standard messages.

A new ``/plan`` starts an episode; so does a call of its ``reset`` service
(``std_srvs/srv/Empty``). Two ways of running, the parameter ``mode``:

- ``answer`` (default): one ``/cmd_vel`` for each ``/odom`` message, computed from it;
- ``timer``: a timer on simulated time (``use_sim_time``) every ``period`` s publishes a command
  from the latest odometry received, which may be one control period old.

Run it against hazardhunt:

    hazardhunt run --scenario crossing --field none --tester random --episodes 20 \\
        --controller ros2 --controller-param command="python examples/ros2/pure_pursuit_node.py" \\
        --out runs/ros2-pursuit
"""

from __future__ import annotations

import math

import numpy as np
import rclpy
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry, Path
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_srvs.srv import Empty


class Polyline:
    """The route as a polyline parameterised by arc length s (m)."""

    def __init__(self, points: np.ndarray) -> None:
        self.points = points
        self.cumulative = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(points, axis=0).T))])
        self.arc_lengths = self.cumulative.tolist()
        self.frames = []
        for (start_x, start_y), (end_x, end_y) in zip(
            points[:-1].tolist(), points[1:].tolist(), strict=True
        ):
            dx, dy = end_x - start_x, end_y - start_y
            norm = max(float(np.hypot(dx, dy)), 1e-12)
            self.frames.append((start_x, start_y, dx / norm, dy / norm))

    def point_at(self, s: float) -> tuple[float, float]:
        """The point at arc length s; beyond either end, the end segment extended."""
        index = int(np.searchsorted(self.arc_lengths, s, side="right")) - 1
        index = min(max(index, 0), len(self.frames) - 1)
        start_x, start_y, tangent_x, tangent_y = self.frames[index]
        along = s - self.arc_lengths[index]
        return start_x + along * tangent_x, start_y + along * tangent_y

    def project(self, point: np.ndarray, s_min: float = 0.0, s_max: float = math.inf) -> float:
        """Arc length of the route point nearest ``point`` within [s_min, s_max]."""
        best_s, best_distance = s_min, math.inf
        for index in range(len(self.frames)):
            start_s, end_s = self.arc_lengths[index], self.arc_lengths[index + 1]
            if end_s < s_min or start_s > s_max:
                continue
            start = self.points[index]
            direction = self.points[index + 1] - start
            length = end_s - start_s
            t = float(np.dot(point - start, direction)) / max(length * length, 1e-12)
            s = min(max(start_s + t * length, max(start_s, s_min)), min(end_s, s_max))
            nearest_x, nearest_y = self.point_at(s)
            distance = float(np.hypot(nearest_x - point[0], nearest_y - point[1]))
            if distance < best_distance:
                best_s, best_distance = s, distance
        return best_s


def yaw_of(odometry: Odometry) -> float:
    """The heading a planar pose's quaternion holds, in rad."""
    q = odometry.pose.pose.orientation
    return 2.0 * math.atan2(q.z, q.w)


class PurePursuit(Node):
    def __init__(self) -> None:
        super().__init__("pure_pursuit")
        self.speed = self.declare_parameter("speed", 1.0).value
        self.lookahead = self.declare_parameter("lookahead", 1.0).value
        self.max_speed = self.declare_parameter("max_speed", 1.2).value
        self.max_yaw_rate = self.declare_parameter("max_yaw_rate", 0.5).value
        mode = self.declare_parameter("mode", "answer").value
        latched = QoSProfile(
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
        self.route: Polyline | None = None
        self.progress: float | None = None
        self.odometry: Odometry | None = None
        self.commands = self.create_publisher(Twist, "cmd_vel", 10)
        self.create_subscription(Path, "plan", self.on_plan, latched)
        self.create_subscription(Odometry, "odom", self.on_odometry, 10)
        self.create_service(Empty, "reset", self.on_reset)
        if mode == "timer":
            self.create_timer(self.declare_parameter("period", 0.2).value, self.on_timer)
        elif mode != "answer":
            raise SystemExit(f"mode must be 'answer' or 'timer', not {mode!r}")
        self.answering = mode == "answer"

    def on_plan(self, path: Path) -> None:
        """A new episode's route: start from wherever the robot is on it."""
        points = [(pose.pose.position.x, pose.pose.position.y) for pose in path.poses]
        self.route = Polyline(np.array(points, dtype=np.float64))
        self.progress = None

    def on_reset(self, request: Empty.Request, response: Empty.Response) -> Empty.Response:
        """A new episode (hazardhunt's ``reset = "service"``): forget where the robot was."""
        self.progress = None
        self.odometry = None
        return response

    def on_odometry(self, odometry: Odometry) -> None:
        self.odometry = odometry
        if self.answering:
            self.publish_command()

    def on_timer(self) -> None:
        if self.odometry is not None:
            self.publish_command()

    def publish_command(self) -> None:
        if self.route is None or self.odometry is None:
            return
        x = self.odometry.pose.pose.position.x
        y = self.odometry.pose.pose.position.y
        heading = yaw_of(self.odometry)
        position = np.array([x, y])
        if self.progress is None:
            self.progress = self.route.project(position)
        self.progress = self.route.project(position, self.progress, self.progress + 2.0)
        target_x, target_y = self.route.point_at(self.progress + self.lookahead)
        forward = math.cos(heading) * (target_x - x) + math.sin(heading) * (target_y - y)
        left = -math.sin(heading) * (target_x - x) + math.cos(heading) * (target_y - y)
        curvature = 2.0 * left / max(forward * forward + left * left, 1e-9)
        command = Twist()
        command.linear.x = min(self.speed, self.max_speed)
        command.angular.z = float(
            np.clip(command.linear.x * curvature, -self.max_yaw_rate, self.max_yaw_rate)
        )
        self.commands.publish(command)


def main() -> None:
    rclpy.init()
    node = PurePursuit()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):  # SIGINT: the run has ended
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
