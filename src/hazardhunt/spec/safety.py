"""The safety specification Phi: which contacts are the robot's fault (SPEC 4)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

import numpy as np

from hazardhunt.world.geometry import FloatArray


class ContactVerdict(str, Enum):
    """How a step's human-robot contact is judged."""

    NONE = "none"
    """No contact."""
    UNSAFE = "unsafe"
    """A contact the robot is responsible for: a failure."""
    ROBOT_STANDING = "robot_standing"
    """Exception (i): the human walked into the standing robot."""
    HUMAN_FROM_BEHIND = "human_from_behind"
    """Exception (ii): the human ran into the moving robot's rear face, faster than it."""


@dataclass(frozen=True)
class SafetySpecParams:
    """Thresholds of the safety specification."""

    standstill_speed: float = 0.05
    """Below this speed the robot counts as standing still, in m/s."""


def judge_contact(
    contact: bool,
    contact_face: str,
    robot_speed: float,
    robot_heading: float,
    human_velocity: FloatArray,
    params: SafetySpecParams = SafetySpecParams(),
) -> ContactVerdict:
    """Judge a step's contact against Phi and its two exceptions.

    Args:
        contact: Whether the human disc and the robot rectangle overlap.
        contact_face: Face of the robot nearest the human (``front``, ``rear``, ``left``,
            ``right``).
        robot_speed: Robot forward speed, in m/s.
        robot_heading: Robot heading, in rad.
        human_velocity: Human velocity (vx, vy), in m/s.
        params: Thresholds.
    """
    if not contact:
        return ContactVerdict.NONE
    if abs(robot_speed) < params.standstill_speed:
        return ContactVerdict.ROBOT_STANDING
    along_heading = float(
        np.dot(human_velocity, (math.cos(robot_heading), math.sin(robot_heading)))
    )
    if contact_face == "rear" and along_heading > robot_speed:
        return ContactVerdict.HUMAN_FROM_BEHIND
    return ContactVerdict.UNSAFE
