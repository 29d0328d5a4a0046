"""A controller or safety layer that fails, raises, returns something unusable or hangs
becomes a recorded outcome, never a crash; periods that cannot work are one-line errors."""

import contextlib
import signal
import threading
import time

import numpy as np
import pytest

from hazardhunt.sim.simulation import PeriodError, Simulation
from hazardhunt.sut.protocols import ControlCommand, SafetyStatus
from hazardhunt.sut.pursuit import PursuitController, PursuitParams
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


def far_away_human(controller=None, **kwargs):
    """A human standing far from the robot's route: the pursuit controller reaches its goal."""
    return Simulation.build(
        "crossing",
        "none",
        controller=controller or PursuitController(),
        decision_period=0.2,
        **kwargs,
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


# --- a SUT that raises, returns something unusable or hangs: one sut_error episode, then clean

NAN = float("nan")

UNUSABLE_COMMANDS = {
    "a string": (
        "go",
        "UnusableReturnError: control() returned a str ('go'), not a ControlCommand",
    ),
    "None": (None, "UnusableReturnError: control() returned None, not a ControlCommand"),
    "a tuple": ((0.5, 0.0), "returned a tuple ((0.5, 0.0)), not a ControlCommand"),
    "a NaN speed": (ControlCommand(NAN, 0.0), "returned a non-finite command (speed nan"),
    "an infinite turn rate": (
        ControlCommand(0.5, float("inf")),
        "returned a non-finite command (speed 0.5, yaw_rate inf)",
    ),
    "a speed in words": (ControlCommand("fast", 0.0), "whose speed is a str ('fast')"),  # type: ignore[arg-type]
    "a prediction that is no points": (
        ControlCommand(0.5, 0.0, predicted_human="there"),  # type: ignore[arg-type]
        "whose predicted_human is a str ('there'), not None or an array of (x, y) rows",
    ),
}


class FaultyInFirstEpisode:
    """A pursuit controller that, in its first episode only, returns ``returned`` (or calls
    ``hang``) from 1 s on, or raises in ``reset`` when ``returned`` is an exception (fault
    injection)."""

    control_period = 0.2

    def __init__(self, returned=None, hang=None):
        self.inner, self.returned, self.hang = PursuitController(), returned, hang
        self.resets = 0

    def reset(self, floor, route, robot, params):
        self.resets += 1
        self.inner.reset(floor, route, robot, params)
        if self.resets == 1 and isinstance(self.returned, Exception):
            raise self.returned

    def control(self, time, robot, human):
        command = self.inner.control(time, robot, human)
        if self.resets == 1 and time >= 1.0:
            if self.hang is None:
                return self.returned
            self.hang()
        return command


def hang():
    time.sleep(5.0)


def hang_catching_everything():
    with contextlib.suppress(BaseException):
        time.sleep(5.0)


class FaultySafetyLayer:
    """A safety layer that never stops the robot and, in its first episode only, returns
    ``returned`` from 1 s on, or raises (in ``reset`` when ``in_reset``)."""

    def __init__(self, returned, in_reset=False):
        self.returned, self.in_reset, self.resets = returned, in_reset, 0

    def reset(self):
        self.resets += 1
        if self.resets == 1 and self.in_reset:
            raise self.returned

    def update(self, time, robot, human_position, radius):
        if self.resets == 1 and time >= 1.0 and not self.in_reset:
            if isinstance(self.returned, Exception):
                raise self.returned
            return self.returned
        return SafetyStatus(emergency_stop=False, human_in_field=False)


def first_and_second_episode(**parts):
    """Two episodes of a standing human on one simulation, and the episode a sound SUT plays."""
    sim = far_away_human(**parts)
    first, second = run(sim, stand_still), run(sim, stand_still)
    return first, second, run(far_away_human(), stand_still)


@pytest.mark.parametrize("fault", list(UNUSABLE_COMMANDS))
def test_a_controller_returning_something_unusable_ends_the_episode_as_sut_error(fault):
    returned, message = UNUSABLE_COMMANDS[fault]
    first, second, sound = first_and_second_episode(controller=FaultyInFirstEpisode(returned))
    assert first.outcome == "sut_error"
    assert first.summary.sim_time == pytest.approx(1.05)
    [error] = first.summary.controller_errors
    assert message in error
    assert first.trajectory[-1].controller_status == "unusable return"
    # The next episode starts clean: as if the fault had never happened.
    assert second.summary == sound.summary
    assert second.outcome == "goal"


def test_a_controller_whose_reset_raises_ends_the_episode_at_once():
    controller = FaultyInFirstEpisode(RuntimeError("no map"))
    first, second, sound = first_and_second_episode(controller=controller)
    assert first.outcome == "sut_error"
    assert first.summary.sim_time == pytest.approx(0.05)
    assert first.summary.controller_errors == ("reset() raised RuntimeError: no map",)
    assert first.summary.controller_calls == 0
    assert first.trajectory[-1].controller_status == "reset raised RuntimeError"
    assert second.summary == sound.summary


@pytest.mark.parametrize(
    ("layer", "message"),
    [
        (FaultySafetyLayer(OSError("scanner offline")), "OSError: scanner offline"),
        (
            FaultySafetyLayer(None),
            "UnusableReturnError: update() returned None, not a SafetyStatus",
        ),
        (
            FaultySafetyLayer((True, False)),
            "UnusableReturnError: update() returned a tuple ((True, False)), not a SafetyStatus",
        ),
        (
            FaultySafetyLayer(SafetyStatus("stop", False)),  # type: ignore[arg-type]
            "UnusableReturnError: update() returned a SafetyStatus of a str ('stop') and a bool "
            "(False), not two bools",
        ),
        (
            FaultySafetyLayer(OSError("no scanner"), in_reset=True),
            "reset() raised OSError: no scanner",
        ),
    ],
)
def test_a_safety_layer_that_raises_or_returns_something_unusable_ends_as_sut_error(layer, message):
    first, second, sound = first_and_second_episode(safety_layer=layer)
    assert first.outcome == "sut_error"
    assert first.summary.sim_time == pytest.approx(0.05 if layer.in_reset else 1.05)
    assert first.summary.safety_layer_errors == (message,)
    assert first.summary.controller_errors == ()
    assert second.summary == sound.summary


@pytest.mark.parametrize("period", [0.07, 0.12])
def test_a_controller_period_off_the_physics_step_is_a_one_line_error(period):
    controller = PursuitController(PursuitParams(control_period=period))
    with pytest.raises(PeriodError) as error:
        far_away_human(controller)
    assert str(error.value).startswith(
        f"the controller's control_period ({period:g} s) must be a multiple of the physics step "
        "(0.05 s), e.g. "
    )
    assert "\n" not in str(error.value)


@pytest.mark.parametrize(
    ("decision_period", "message"),
    [
        (0.3, "decision_period (0.3 s) must be a multiple of the controller's control_period "
         "(0.2 s), e.g. 0.2 s or 0.4 s"),
        (0.07, "decision_period (0.07 s) must be a multiple of the controller's control_period "
         "(0.2 s), e.g. 0.2 s"),
        (float("inf"), "decision_period must be a positive, finite number of seconds, not inf"),
        (float("nan"), "decision_period must be a positive, finite number of seconds, not nan"),
        (-2.0, "decision_period must be a positive, finite number of seconds, not -2.0"),
        # An episode of one decision would have sized arrays of the decision's physics steps.
        (1e9, "decision_period (1e+09 s) must be at most the episode's duration (30 s)"),
    ],
)  # fmt: skip
def test_a_decision_period_that_cannot_work_is_a_one_line_error(decision_period, message):
    with pytest.raises(PeriodError) as error:
        Simulation.build(
            "crossing", "none", decision_period=decision_period, controller=PursuitController()
        )
    assert str(error.value) == message


@pytest.mark.parametrize("stuck", [hang, hang_catching_everything])
def test_a_controller_that_hangs_past_the_time_limit_ends_the_episode_as_sut_error(stuck):
    handler = signal.getsignal(signal.SIGALRM)
    first, second, sound = first_and_second_episode(
        controller=FaultyInFirstEpisode(hang=stuck), controller_timeout=0.2
    )
    assert first.outcome == "sut_error"
    assert first.summary.sim_time == pytest.approx(1.05)
    assert first.summary.controller_errors == (
        "TimeLimitError: control() took longer than its time limit of 0.2 s",
    )
    assert first.trajectory[-1].controller_status == "time limit exceeded"
    assert second.summary == sound.summary
    # Nothing is left armed behind the simulation's back.
    assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)
    assert signal.getsignal(signal.SIGALRM) is handler


