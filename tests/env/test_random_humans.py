"""Random humans in every scenario and field setting: the simulation's invariants hold."""

import numpy as np
import pytest

from hazardhunt.env.agv import AGVEnv
from hazardhunt.sut.nmpc import NMPCController
from hazardhunt.sut.safety_layer import FIELD_SETTINGS
from hazardhunt.world.scenario import BUILTIN_SCENARIOS

OUTCOMES = {"goal", "failure", "safe_contact", "timeout", "stall", "sut_error"}


@pytest.mark.slow
@pytest.mark.parametrize("field", list(FIELD_SETTINGS))
@pytest.mark.parametrize("scenario", BUILTIN_SCENARIOS)
def test_random_humans_never_break_the_simulation(scenario, field):
    env = AGVEnv(scenario, field, controller=NMPCController(), decision_period=0.4)
    rng = np.random.default_rng(42)
    floor, robot = env.scenario.floor, env.robot_params
    for episode in range(6):
        env.reset(seed=episode)
        done = False
        while not done:
            _, _, terminated, truncated, info = env.step(rng.uniform(-1, 1, 2).astype(np.float32))
            done = terminated or truncated
        assert info["outcome"] in OUTCOMES
        assert info["summary"]["controller_errors"] == []
        assert info["outcome"] != "sut_error"
        for row in env.trajectory():
            human = np.array([row["human_x"], row["human_y"]])
            assert floor.obstacle_clearance(human) >= env.human_params.radius - 1e-9
            assert 0.0 <= row["robot_speed"] <= robot.max_speed + 1e-12
            assert abs(row["robot_yaw_rate"]) <= robot.max_yaw_rate + 1e-12
        if field == "none":
            assert info["estop_count"] == 0
