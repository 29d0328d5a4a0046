"""A node that answers each odometry message with what its scan reads straight ahead: linear.x
the range of the scan's middle ray (m), once it has the scan of the same instant."""

import rclpy
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from sensor_msgs.msg import LaserScan
from spinning import spin


def nanoseconds(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


class ScanEcho:
    def __init__(self, node) -> None:
        self.scans: dict[int, float] = {}
        self.waiting: set[int] = set()
        self.commands = node.create_publisher(Twist, "cmd_vel", 10)
        node.create_subscription(LaserScan, "scan", self.on_scan, 10)
        node.create_subscription(Odometry, "odom", self.on_odometry, 10)

    def on_scan(self, scan: LaserScan) -> None:
        self.scans[nanoseconds(scan.header.stamp)] = float(scan.ranges[len(scan.ranges) // 2])
        self.answer()

    def on_odometry(self, odometry: Odometry) -> None:
        self.waiting.add(nanoseconds(odometry.header.stamp))
        self.answer()

    def answer(self) -> None:
        for stamp in sorted(self.waiting & set(self.scans)):
            self.waiting.discard(stamp)
            command = Twist()
            command.linear.x = min(self.scans.pop(stamp), 1e6)  # +inf: nothing within range
            self.commands.publish(command)


def main() -> None:
    rclpy.init()
    node = rclpy.create_node("scan_echo")
    ScanEcho(node)
    spin(node)


if __name__ == "__main__":
    main()