class HangingSafetyLayer(FaultySafetyLayer):
    """A safety layer that, in its first episode only, hangs in ``update`` from 1 s on."""

    def __init__(self):
        super().__init__(returned=None)

    def update(self, time, robot, human_position, radius):
        if self.resets == 1 and time >= 1.0:
            hang()
        return SafetyStatus(emergency_stop=False, human_in_field=False)


def test_a_safety_layer_that_hangs_past_the_time_limit_ends_the_episode_as_sut_error():
    first, second, sound = first_and_second_episode(
        safety_layer=HangingSafetyLayer(), controller_timeout=0.2
    )
    assert first.outcome == "sut_error"
    assert first.summary.sim_time == pytest.approx(1.05)
    assert first.summary.safety_layer_errors == (
        "TimeLimitError: update() took longer than its time limit of 0.2 s",
    )
    assert second.summary == sound.summary
    assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)


def test_outside_the_main_thread_the_time_limit_gives_way_with_a_warning():
    calls = []

    def slow_once():
        if not calls:
            time.sleep(0.3)
        calls.append(1)

    def in_a_thread(sim):
        results = []
        thread = threading.Thread(target=lambda: results.append(run(sim, stand_still)))
        thread.start()
        thread.join()
        return results[0]

    sim = far_away_human(FaultyInFirstEpisode(hang=slow_once), controller_timeout=0.1)
    with pytest.warns(RuntimeWarning, match="only in a process's main thread"):
        result = in_a_thread(sim)
    assert result.outcome == "goal"


@pytest.mark.parametrize("seconds", [0, -1.0, float("inf"), float("nan")])
def test_a_time_limit_is_a_positive_number_of_seconds(seconds):
    with pytest.raises(ValueError, match="controller_timeout must be a positive number"):
        far_away_human(controller_timeout=seconds)
