"""The NMPC planner in closed loop with a simple robot simulation, with real CasADi solvers."""

from __future__ import annotations

import math
import pickle
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np
import pytest

from hazardhunt.sut.nmpc import NMPCController, NMPCParams
from hazardhunt.sut.protocols import ControlCommand, Controller, RobotState, TrackedHuman
from hazardhunt.sut.route import Route, plan_route
from hazardhunt.world.bodies import HumanParams, RobotParams
from hazardhunt.world.floor import FloorMap
from hazardhunt.world.scenario import Scenario, load_scenario

ROBOT = RobotParams()
HUMAN = HumanParams()
PHYSICS_STEP = 0.05
CONTACT_DISTANCE = ROBOT.half_diagonal + HUMAN.radius
"""Robot centre to human centre below which the bodies may touch, in m."""


@dataclass
class Trace:
    """What a closed-loop drive did."""

    positions: list[np.ndarray] = field(default_factory=list)
    commands: list[ControlCommand] = field(default_factory=list)
    arrival_time: float | None = None
    final: RobotState | None = None


def step_robot(state: RobotState, command: ControlCommand, dt: float) -> RobotState:
    """Unicycle whose speeds move towards the command within the acceleration limits."""
    speed_step, yaw_step = ROBOT.max_acceleration * dt, ROBOT.max_yaw_acceleration * dt
    speed = state.speed + float(np.clip(command.speed - state.speed, -speed_step, speed_step))
    yaw_rate = state.yaw_rate + float(
        np.clip(command.yaw_rate - state.yaw_rate, -yaw_step, yaw_step)
    )
    mean_speed, mean_yaw_rate = 0.5 * (state.speed + speed), 0.5 * (state.yaw_rate + yaw_rate)
    mid_heading = state.heading + 0.5 * mean_yaw_rate * dt
    return RobotState(
        x=state.x + mean_speed * dt * math.cos(mid_heading),
        y=state.y + mean_speed * dt * math.sin(mid_heading),
        heading=state.heading + mean_yaw_rate * dt,
        speed=speed,
        yaw_rate=yaw_rate,
    )


def standing_human(position: np.ndarray, time: float) -> TrackedHuman:
    return walking_human(lambda _: position, time)


def walking_human(path: Callable[[float], np.ndarray], time: float) -> TrackedHuman:
    """The tracker's report at ``time`` of a human moving along ``path(t)``."""
    times = np.array([time - 0.4, time - 0.2, time])
    positions = np.array([path(t) for t in times])
    return TrackedHuman(time, positions[-1], 0.0, positions, times)


def drive(
    controller: NMPCController,
    floor: FloorMap,
    route: Route,
    start: RobotState,
    human_at: np.ndarray | None = None,
    duration: float = 30.0,
) -> Trace:
    """Run the controller every 0.2 s on 0.05 s physics steps until the goal or ``duration``."""
    controller.reset(floor, route, start, RobotParams())
    state, time, trace = start, 0.0, Trace()
    substeps = round(controller.control_period / PHYSICS_STEP)
    while time < duration:
        human = None if human_at is None else standing_human(human_at, time)
        command = controller.control(time, state, human)
        trace.commands.append(command)
        for _ in range(substeps):
            state = step_robot(state, command, PHYSICS_STEP)
            trace.positions.append(np.array([state.x, state.y]))
        time += controller.control_period
        if math.hypot(state.x - route.goal[0], state.y - route.goal[1]) <= ROBOT.goal_tolerance:
            trace.arrival_time = time
            break
    trace.final = state
    return trace


def start_of(scenario: Scenario) -> RobotState:
    pose = scenario.robot_start
    return RobotState(pose.x, pose.y, pose.heading, 0.0, 0.0)


def distances_to_route(route: Route, positions: list[np.ndarray]) -> np.ndarray:
    return np.array([np.hypot(*(route.point_at(route.project(p)) - p)) for p in positions])


