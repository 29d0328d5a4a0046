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
