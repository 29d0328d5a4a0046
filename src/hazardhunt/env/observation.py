"""The observation a learning tester sees: the study's features plus a few more, in [-1, 1]."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

OBSERVATION_FEATURES: tuple[str, ...] = (
    "human_x",
    "human_y",
    "human_heading_cos",
    "human_heading_sin",
    "human_visible",
    "human_speed",
    "robot_x",
    "robot_y",
    "robot_heading_cos",
    "robot_heading_sin",
    "robot_speed",
    "emergency_stop",
    "contact",
    "human_in_field",
    "human_forward_of_robot",
    "human_left_of_robot",
    "clearance",
    "elapsed_time",
    "robot_yaw_rate",
    "route_progress",
)
"""Names of the observation's entries, in order. Positions are scaled from the floor's extent to
[-1, 1]; speeds by their maxima; flags are 0 or 1; the human's position in the robot's frame and
the clearance are divided by ``RELATIVE_SCALE`` and clipped; elapsed time and route progress are
fractions of the episode duration and the route length."""

RELATIVE_SCALE = 10.0
"""Distances relative to the robot are divided by this, in m, before clipping to [-1, 1]."""


def encode_observation(
    *,
    floor_size: tuple[float, float],
    human_position: NDArray[np.float64],
    human_heading: float,
    human_visible: bool,
    human_speed: float,
    human_max_speed: float,
    robot_pose: tuple[float, float, float],
    robot_speed: float,
    robot_max_speed: float,
    robot_yaw_rate: float,
    robot_max_yaw_rate: float,
    emergency_stop: bool,
    contact: bool,
    human_in_field: bool,
    clearance: float,
    elapsed_fraction: float,
    route_fraction: float,
) -> NDArray[np.float32]:
    """Pack the state into the observation vector described by ``OBSERVATION_FEATURES``."""
    width, height = floor_size
    robot_x, robot_y, robot_heading = robot_pose
    cos_r, sin_r = math.cos(robot_heading), math.sin(robot_heading)
    dx, dy = human_position[0] - robot_x, human_position[1] - robot_y
    values = (
        2.0 * human_position[0] / width - 1.0,
        2.0 * human_position[1] / height - 1.0,
        math.cos(human_heading),
        math.sin(human_heading),
        float(human_visible),
        human_speed / human_max_speed,
        2.0 * robot_x / width - 1.0,
        2.0 * robot_y / height - 1.0,
        cos_r,
        sin_r,
        robot_speed / robot_max_speed,
        float(emergency_stop),
        float(contact),
        float(human_in_field),
        (cos_r * dx + sin_r * dy) / RELATIVE_SCALE,
        (-sin_r * dx + cos_r * dy) / RELATIVE_SCALE,
        clearance / RELATIVE_SCALE,
        elapsed_fraction,
        robot_yaw_rate / robot_max_yaw_rate,
        route_fraction,
    )
    return np.clip(np.array(values, dtype=np.float32), -1.0, 1.0)