@pytest.fixture(scope="module")
def crossing() -> Scenario:
    return load_scenario("crossing")


@pytest.fixture(scope="module")
def crossing_route(crossing: Scenario) -> Route:
    return plan_route(
        crossing.floor, crossing.robot_start.position, crossing.waypoints, crossing.goal, 0.5
    )


@pytest.fixture(scope="module")
def fatrop_controller() -> NMPCController:
    return NMPCController(NMPCParams(solver="fatrop"))


@pytest.fixture(scope="module")
def ipopt_controller() -> NMPCController:
    return NMPCController(NMPCParams(solver="ipopt"))


@pytest.mark.parametrize(
    "change",
    [
        {"horizon": 0},
        {"sample_time": 0.0},
        {"obstacle_slots": -1},
        {"solver": "sqp"},
        {"barrier_decrease_power": 2.0},
    ],
)
def test_rejects_meaningless_parameters(change: dict[str, Any]) -> None:
    with pytest.raises(ValueError, match=next(iter(change))):
        NMPCParams(**change)


def test_is_a_controller_called_every_sample_time(fatrop_controller: NMPCController) -> None:
    assert isinstance(fatrop_controller, Controller)
    assert fatrop_controller.control_period == pytest.approx(0.2)


@pytest.mark.parametrize("solver", ["fatrop", "ipopt"])
def test_drives_the_crossing_route_to_the_goal(
    solver: str, crossing: Scenario, crossing_route: Route, request: pytest.FixtureRequest
) -> None:
    controller: NMPCController = request.getfixturevalue(f"{solver}_controller")

    trace = drive(controller, crossing.floor, crossing_route, start_of(crossing))

    assert trace.arrival_time is not None
    assert trace.arrival_time < 30.0
    assert np.max(distances_to_route(crossing_route, trace.positions)) < 0.3
    assert all(c.status == "ok" and not c.failed for c in trace.commands)
    for command in trace.commands:
        assert command.planned_positions is not None
        assert command.planned_positions.shape == (21, 2)
        assert command.predicted_human is None
        assert command.solve_time_s > 0.0
        assert command.extras["iterations"] >= 1
        assert 0.0 <= command.speed <= ROBOT.max_speed
        assert abs(command.yaw_rate) <= ROBOT.max_yaw_rate


def test_keeps_off_the_shelves_through_corners(
    crossing: Scenario, fatrop_controller: NMPCController
) -> None:
    # Into the narrow aisle between the south-west shelf blocks: a U-turn and two shelf corners.
    route = plan_route(
        crossing.floor, crossing.robot_start.position, np.zeros((0, 2)), np.array([5.0, 4.75]), 0.5
    )

    trace = drive(fatrop_controller, crossing.floor, route, start_of(crossing))

    assert trace.arrival_time is not None
    clearances = [crossing.floor.obstacle_clearance(p) for p in trace.positions]
    assert min(clearances) > ROBOT.width / 2 + 0.2
    assert all(not c.failed for c in trace.commands)


def test_stops_before_a_human_standing_on_the_route(
    crossing: Scenario, crossing_route: Route, fatrop_controller: NMPCController
) -> None:
    human = np.array([9.0, 10.0])  # on the route; no room to pass between shelves and keep-out

    trace = drive(
        fatrop_controller, crossing.floor, crossing_route, start_of(crossing), human, 20.0
    )

    distances = np.hypot(*(np.array(trace.positions) - human).T)
    assert distances.min() > CONTACT_DISTANCE
    assert trace.final is not None
    assert trace.final.speed < 0.05
    assert all(not c.failed for c in trace.commands)
    predicted = trace.commands[-1].predicted_human
    assert predicted is not None
    np.testing.assert_allclose(predicted, np.tile(human, (20, 1)))


