"""Scripted humans for the tests: small policies that steer the human by its pose."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from hazardhunt.sim.simulation import EpisodeResult, Simulation

Policy = Callable[[Simulation], tuple[float, float]]
"""Maps the simulation's state to the human's (speed m/s, turn rate rad/s)."""


def to_action(sim: Simulation, speed: float, turn_rate: float) -> np.ndarray:
    """SPEC units to the normalised action."""
    human = sim.human_params
    return np.array(
        [2.0 * speed / human.max_speed - 1.0, turn_rate / human.max_turn_rate], dtype=np.float32
    )


def run(sim: Simulation, policy: Policy) -> EpisodeResult:
    """Play one episode through the simulation's own loop, with its trajectory."""
    return sim.simulate(lambda state: to_action(state, *policy(state)))


def steer_towards(
    sim: Simulation, target: tuple[float, float], speed: float
) -> tuple[float, float]:
    """Turn towards ``target`` as fast as allowed over one decision period, walking at ``speed``."""
    x, y, heading = sim.human_pose
    error = math.atan2(target[1] - y, target[0] - x) - heading
    error = math.atan2(math.sin(error), math.cos(error))
    limit = sim.human_params.max_turn_rate
    return speed, float(np.clip(error / sim.decision_period, -limit, limit))


def stand_still(sim: Simulation) -> tuple[float, float]:
    return 0.0, 0.0


def keep_heading(sim: Simulation, heading: float, speed: float) -> tuple[float, float]:
    """Turn towards the world ``heading`` (rad) as fast as allowed, walking at ``speed``."""
    error = heading - sim.human_pose[2]
    error = math.atan2(math.sin(error), math.cos(error))
    limit = sim.human_params.max_turn_rate
    return speed, float(np.clip(error / sim.decision_period, -limit, limit))


def walk_to(sim: Simulation, target: tuple[float, float]) -> tuple[float, float]:
    """Head for ``target``, slowing down so as not to overshoot it within one decision period."""
    x, y, _ = sim.human_pose
    distance = math.hypot(target[0] - x, target[1] - y)
    _, turn_rate = steer_towards(sim, target, sim.human_params.max_speed)
    return min(sim.human_params.max_speed, distance / sim.decision_period), turn_rate


def lie_in_wait(
    spot: tuple[float, float],
    facing: float,
    trigger: Callable[[Simulation], bool],
    attack: Policy,
) -> Policy:
    """Walk to ``spot`` and wait there facing ``facing`` (rad); from the first decision at which
    ``trigger`` holds, play ``attack`` for the rest of the episode."""
    attacking = False

    def policy(sim: Simulation) -> tuple[float, float]:
        nonlocal attacking
        attacking = attacking or trigger(sim)
        if attacking:
            return attack(sim)
        x, y, _ = sim.human_pose
        if math.hypot(spot[0] - x, spot[1] - y) > 0.01:
            return walk_to(sim, spot)
        return keep_heading(sim, facing, 0.0)

    return policy


def intercept(sim: Simulation, speed: float, offset: float = 0.0) -> tuple[float, float]:
    """Head at ``speed`` for where the robot's centre, shifted ``offset`` m along its heading
    (+0.32 its front, -0.32 its rear), will be when the human gets there."""
    robot = sim.robot
    x, y, _ = sim.human_pose
    cos_h, sin_h = math.cos(robot.heading), math.sin(robot.heading)
    target_x, target_y, lead_time = robot.x, robot.y, 0.0
    for _ in range(5):  # a few fixed-point steps of "where will it be when I arrive"
        ahead = offset + robot.speed * lead_time
        target_x, target_y = robot.x + ahead * cos_h, robot.y + ahead * sin_h
        lead_time = math.hypot(target_x - x, target_y - y) / speed
    return steer_towards(sim, (target_x, target_y), speed)
