"""A node that subscribes to odometry and advertises /cmd_vel but never publishes a command."""

import rclpy
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from spinning import spin


def main() -> None:
    rclpy.init()
    node = rclpy.create_node("silent")
    node.create_publisher(Twist, "cmd_vel", 10)
    node.create_subscription(Odometry, "odom", lambda message: None, 10)
    spin(node)


if __name__ == "__main__":
    main()
