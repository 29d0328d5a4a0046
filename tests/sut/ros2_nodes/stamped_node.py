"""A node that publishes its commands as geometry_msgs/TwistStamped, not Twist."""

import rclpy
from geometry_msgs.msg import TwistStamped
from nav_msgs.msg import Odometry
from spinning import spin


def main() -> None:
    rclpy.init()
    node = rclpy.create_node("stamped")
    commands = node.create_publisher(TwistStamped, "cmd_vel", 10)
    node.create_subscription(Odometry, "odom", lambda message: commands.publish(TwistStamped()), 10)
    spin(node)


if __name__ == "__main__":
    main()
