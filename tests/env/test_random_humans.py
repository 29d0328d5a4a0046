"""Random humans in every scenario and field setting: the simulation's invariants hold."""

import numpy as np
import pytest

from hazardhunt.sim.simulation import Simulation
from hazardhunt.sut.nmpc import NMPCController
from hazardhunt.sut.safety_layer import FIELD_SETTINGS
from hazardhunt.world.scenario import BUILTIN_SCENARIOS

OUTCOMES = {"goal", "failure", "safe_contact", "timeout", "stall", "sut_error"}


@pytest.mark.slow
@pytest.mark.parametrize("field", list(FIELD_SETTINGS))
@pytest.mark.parametrize("scenario", BUILTIN_SCENARIOS)
def test_random_humans_never_break_the_simulation(scenario, field):
    sim = Simulation.build(scenario, field, decision_period=0.4, controller=NMPCController())
    rng = np.random.default_rng(42)
    floor, robot = sim.scenario.floor, sim.robot_params
    for _ in range(6):
        result = sim.simulate(lambda _: rng.uniform(-1, 1, 2))
        assert result.outcome in OUTCOMES
        assert result.summary.controller_errors == ()
        assert result.outcome != "sut_error"
        for row in result.trajectory:
            human = np.array([row.human_x, row.human_y])
            assert floor.obstacle_clearance(human) >= sim.human_params.radius - 1e-9
            assert 0.0 <= row.robot_speed <= robot.max_speed + 1e-12
            assert abs(row.robot_yaw_rate) <= robot.max_yaw_rate + 1e-12
        if field == "none":
            assert result.summary.emergency_stops == 0