def test_steers_around_a_human_who_leaves_room(
    crossing: Scenario, crossing_route: Route, fatrop_controller: NMPCController
) -> None:
    human = np.array([9.0, 10.5])

    trace = drive(fatrop_controller, crossing.floor, crossing_route, start_of(crossing), human)

    distances = np.hypot(*(np.array(trace.positions) - human).T)
    assert distances.min() > CONTACT_DISTANCE
    assert trace.arrival_time is not None
    assert np.max(distances_to_route(crossing_route, trace.positions)) > 0.3, "it left the route"
    assert all(not c.failed for c in trace.commands)


def test_a_human_walking_head_on_into_the_standing_robot_never_breaks_the_solver(
    fatrop_controller: NMPCController,
) -> None:
    # The prediction sweeps straight through the robot, which cannot back off: the keep-out is
    # violated whatever it does, symmetrically on both sides.
    scenario = load_scenario("head-on")
    route = plan_route(
        scenario.floor, scenario.robot_start.position, scenario.waypoints, scenario.goal, 0.5
    )
    robot = RobotState(6.0, 10.0, 0.0, 0.0, 0.0)
    fatrop_controller.reset(scenario.floor, route, robot, RobotParams())

    def path(t: float) -> np.ndarray:
        return np.array([9.0 - 0.8 * t, 10.0])

    for step in range(30):
        time = 0.2 * step
        command = fatrop_controller.control(time, robot, walking_human(path, time))
        assert command.status == "ok", f"at {time:.1f} s"
        assert command.speed <= ROBOT.max_acceleration * 0.2 + 1e-6
        robot = RobotState(6.0, 10.0, 0.0, 0.0, 0.0)  # held by the safety layer


def recorded_situations() -> list[tuple[RobotState, TrackedHuman | None]]:
    walking = TrackedHuman(
        time=6.0,
        position=np.array([9.5, 8.0]),
        heading=math.pi / 2,
        recent_positions=np.array([[9.5, 7.6], [9.5, 7.8], [9.5, 8.0]]),
        recent_times=np.array([5.6, 5.8, 6.0]),
    )
    return [
        (RobotState(2.0, 10.0, 0.0, 0.0, 0.0), None),
        (RobotState(6.0, 10.2, -0.1, 1.0, 0.1), None),
        (RobotState(6.5, 10.0, 0.0, 1.0, 0.0), walking),
        (RobotState(8.0, 9.8, 0.05, 0.8, -0.2), standing_human(np.array([9.5, 10.0]), 6.0)),
        (RobotState(17.2, 10.0, 0.0, 0.9, 0.0), None),
    ]


def test_fatrop_and_ipopt_agree_on_the_first_command(
    crossing: Scenario,
    crossing_route: Route,
    fatrop_controller: NMPCController,
    ipopt_controller: NMPCController,
) -> None:
    # Both solve the same problem to a KKT tolerance of 1e-6; their commands agree to 1e-3.
    for robot, human in recorded_situations():
        commands = []
        for controller in (fatrop_controller, ipopt_controller):
            controller.reset(crossing.floor, crossing_route, robot, RobotParams())
            commands.append(controller.control(6.0, robot, human))
        fatrop, ipopt = commands
        assert fatrop.status == ipopt.status == "ok"
        assert fatrop.speed == pytest.approx(ipopt.speed, abs=1e-3)
        assert fatrop.yaw_rate == pytest.approx(ipopt.yaw_rate, abs=1e-3)


class RaisingSolver:
    def __call__(self, **arguments: Any) -> dict[str, Any]:
        raise RuntimeError("injected CasADi failure")

    def solve(self, x0: Any, p: Any) -> Any:  # the compiled solver's call
        raise RuntimeError("injected solver failure")


