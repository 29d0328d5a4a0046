"""The risk metric of the study (paper Eq. 6), evaluated at every physics step."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class RiskParams:
    """Constants of the risk metric."""

    collision_risk: float = 100.0
    """Base risk of an unsafe contact; the speeds can double it."""
    max_human_speed: float = 1.5
    """Normalises the human speed, in m/s."""
    max_robot_speed: float = 1.2
    """Normalises the robot speed, in m/s."""
    moving_speed: float = 0.1
    """The proximity term counts only while the robot is faster than this, in m/s."""


def risk(
    unsafe_contact: bool,
    contact: bool,
    human_speed: float,
    robot_speed: float,
    clearance: float,
    params: RiskParams = RiskParams(),
) -> float:
    """Risk at one physics step.

    ``collision_risk * (1 + v_H v_R / (v_H,max v_R,max))`` on an unsafe contact;
    ``exp(-clearance)`` when there is no contact and the robot moves faster than
    ``moving_speed``; 0 otherwise (a safe contact included).

    Args:
        unsafe_contact: The step's contact violates the safety specification.
        contact: Human and robot touch.
        human_speed: in m/s.
        robot_speed: in m/s.
        clearance: Gap between the human disc and the robot rectangle, in m.
        params: Constants.
    """
    if unsafe_contact:
        scale = params.max_human_speed * params.max_robot_speed
        return params.collision_risk * (1.0 + human_speed * robot_speed / scale)
    if not contact and robot_speed > params.moving_speed:
        return math.exp(-clearance)
    return 0.0
