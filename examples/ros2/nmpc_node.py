"""hazardhunt's built-in NMPC controller as a ROS 2 node: it drives the robot from the ROS
messages a navigation node gets, and nothing else (docs/ros2.md).

Its inputs are the latched map (``/map``, ``nav_msgs/OccupancyGrid``), route (``/plan``,
``nav_msgs/Path``) and goal (``/goal_pose``, ``geometry_msgs/PoseStamped``), the robot's
odometry (``/odom``, ``nav_msgs/Odometry``) and the tracked human (``/human``,
``nav_msgs/Odometry``, none while the cameras do not see it) and ``/clock``; its output is
one ``/cmd_vel`` (``geometry_msgs/Twist``) per odometry message. Messages on two topics may
arrive in either order, so it answers an odometry message once the ``/human`` of the same stamp
has come, or else once ``/clock`` has reached that stamp (the human was not tracked then).

The control law is hazardhunt's NMPC solver used as a library (``hazardhunt.sut.nmpc``), and the
map's occupied cells become its obstacles as hazardhunt reads a ROS map
(``hazardhunt.world.rosmap``): what comes from hazardhunt is code, every input comes over ROS.

A new ``/plan`` starts an episode; so does a call of its ``reset`` service
(``std_srvs/srv/Empty``). The human's last three consecutive positions (an odometry instant
without a ``/human`` message of the same stamp starts them anew) feed the NMPC's prediction.
When the solver fails, the node answers a standstill (speed and turn rate 0), as hazardhunt
does with a failed command of an in-process controller.

Run it against hazardhunt:

    hazardhunt run --scenario crossing --field none --tester random --episodes 20 \\
        --controller ros2 --controller-param command="python examples/ros2/nmpc_node.py" \\
        --out runs/ros2-nmpc
"""

from __future__ import annotations

import math
import sys
from decimal import Decimal

import numpy as np
import rclpy
from geometry_msgs.msg import PoseStamped, Twist
from nav_msgs.msg import OccupancyGrid, Odometry, Path
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from std_srvs.srv import Empty

from hazardhunt.sut.nmpc import NMPCController, NMPCParams
from hazardhunt.sut.protocols import RobotParams, RobotState, TrackedHuman
from hazardhunt.sut.route import Route
from hazardhunt.world import rosmap