class NaNSolver:
    """The real solver, with its solution replaced by NaN."""

    def __init__(self, solver: Any) -> None:
        self.solver = solver

    def __call__(self, **arguments: Any) -> dict[str, Any]:
        result = dict(self.solver(**arguments))
        result["x"] = ca.DM.nan(*result["x"].shape)
        return result

    def stats(self) -> dict[str, Any]:
        return dict(self.solver.stats())

    def solve(self, x0: Any, p: Any) -> Any:  # the compiled solver's call
        result = self.solver.solve(x0, p)
        result.x = np.full_like(result.x, np.nan)
        return result


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "interpreted"])
@pytest.mark.parametrize(
    ("make_solver", "status"),
    [(lambda real: RaisingSolver(), "RuntimeError"), (NaNSolver, "non-finite")],
)
def test_a_failed_solve_brakes_instead_of_raising(
    make_solver: Any,
    status: str,
    compiled: bool,
    crossing: Scenario,
    crossing_route: Route,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    controller = NMPCController(NMPCParams(compiled=compiled))
    robot = RobotState(6.0, 10.0, 0.0, 1.0, 0.2)
    controller.reset(crossing.floor, crossing_route, robot, RobotParams())
    problem = controller._problem
    if compiled:
        assert problem.compiled is not None
        faulty = tuple(make_solver(solver) for solver in problem.compiled)
        monkeypatch.setattr(problem, "compiled", faulty)
    else:
        for name in ("solver", "cold_solver"):  # warm-started and from-rollout solves
            monkeypatch.setattr(problem, name, make_solver(getattr(problem, name)))

    command = controller.control(0.0, robot, None)

    assert command.failed
    assert command.status == status
    assert command.speed == pytest.approx(1.0 - ROBOT.max_acceleration * 0.2)
    assert command.yaw_rate == 0.0
    assert command.planned_positions is not None
    assert command.planned_positions.shape == (21, 2)

    monkeypatch.undo()
    recovered = controller.control(0.2, robot, None)
    assert not recovered.failed
    assert recovered.status == "ok"


def test_an_unconverged_solve_reports_the_solver_status(
    crossing: Scenario, crossing_route: Route
) -> None:
    controller = NMPCController(NMPCParams(max_iterations=1))
    robot = RobotState(2.0, 10.0, 0.0, 0.1, 0.0)
    controller.reset(crossing.floor, crossing_route, robot, RobotParams())

    command = controller.control(0.0, robot, None)

    assert command.failed
    assert command.status == "MaxIterExceeded"
    assert command.speed == 0.0
    assert command.yaw_rate == 0.0


def test_resumes_after_an_emergency_stop_it_did_not_see(
    crossing: Scenario, crossing_route: Route, fatrop_controller: NMPCController
) -> None:
    trace = drive(
        fatrop_controller, crossing.floor, crossing_route, start_of(crossing), duration=6.0
    )
    assert trace.final is not None
    assert trace.final.speed > 0.9
    # The safety layer braked at 7.5 m/s^2 and held the robot for a second.
    stopped = RobotState(trace.final.x + 0.07, trace.final.y, trace.final.heading, 0.0, 0.0)

    command = fatrop_controller.control(7.4, stopped, None)

    assert command.status == "ok"
    assert 0.0 < command.speed <= ROBOT.max_acceleration * 0.2 + 1e-9


def test_survives_a_pickle_round_trip(crossing: Scenario, crossing_route: Route) -> None:
    controller = NMPCController()
    robot = RobotState(5.0, 10.1, 0.05, 0.8, 0.0)
    controller.reset(crossing.floor, crossing_route, robot, RobotParams())
    controller.control(0.0, robot, None)
    following = RobotState(5.16, 10.1, 0.05, 0.8, 0.0)

    copy = pickle.loads(pickle.dumps(controller))

    original, restored = (
        controller.control(0.2, following, None),
        copy.control(0.2, following, None),
    )
    assert restored.status == "ok"
    assert restored.speed == pytest.approx(original.speed, abs=1e-9)
    assert restored.yaw_rate == pytest.approx(original.yaw_rate, abs=1e-9)
