"""The example pure-pursuit node, which dies (exit code 4) if /clock or the odometry's stamps
ever run backwards, or a stamp is not a whole multiple of 1 ms."""

import os
import sys
from pathlib import Path

import rclpy
from rosgraph_msgs.msg import Clock
from spinning import spin

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "examples" / "ros2"))
from pure_pursuit_node import PurePursuit


def nanoseconds(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


class ClockChecking(PurePursuit):
    def __init__(self) -> None:
        super().__init__()
        self.last_clock = self.last_odometry = -1
        self.create_subscription(Clock, "/clock", self.on_clock, 10)

    def on_clock(self, clock: Clock) -> None:
        now = nanoseconds(clock.clock)
        if now < self.last_clock or now % 1_000_000:
            os._exit(4)
        self.last_clock = now

    def on_odometry(self, odometry) -> None:
        stamp = nanoseconds(odometry.header.stamp)
        if stamp <= self.last_odometry:
            os._exit(4)
        self.last_odometry = stamp
        super().on_odometry(odometry)


def main() -> None:
    rclpy.init()
    node = ClockChecking()
    spin(node)


if __name__ == "__main__":
    main()
