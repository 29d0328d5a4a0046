"""How every test node runs until the bridge stops it: spin, and end quietly on SIGINT."""

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node


def spin(node: Node) -> None:
    """Spin ``node`` until SIGINT (how the bridge ends a node), then shut ROS down."""
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        rclpy.try_shutdown()