def nanoseconds(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def yaw_of(pose) -> float:
    """The heading a planar pose's quaternion holds, in rad."""
    return 2.0 * math.atan2(pose.orientation.z, pose.orientation.w)


def floor_of(grid: OccupancyGrid):
    """The map as a floor whose obstacles are its occupied and unknown cells, merged into
    rectangles. The resolution travels as a 32-bit float: it is taken as the decimal with six
    places it stands for (0.05 m, not 0.0500000007 m)."""
    resolution = float(round(Decimal(float(grid.info.resolution)), 6))
    cells = np.array(grid.data, dtype=np.int8).reshape(grid.info.height, grid.info.width)
    origin = grid.info.origin
    pose = (origin.position.x, origin.position.y, yaw_of(origin))
    return rosmap.grid_floor("map", rosmap.OccupancyGrid(resolution, pose, cells))


class NMPCNode(Node):
    def __init__(self) -> None:
        super().__init__("nmpc")
        self.controller = NMPCController(NMPCParams(), robot=RobotParams())
        latched = QoSProfile(
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
        self.floor = None
        self.route: Route | None = None
        self.goal: tuple[float, float] | None = None
        self.start_ns = 0
        """The episode's start: the route's stamp."""
        self.fresh = True
        """Whether the NMPC is yet to be reset for this episode (at its first odometry)."""
        self.humans: dict[int, Odometry] = {}
        """The /human messages not yet used, by stamp."""
        self.sightings: list[tuple[float, tuple[float, float]]] = []
        self.last_answered = -1
        self.pending: Odometry | None = None
        """The odometry waiting for its instant's /human or /clock."""
        self.commands = self.create_publisher(Twist, "cmd_vel", 10)
        self.create_subscription(OccupancyGrid, "map", self.on_map, latched)
        self.create_subscription(Path, "plan", self.on_plan, latched)
        self.create_subscription(PoseStamped, "goal_pose", self.on_goal, latched)
        self.create_subscription(Odometry, "human", self.on_human, 10)
        self.create_subscription(Odometry, "odom", self.on_odometry, 10)
        self.create_subscription(Clock, "clock", self.on_clock, 10)
        self.create_service(Empty, "reset", self.on_reset)

    def on_map(self, grid: OccupancyGrid) -> None:
        self.floor = floor_of(grid)
        self.fresh = True

    def on_plan(self, path: Path) -> None:
        points = [(pose.pose.position.x, pose.pose.position.y) for pose in path.poses]
        self.route = Route(np.array(points, dtype=np.float64))
        self.start_ns = nanoseconds(path.header.stamp)
        self.on_reset(None, Empty.Response())

    def on_goal(self, goal: PoseStamped) -> None:
        self.goal = (goal.pose.position.x, goal.pose.position.y)

    def on_reset(self, request: Empty.Request | None, response: Empty.Response) -> Empty.Response:
        """A new episode: forget the warm start and the human's history."""
        self.fresh = True
        self.humans.clear()
        self.sightings = []
        self.pending = None
        return response

    def on_human(self, human: Odometry) -> None:
        stamp = nanoseconds(human.header.stamp)
        if stamp <= self.last_answered:
            print(f"nmpc: a /human of {stamp} ns came after its odometry", file=sys.stderr)
        self.humans[stamp] = human
        if self.pending is not None and nanoseconds(self.pending.header.stamp) == stamp:
            self.answer()

    def on_odometry(self, odometry: Odometry) -> None:
        self.pending = odometry
        if nanoseconds(odometry.header.stamp) in self.humans:
            self.answer()

    def on_clock(self, clock: Clock) -> None:
        if self.pending is not None and nanoseconds(clock.clock) >= nanoseconds(
            self.pending.header.stamp
        ):
            self.answer()

    def answer(self) -> None:
        """The command for the pending odometry's instant."""
        odometry, self.pending = self.pending, None
        if odometry is None or self.floor is None or self.route is None:
            return
        stamp = nanoseconds(odometry.header.stamp)
        self.last_answered = stamp
        now = (stamp - self.start_ns) / 1e9
        pose, twist = odometry.pose.pose, odometry.twist.twist
        robot = RobotState(
            pose.position.x, pose.position.y, yaw_of(pose), twist.linear.x, twist.angular.z
        )
        if self.fresh:
            self.controller.reset(self.floor, self.route, robot, self.controller.robot)
            self.fresh = False
        command = self.controller.control(now, robot, self.tracked(stamp, now))
        answer = Twist()
        if not command.failed:
            answer.linear.x, answer.angular.z = command.speed, command.yaw_rate
        self.commands.publish(answer)

    def tracked(self, stamp: int, now: float) -> TrackedHuman | None:
        """The human at this instant with its last consecutive sightings; None if no /human
        came with this instant's odometry (which breaks the history)."""
        human = self.humans.pop(stamp, None)
        self.humans = {s: h for s, h in self.humans.items() if s > stamp}
        if human is None:
            self.sightings = []
            return None
        position = (human.pose.pose.position.x, human.pose.pose.position.y)
        self.sightings = [*self.sightings[-2:], (now, position)]
        return TrackedHuman(
            time=now,
            position=np.array(position),
            heading=yaw_of(human.pose.pose),
            recent_positions=np.array([p for _, p in self.sightings]),
            recent_times=np.array([t for t, _ in self.sightings]),
        )


def main() -> None:
    rclpy.init()
    node = NMPCNode()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):  # SIGINT: the run has ended
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
