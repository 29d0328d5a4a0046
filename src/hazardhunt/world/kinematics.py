"""Unicycle kinematics of the human and the robot over one physics step (pure functions)."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from hazardhunt.world.bodies import RobotParams, RobotState
from hazardhunt.world.floor import FloorMap


class HumanStep(NamedTuple):
    """The human after one physics step, on Python floats (what the simulation's loop keeps)."""

    x: float
    """m"""
    y: float
    """m"""
    heading: float
    """rad"""
    velocity_x: float
    """Actual velocity over the step (zero when blocked), in m/s."""
    velocity_y: float
    """m/s"""
    blocked: bool
    """True when an obstacle shortened the step."""


def move_human(
    x: float,
    y: float,
    heading: float,
    speed: float,
    turn_rate: float,
    dt: float,
    floor: FloorMap,
    radius: float,
) -> HumanStep:
    """Move the human disc at (x, y) for ``dt`` seconds; walls and shelves block it.

    At contact the human slides along the obstacle (the part of the step that points into it is
    removed); where sliding is blocked too (a corner), it stops. It never passes through. On
    floats: no arrays unless an obstacle blocks the step.
    """
    new_heading = heading + turn_rate * dt
    mid_heading = heading + 0.5 * turn_rate * dt
    distance = speed * dt
    step_x, step_y = distance * math.cos(mid_heading), distance * math.sin(mid_heading)
    target_x, target_y = x + step_x, y + step_y
    if not floor.disc_blocked_at(target_x, target_y, radius):
        return HumanStep(target_x, target_y, new_heading, step_x / dt, step_y / dt, False)
    position = np.array([x, y])
    step = np.array([step_x, step_y])
    nearest = floor.nearest_obstacle_point(position)
    away = position - nearest
    norm = float(np.hypot(*away))
    if norm > 1e-12:
        normal = away / norm
        slide = step - min(float(np.dot(step, normal)), 0.0) * normal
        target = position + slide
        if not floor.disc_blocked(target, radius):
            (target_x, target_y), (velocity_x, velocity_y) = target.tolist(), (slide / dt).tolist()
            return HumanStep(target_x, target_y, new_heading, velocity_x, velocity_y, True)
    return HumanStep(x, y, new_heading, 0.0, 0.0, True)


def step_robot(
    state: RobotState,
    commanded_speed: float,
    commanded_yaw_rate: float,
    dt: float,
    params: RobotParams,
    emergency_stop: bool = False,
) -> RobotState:
    """Advance the robot for ``dt`` seconds towards the commanded speeds.

    The speeds move towards the command no faster than the acceleration limits allow and stay
    within their bounds. Under an emergency stop the robot brakes at the emergency deceleration
    and stops turning at once. Position and heading integrate the mean speeds of the step (exact
    for straight motion under constant acceleration).
    """
    speed, yaw_rate, heading = state.speed, state.yaw_rate, state.heading
    if emergency_stop:
        new_speed = max(speed - params.emergency_deceleration * dt, 0.0)
        new_yaw_rate = 0.0
    else:
        speed_step = params.max_acceleration * dt
        yaw_step = params.max_yaw_acceleration * dt
        new_speed = speed + min(max(commanded_speed - speed, -speed_step), speed_step)
        new_speed = min(max(new_speed, 0.0), params.max_speed)
        new_yaw_rate = yaw_rate + min(max(commanded_yaw_rate - yaw_rate, -yaw_step), yaw_step)
        new_yaw_rate = min(max(new_yaw_rate, -params.max_yaw_rate), params.max_yaw_rate)
    mean_speed = 0.5 * (speed + new_speed)
    mean_yaw_rate = 0.5 * (yaw_rate + new_yaw_rate)
    mid_heading = heading + 0.5 * mean_yaw_rate * dt
    return RobotState(
        x=state.x + mean_speed * dt * math.cos(mid_heading),
        y=state.y + mean_speed * dt * math.sin(mid_heading),
        heading=heading + mean_yaw_rate * dt,
        speed=new_speed,
        yaw_rate=new_yaw_rate,
    )
