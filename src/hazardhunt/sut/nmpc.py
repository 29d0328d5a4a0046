"""The robot's planner: a nonlinear model predictive controller after Berlin et al. 2021 (SPEC 3).

Every control period the controller solves one optimal control problem over a horizon of N
stages of Ts seconds: a unicycle whose speed and yaw rate are states and whose accelerations are
the controls follows the reference route at a reference speed, is kept off the static obstacles
by linear half-plane constraints and out of a disc around each predicted human position (its
tangent half-plane where the guess is already inside the disc). The obstacle and keep-out
constraints are soft (slack variables with a heavy penalty), so every problem is feasible: a
hard keep-out makes the problem infeasible exactly when the human is a good adversary (SPEC 9).
A solve that fails anyway is retried once from a rollout, then answered with a brake command.

The problem is built once per controller with the decision variables ordered stage by stage
(x0, u0, x1, u1, ..., xN) and the constraints grouped by stage, the layout that the
structure-exploiting solver fatrop detects; IPOPT solves the same problem as the reference.
Everything that changes between calls (measured state, reference lines, obstacle half-planes,
predicted human) enters as parameters, so a call only fills numpy arrays and runs the solver.
"""

from __future__ import annotations

import math
from time import perf_counter
from typing import Any

import numpy as np
from numpy.typing import NDArray

from hazardhunt.sut.nmpc_problem import (
    OBSTACLE_SLACK,
    SPEED,
    STATE_SIZE,
    YAW_RATE,
    NMPCParams,
    Outcome,
    Plan,
    Problem,
)
from hazardhunt.sut.nmpc_stages import (
    Obstacles,
    braking_positions,
    keep_out_table,
    reference_table,
    rollout,
    unwrap,
)
from hazardhunt.sut.prediction import predict_constant_acceleration
from hazardhunt.sut.protocols import ControlCommand, RobotState, TrackedHuman
from hazardhunt.sut.route import Route
from hazardhunt.world.bodies import HumanParams, RobotParams
from hazardhunt.world.floor import FloorMap

__all__ = ["NMPCController", "NMPCParams"]

FloatArray = NDArray[np.float64]


