"""Scripted humans for the tests: small policies that steer the human by its pose."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from hazardhunt.env.agv import AGVEnv

Policy = Callable[[AGVEnv], tuple[float, float]]
"""Maps the env's state to the human's (speed m/s, turn rate rad/s)."""


def to_action(env: AGVEnv, speed: float, turn_rate: float) -> np.ndarray:
    """SPEC units to the env's normalised action."""
    human = env.human_params
    return np.array(
        [2.0 * speed / human.max_speed - 1.0, turn_rate / human.max_turn_rate], dtype=np.float32
    )


def steer_towards(env: AGVEnv, target: tuple[float, float], speed: float) -> tuple[float, float]:
    """Turn towards ``target`` as fast as allowed over one decision period, walking at ``speed``."""
    x, y, heading = env.human_pose
    error = math.atan2(target[1] - y, target[0] - x) - heading
    error = math.atan2(math.sin(error), math.cos(error))
    limit = env.human_params.max_turn_rate
    return speed, float(np.clip(error / env.decision_period, -limit, limit))


def run(env: AGVEnv, policy: Policy, seed: int = 0) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Play one episode; returns the last info and every step's info."""
    env.reset(seed=seed)
    infos = []
    while True:
        speed, turn_rate = policy(env)
        _, _, terminated, truncated, info = env.step(to_action(env, speed, turn_rate))
        infos.append(info)
        if terminated or truncated:
            return info, infos


def stand_still(env: AGVEnv) -> tuple[float, float]:
    return 0.0, 0.0


def keep_heading(env: AGVEnv, heading: float, speed: float) -> tuple[float, float]:
    """Turn towards the world ``heading`` (rad) as fast as allowed, walking at ``speed``."""
    error = heading - env.human_pose[2]
    error = math.atan2(math.sin(error), math.cos(error))
    limit = env.human_params.max_turn_rate
    return speed, float(np.clip(error / env.decision_period, -limit, limit))


def walk_to(env: AGVEnv, target: tuple[float, float]) -> tuple[float, float]:
    """Head for ``target``, slowing down so as not to overshoot it within one decision period."""
    x, y, _ = env.human_pose
    distance = math.hypot(target[0] - x, target[1] - y)
    _, turn_rate = steer_towards(env, target, env.human_params.max_speed)
    return min(env.human_params.max_speed, distance / env.decision_period), turn_rate


def lie_in_wait(
    spot: tuple[float, float],
    facing: float,
    trigger: Callable[[AGVEnv], bool],
    attack: Policy,
) -> Policy:
    """Walk to ``spot`` and wait there facing ``facing`` (rad); from the first decision at which
    ``trigger`` holds, play ``attack`` for the rest of the episode."""
    attacking = False

    def policy(env: AGVEnv) -> tuple[float, float]:
        nonlocal attacking
        attacking = attacking or trigger(env)
        if attacking:
            return attack(env)
        x, y, _ = env.human_pose
        if math.hypot(spot[0] - x, spot[1] - y) > 0.01:
            return walk_to(env, spot)
        return keep_heading(env, facing, 0.0)

    return policy
