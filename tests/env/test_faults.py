"""A controller that fails or raises becomes a recorded outcome, never a crash."""

import numpy as np
import pytest

from hazardhunt.sim.simulation import Simulation
from hazardhunt.sut.protocols import ControlCommand
from hazardhunt.sut.pursuit import PursuitController
from tests.scripted import run, stand_still


class FailingAfter:
    """Wraps a real controller; from ``start`` s on, its solver 'fails' (fault injection)."""

    def __init__(self, controller, start, stop=float("inf"), raise_error=False):
        self.inner, self.start, self.stop, self.raise_error = controller, start, stop, raise_error
        self.control_period = controller.control_period

    def reset(self, floor, route, robot, params):
        self.inner.reset(floor, route, robot, params)

    def control(self, time, robot, human):
        command = self.inner.control(time, robot, human)
        if self.start <= time < self.stop:
            if self.raise_error:
                raise RuntimeError("controller crashed")
            return ControlCommand(speed=1.0, yaw_rate=0.0, failed=True, status="Infeasible")
        return command


def far_away_human(controller, **kwargs):
    return Simulation.build(
        "crossing", "none", controller=controller, decision_period=0.2, **kwargs
    )


def test_a_short_solver_failure_brakes_and_the_episode_goes_on():
    sim = far_away_human(FailingAfter(PursuitController(), start=3.0, stop=3.6))
    result = run(sim, stand_still)
    assert result.outcome == "goal"
    rows = sim.trajectory()
    failed = [row for row in rows if row.controller_failed]
    assert [round(row.time, 2) for row in failed] == [3.0, 3.2, 3.4]
    assert {row.controller_status for row in failed} == {"Infeasible"}
    speeds = {round(row.time, 2): row.robot_speed for row in rows}
    # The failed commands brake at 1 m/s^2 despite asking for 1 m/s.
    assert speeds[3.6] == pytest.approx(speeds[3.0] - 0.6, abs=1e-9)
    assert result.summary.controller_failures == 3


def test_a_persistent_solver_failure_ends_as_sut_error():
    sim = far_away_human(FailingAfter(PursuitController(), start=2.0), max_failed_commands=5)
    result = run(sim, stand_still)
    assert result.outcome == "sut_error"
    assert result.summary.sim_time == pytest.approx(2.8 + 0.05)


def test_a_controller_that_raises_ends_as_sut_error_with_the_error_recorded():
    sim = far_away_human(FailingAfter(PursuitController(), start=1.0, raise_error=True))
    result = run(sim, stand_still)
    assert result.outcome == "sut_error"
    assert list(result.summary.controller_errors) == ["RuntimeError: controller crashed"]
    assert sim.trajectory()[-1].controller_status == "raised RuntimeError"


def test_stepping_after_the_end_asks_for_a_reset():
    sim = far_away_human(PursuitController())
    run(sim, stand_still)
    with pytest.raises(RuntimeError, match="call reset"):
        sim.decide(np.zeros(2, dtype=np.float32))