class NMPCController:
    """The NMPC planner as a :class:`~hazardhunt.sut.protocols.Controller`.

    The CasADi problem is built once, in the constructor (about 0.1 s; seconds with ``jit``);
    ``reset`` only stores the floor and the route and forgets the warm start. Pickling leaves the
    solver out and unpickling builds a new one.

    Example:
        >>> controller = NMPCController()  # doctest: +SKIP
        >>> controller.reset(scenario.floor, route, robot_state)  # doctest: +SKIP
        >>> command = controller.control(0.0, robot_state, tracked_human)  # doctest: +SKIP
    """

    def __init__(
        self,
        params: NMPCParams = NMPCParams(),
        robot: RobotParams = RobotParams(),
        human: HumanParams = HumanParams(),
    ) -> None:
        self.params = params
        self.robot = robot
        self.human = human
        self.control_period = params.sample_time
        self._problem = Problem(params, robot)
        self._route: Route | None = None
        self._obstacles: Obstacles | None = None
        self._progress = 0.0
        self._previous: Plan | None = None
        self._previous_time = -math.inf

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        del state["_problem"]  # CasADi's solver is rebuilt rather than pickled
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._problem = Problem(self.params, self.robot)

    def reset(self, floor: FloorMap, route: Route, robot: RobotState, params: RobotParams) -> None:
        """Forget the previous episode; the robot starts at ``robot`` and follows ``route``.

        Raises:
            ValueError: ``params`` is another robot than the one the problem was built for.
        """
        if params != self.robot:
            raise ValueError(
                f"the NMPC was built for {self.robot} and cannot drive {params}; "
                "build it with robot=params"
            )
        self._route = route
        self._obstacles = Obstacles(floor)
        self._progress = route.project(np.array([robot.x, robot.y]))
        self._previous = None
        self._previous_time = -math.inf

    def control(self, time: float, robot: RobotState, human: TrackedHuman | None) -> ControlCommand:
        """Solve the problem from the measured state and return the first command.

        Args:
            time: Simulated time, in s.
            robot: The robot's measured state.
            human: The tracked human, or None when the cameras do not see it (then the keep-out
                constraint is off).

        Returns:
            The speed and yaw rate the plan reaches at the end of its first stage, with the plan,
            the predicted human and solver statistics in ``extras`` (``iterations``, ``cost``,
            ``keep_out_slack`` in m^2, ``obstacle_slack`` in m). When the solve fails, raises
            inside CasADi or returns non-finite numbers: a brake command with ``failed=True``
            and the solver's status (or the exception's class name).

        Raises:
            RuntimeError: When called before :meth:`reset`.
        """
        if self._route is None or self._obstacles is None:
            raise RuntimeError("reset() must be called before control()")
        params = self.params
        guess, warm = self._initial_guess(time, robot)
        self._progress = self._route.project(
            guess.stages[0, :2], self._progress, self._progress + params.projection_window
        )
        predicted_human = None
        if human is not None:
            predicted_human = predict_constant_acceleration(
                human.recent_positions,
                human.recent_times,
                params.horizon,
                params.sample_time,
                self.human.max_speed,
            )
        normals, offsets = self._obstacles.half_planes(
            guess.stages[1:, :2],
            self.robot.width / 2 + params.obstacle_margin,
            params.obstacle_slots,
        )
        parameters = self._problem.parameters(
            guess.stages[0, :STATE_SIZE],
            reference_table(self._route, self._progress, params),
            normals,
            offsets,
            keep_out_table(predicted_human, guess.stages, params),
        )
        started = perf_counter()
        outcome = self._attempt(guess, parameters, warm)
        if not outcome.success and warm and params.retry_from_rollout:
            warm_iterations = outcome.extras.get("iterations", 0.0)
            outcome = self._attempt(self.rollout(robot), parameters, False)
            outcome.extras["iterations"] = outcome.extras.get("iterations", 0.0) + warm_iterations
            outcome.extras["retried"] = 1.0
        solve_time = perf_counter() - started
        self._previous_time = time
        if not outcome.success:
            self._previous = None
            return self._brake(robot, outcome, solve_time, predicted_human)
        self._previous = outcome.plan
        stages = outcome.plan.stages
        speed, yaw_rate = stages[1, SPEED : YAW_RATE + 1].tolist()
        max_yaw_rate = self.robot.max_yaw_rate
        return ControlCommand(
            speed=min(max(speed, 0.0), self.robot.max_speed),
            yaw_rate=min(max(yaw_rate, -max_yaw_rate), max_yaw_rate),
            status="ok",
            solve_time_s=solve_time,
            planned_positions=stages[:, :2].copy(),
            predicted_human=predicted_human,
            extras=outcome.extras,
        )

    def _attempt(self, guess: Plan, parameters: FloatArray, warm: bool) -> Outcome:
        """One solve; an exception inside CasADi becomes a failed outcome named after it."""
        try:
            return self._problem.solve(guess, parameters, warm)
        except Exception as error:  # CasADi raises RuntimeError; a failed solve must not crash
            return Outcome(False, type(error).__name__, guess)

    def rollout(self, robot: RobotState) -> Plan:
        """The guess without history: straight on at the current speed."""
        return rollout(robot, self.params.horizon, self.params.sample_time, self.robot.max_speed)

    def _initial_guess(self, time: float, robot: RobotState) -> tuple[Plan, bool]:
        """The previous plan shifted by one stage, or a rollout when there is none that fits.

        The previous plan does not fit when the last call was not one period ago (the safety
        layer held the robot in between) or the robot is not where the plan put it.

        Returns:
            The guess, with the measured state in stage 0, and whether it is warm (shifted).
        """
        previous, params = self._previous, self.params
        on_time = abs(time - self._previous_time - params.sample_time) < 0.5 * params.sample_time
        if previous is not None and on_time:
            plan = self._problem.shift(previous)
            x, y, heading, speed, _, acceleration, yaw_acceleration = plan.stages[
                0, :OBSTACLE_SLACK
            ].tolist()
            distance = math.hypot(robot.x - x, robot.y - y)
            speed_error = abs(robot.speed - speed)
            if (
                distance <= params.reinitialise_distance
                and speed_error <= params.reinitialise_speed_error
            ):
                # The measured state, the planned accelerations and no slack.
                plan.stages[0] = (
                    robot.x,
                    robot.y,
                    unwrap(robot.heading, heading),
                    robot.speed,
                    robot.yaw_rate,
                    acceleration,
                    yaw_acceleration,
                    0.0,
                    0.0,
                )
                return plan, True
        return self.rollout(robot), False

    def _brake(
        self,
        robot: RobotState,
        outcome: Outcome,
        solve_time: float,
        predicted_human: FloatArray | None,
    ) -> ControlCommand:
        """The command that stops the robot when no plan could be computed."""
        deceleration, sample_time = self.robot.max_acceleration, self.params.sample_time
        return ControlCommand(
            speed=max(robot.speed - deceleration * sample_time, 0.0),
            yaw_rate=0.0,
            status=outcome.status,
            failed=True,
            solve_time_s=solve_time,
            planned_positions=braking_positions(robot, self.params, deceleration),
            predicted_human=predicted_human,
            extras=outcome.extras,
        )
