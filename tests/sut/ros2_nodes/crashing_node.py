"""The example pure-pursuit node, which dies (exit code 3) at its ``crash_after``-th odometry
message unless the file ``marker`` exists; it creates the file as it dies, so that the node
started anew after the crash runs on."""

import os
import sys
from pathlib import Path

import rclpy
from spinning import spin

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "examples" / "ros2"))
from pure_pursuit_node import PurePursuit


class CrashingPursuit(PurePursuit):
    def __init__(self) -> None:
        super().__init__()
        self.crash_after = self.declare_parameter("crash_after", 20).value
        self.marker = Path(self.declare_parameter("marker", "").value)
        self.received = 0

    def on_odometry(self, odometry) -> None:
        self.received += 1
        if self.received >= self.crash_after and not self.marker.exists():
            self.marker.touch()
            os._exit(3)
        super().on_odometry(odometry)


def main() -> None:
    rclpy.init()
    node = CrashingPursuit()
    spin(node)


if __name__ == "__main__":
    main()
