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
import warnings
from dataclasses import dataclass, field
from time import perf_counter
from typing import Any, Literal

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from hazardhunt.sut.compiled import CompiledSolver, CompileError, compile_solvers
from hazardhunt.sut.prediction import predict_constant_acceleration
from hazardhunt.sut.protocols import ControlCommand, RobotState, TrackedHuman
from hazardhunt.sut.route import Route
from hazardhunt.world.bodies import HumanParams, RobotParams
from hazardhunt.world.floor import FloorMap

FloatArray = NDArray[np.float64]

_STATE = 5
"""State size: x (m), y (m), heading (rad), speed (m/s), yaw rate (rad/s)."""
_STAGE = 9
"""Variables of a stage in the stage table: the state, then acceleration (m/s^2), yaw
acceleration (rad/s^2), obstacle slack (m) and keep-out slack (m^2)."""
_SPEED, _YAW_RATE = 3, 4
_ACCELERATION, _YAW_ACCELERATION = 5, 6
_ACCELERATIONS = slice(_ACCELERATION, _YAW_ACCELERATION + 1)
_OBSTACLE_SLACK, _KEEP_OUT_SLACK = 7, 8

_REFERENCE_SIZE = 5
"""Columns of a stage's reference (:func:`_reference`): the point (m), the route's unit tangent
and the speed (m/s). A stage's parameter row is the reference, then the obstacle slots' normals
(2 each) and offsets (1 each), then the keep-out columns (:func:`_keep_out`)."""
_KEEP_OUT_SIZE = 7
"""Keep-out columns of a stage: the human's position, the half-plane normal, the weights of the
exact and linearised rows, and the relief."""
_HUMAN, _NORMAL = slice(0, 2), slice(2, 4)
_EXACT_WEIGHT, _LINEAR_WEIGHT, _RELIEF = 4, 5, 6
"""Where each quantity sits among the keep-out columns."""


@dataclass(frozen=True)
class _StageLayout:
    """Where each quantity sits in a stage's parameter row, for ``slots`` obstacle slots."""

    slots: int

    @property
    def normals(self) -> slice:
        return slice(_REFERENCE_SIZE, _REFERENCE_SIZE + 2 * self.slots)

    @property
    def offsets(self) -> slice:
        return slice(_REFERENCE_SIZE + 2 * self.slots, self.keep_out)

    @property
    def keep_out(self) -> int:
        """The first keep-out column."""
        return _REFERENCE_SIZE + 3 * self.slots

    @property
    def size(self) -> int:
        return self.keep_out + _KEEP_OUT_SIZE


_DISABLED_OFFSET = -1.0
"""Right-hand side of an unused obstacle slot: with a zero normal the row reads slack >= -1."""
_BOX_MARGIN = 1e-6
"""Growth of the obstacles' bounding boxes in the inside test, in m: far more than the rounding
error of a ray's crossing with an edge."""


@dataclass(frozen=True)
class NMPCParams:
    """Tuning of the NMPC. Defaults follow SPEC 3; cost weights apply at every stage."""

    horizon: int = 20
    """Number of stages N."""
    sample_time: float = 0.2
    """Length Ts of a stage and time between two calls, in s."""
    speed_reference: float = 1.0
    """Cruise speed along the route, in m/s; below the 1.2 m/s bound so that speed tracking does
    not fight the bound."""
    goal_deceleration: float = 0.5
    """Deceleration of the reference speed profile towards the end of the route, in m/s^2."""
    cross_track_weight: float = 1.0
    """Weight of the squared lateral offset from the stage's reference line, in 1/m^2; low
    enough that the robot steers around a human who leaves room beside the route."""
    heading_weight: float = 1.0
    """Weight of the squared difference of the heading and route-direction unit vectors."""
    speed_weight: float = 1.0
    """Weight of the squared speed-reference error, in s^2/m^2."""
    acceleration_weight: float = 0.2
    """Weight of the squared acceleration (the input-change penalty), in s^4/m^2."""
    yaw_acceleration_weight: float = 0.1
    """Weight of the squared yaw acceleration (the input-change penalty), in s^4/rad^2."""
    obstacle_margin: float = 0.25
    """Clearance kept from static obstacles on top of half the robot width, in m."""
    obstacle_slots: int = 4
    """Number M of nearest obstacles constrained at each stage."""
    obstacle_slack_weight: float = 1000.0
    """Linear (exact-penalty) weight of the obstacle slack, in 1/m."""
    obstacle_slack_quadratic_weight: float = 10000.0
    """Quadratic weight of the obstacle slack, in 1/m^2."""
    keep_out_radius: float = 1.0
    """Radius of the keep-out disc around each predicted human position, in m: the robot's
    half-diagonal (0.41 m) plus the human radius (0.25 m) plus a margin (0.34 m)."""
    keep_out_slack_weight: float = 100.0
    """Linear (exact-penalty) weight of the keep-out slack, in 1/m^2 (that slack is in m^2):
    intruding by 0.01 m^2 costs as much as a stage at 1 m/s below the reference speed. Heavier
    weights made the problem so badly scaled that solves with an unavoidable intrusion (a human
    walking at a standing robot) ran out of iterations."""
    keep_out_slack_quadratic_weight: float = 10.0
    """Quadratic weight of the keep-out slack, in 1/m^4."""
    projection_window: float = 2.0
    """Distance ahead of the previous route progress searched for the current progress, in m;
    keeps the progress monotone where the route passes close to itself."""
    reinitialise_distance: float = 0.3
    """Distance between the measured position and the previous plan beyond which the warm start is
    replaced by a rollout at the current speed, in m."""
    reinitialise_speed_error: float = 0.3
    """Speed error against the previous plan beyond which the warm start is replaced (e.g. after
    an emergency stop applied without calling the controller), in m/s."""
    retry_from_rollout: bool = True
    """After a failed warm-started solve, solve once more from a rollout with the solver's
    cold-start settings before braking."""
    solver: Literal["fatrop", "ipopt"] = "fatrop"
    """The NLP solver: the structure-exploiting ``fatrop`` or the reference ``ipopt``."""
    tolerance: float = 1e-6
    """Convergence tolerance of the solver (its scaled KKT error): keeps the first command within
    1e-4 m/s and rad/s of the exact optimum; 1e-4 saves about one iteration but lets it err by
    up to 2e-3."""
    max_iterations: int = 100
    """Iteration limit of a solve from a rollout; hitting it counts as a failed solve."""
    warm_max_iterations: int = 30
    """Iteration limit of a warm-started solve (most take 3 to 8 iterations). One that needs
    more has usually wandered into a poor region of this nonconvex problem; with
    ``retry_from_rollout`` the solve from a rollout then converges sooner."""
    initial_barrier: float = 1e-4
    """Initial barrier parameter of warm-started solves (the solvers' default 0.1, kept for solves
    from a rollout, suits a cold start); small because the shifted plan usually lies close to the
    solution: about 5 instead of 7 iterations."""
    barrier_decrease_power: float = 1.8
    """Superlinear decrease of the barrier parameter in warm-started solves: the next barrier
    is at most the current one to this power (fatrop's and IPOPT's
    ``mu_superlinear_decrease_power``, between 1 and 2, default 1.5). From 1.7 up, a
    warm-started solve needs about one iteration less (median 4 instead of 5) and reaches the
    same optimum: on recorded closed-loop problems the first commands stay within 3e-5 of
    IPOPT's at a tolerance of 1e-10."""
    bound_push: float = 1e-4
    """How far warm-started solves move the initial guess into the interior of its bounds,
    absolute and relative (fatrop's ``bound_push``/``bound_frac``, IPOPT's
    ``warm_start_*_push``/``_frac``; defaults 1e-2); small so that inactive slacks stay near
    zero. Together with ``barrier_decrease_power`` = 1.8, 1e-4 took fewer iterations and failed
    fewer solves on recorded closed-loop problems than 1e-6 (the value before), 1e-5 or 1e-3."""
    compiled: bool = True
    """Solve with fatrop's solver generated as C code and compiled by gcc
    (:mod:`hazardhunt.sut.compiled`): the same iterates, without CasADi's per-call bookkeeping.
    The first controller of a problem compiles it (about 5 s), later ones load it from the disk
    cache. Without a C compiler the interpreted solver is used, with a warning. Ignored by
    ``ipopt``."""
    jit: bool = False
    """Compile the problem's functions with CasADi's JIT and gcc for the interpreted solver
    (``compiled=False`` or ``ipopt``): about 20 s more to build (and to unpickle), about 25 %
    less time per solve."""

    def __post_init__(self) -> None:
        positive = {
            "horizon": self.horizon,
            "sample_time": self.sample_time,
            "speed_reference": self.speed_reference,
            "goal_deceleration": self.goal_deceleration,
            "keep_out_radius": self.keep_out_radius,
            "max_iterations": self.max_iterations,
            "warm_max_iterations": self.warm_max_iterations,
            "tolerance": self.tolerance,
            "bound_push": self.bound_push,
        }
        for name, value in positive.items():
            if not value > 0:
                raise ValueError(f"NMPCParams.{name} must be positive, got {value}")
        if not 1.0 < self.barrier_decrease_power < 2.0:
            raise ValueError(
                "NMPCParams.barrier_decrease_power must be between 1 and 2, got "
                f"{self.barrier_decrease_power}"
            )
        if self.obstacle_slots < 0:
            raise ValueError(f"NMPCParams.obstacle_slots must be >= 0, got {self.obstacle_slots}")
        if self.solver not in ("fatrop", "ipopt"):
            raise ValueError(f"NMPCParams.solver must be 'fatrop' or 'ipopt', got {self.solver!r}")


@dataclass
class _Plan:
    """A primal (and dual) point of the problem."""

    stages: FloatArray
    """Shape (N+1, 9): per stage the state, accelerations and slacks (stage N has no
    accelerations; its columns repeat stage N-1's)."""
    bound_multipliers: FloatArray | None = None
    """Multipliers of the variable bounds in the solver's order, or None."""
    constraint_multipliers: FloatArray | None = None
    """Multipliers of the constraints in the solver's order, or None."""


@dataclass
class _Outcome:
    success: bool
    status: str
    plan: _Plan
    extras: dict[str, float] = field(default_factory=dict)


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
        self._problem = _Problem(params, robot)
        self._route: Route | None = None
        self._obstacles: _Obstacles | None = None
        self._progress = 0.0
        self._previous: _Plan | None = None
        self._previous_time = -math.inf

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        del state["_problem"]  # CasADi's solver is rebuilt rather than pickled
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._problem = _Problem(self.params, self.robot)

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
        self._obstacles = _Obstacles(floor)
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
            guess.stages[0, :_STATE],
            _reference(self._route, self._progress, params),
            normals,
            offsets,
            _keep_out(predicted_human, guess.stages, params),
        )
        started = perf_counter()
        outcome = self._attempt(guess, parameters, warm)
        if not outcome.success and warm and params.retry_from_rollout:
            warm_iterations = outcome.extras.get("iterations", 0.0)
            outcome = self._attempt(self._rollout(robot), parameters, False)
            outcome.extras["iterations"] = outcome.extras.get("iterations", 0.0) + warm_iterations
            outcome.extras["retried"] = 1.0
        solve_time = perf_counter() - started
        self._previous_time = time
        if not outcome.success:
            self._previous = None
            return self._brake(robot, outcome, solve_time, predicted_human)
        self._previous = outcome.plan
        stages = outcome.plan.stages
        speed, yaw_rate = stages[1, _SPEED : _YAW_RATE + 1].tolist()
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

    def _attempt(self, guess: _Plan, parameters: FloatArray, warm: bool) -> _Outcome:
        """One solve; an exception inside CasADi becomes a failed outcome named after it."""
        try:
            return self._problem.solve(guess, parameters, warm)
        except Exception as error:  # CasADi raises RuntimeError; a failed solve must not crash
            return _Outcome(False, type(error).__name__, guess)

    def _rollout(self, robot: RobotState) -> _Plan:
        """The guess without history: straight on at the current speed."""
        return _rollout(robot, self.params.horizon, self.params.sample_time, self.robot.max_speed)

    def _initial_guess(self, time: float, robot: RobotState) -> tuple[_Plan, bool]:
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
                0, :_OBSTACLE_SLACK
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
                    _unwrap(robot.heading, heading),
                    robot.speed,
                    robot.yaw_rate,
                    acceleration,
                    yaw_acceleration,
                    0.0,
                    0.0,
                )
                return plan, True
        return self._rollout(robot), False

    def _brake(
        self,
        robot: RobotState,
        outcome: _Outcome,
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
            planned_positions=_braking_positions(robot, self.params, deceleration),
            predicted_human=predicted_human,
            extras=outcome.extras,
        )


class _Problem:
    """The CasADi problem and its solver, with the maps between stage tables and flat vectors.

    Variables, stage by stage: x0, u0, ..., x_{N-1}, u_{N-1}, xN, sN with u_k = (a, alpha, obstacle
    slack, keep-out slack) and sN the two slacks of stage N. Constraints, stage by stage: the
    dynamics x_{k+1} - F(x_k, u_k) = 0 of stage k followed by its path constraints (stage 0: x0
    equals the measured state; stages 1..N: M obstacle half-planes and the keep-out, all >= 0).
    Parameters: the measured state, then per stage 1..N the reference point, tangent and speed,
    the obstacle normals and offsets, and the keep-out row's human position, half-plane normal,
    weights of its exact and linearised forms and relief (1 when no human is visible).
    """

    def __init__(self, params: NMPCParams, robot: RobotParams) -> None:
        self.params = params
        self.layout = _StageLayout(params.obstacle_slots)
        self.parameter_size = self.layout.size
        nlp, equality, dynamics_rows, path_rows = self._formulate()
        # Warm-started solves start close to the solution and use a small barrier parameter;
        # from a rollout (first call, after an emergency stop or a failure) the solver's own
        # cold-start settings converge in fewer iterations and more reliably.
        self.solver = ca.nlpsol("nmpc", params.solver, nlp, _solver_options(params, equality, True))
        self.cold_solver = ca.nlpsol(
            "nmpc_cold", params.solver, nlp, _solver_options(params, equality, False)
        )
        self._variable_maps(params.horizon)
        self._constraint_maps(dynamics_rows, path_rows, len(equality))
        self._bounds(robot)
        self.compiled: tuple[CompiledSolver, CompiledSolver] | None = None
        if params.compiled and params.solver == "fatrop":
            try:
                warm, cold = compile_solvers([self.solver, self.cold_solver])
            except CompileError as error:
                warnings.warn(
                    f"the NMPC runs on CasADi's interpreted solver: {error}", stacklevel=3
                )
            else:
                for compiled in (warm, cold):
                    compiled.set_fixed(**self.bounds)
                self.compiled = (warm, cold)

    def _formulate(
        self,
    ) -> tuple[dict[str, ca.SX], list[bool], list[NDArray[np.int_]], list[NDArray[np.int_]]]:
        """The NLP, which constraint rows are equalities, and the rows of each stage's dynamics
        and path constraints."""
        params, horizon = self.params, self.params.horizon
        stage_variables = [ca.SX.sym(f"stage_{k}", _STAGE) for k in range(horizon)]
        stage_variables.append(ca.SX.sym(f"stage_{horizon}", _STATE + 2))
        measured = ca.SX.sym("measured", _STATE)
        stage_parameters = ca.SX.sym("parameters", self.parameter_size, horizon)
        step = _discrete_dynamics(params.sample_time)
        cost = ca.SX(0)
        rows: list[ca.SX] = []
        equality: list[bool] = []
        dynamics_rows: list[NDArray[np.int_]] = []
        path_rows: list[NDArray[np.int_]] = []

        def add(row: ca.SX, is_equality: bool) -> NDArray[np.int_]:
            first = len(equality)
            rows.append(row)
            equality.extend([is_equality] * row.numel())
            return np.arange(first, len(equality))

        for k in range(horizon):
            current, following = stage_variables[k], stage_variables[k + 1]
            cost += params.acceleration_weight * current[_ACCELERATION] ** 2
            cost += params.yaw_acceleration_weight * current[_YAW_ACCELERATION] ** 2
            dynamics = following[:_STATE] - step(current[:_STATE], current[_ACCELERATIONS])
            dynamics_rows.append(add(dynamics, True))
            if k == 0:
                # Fixing x0 by a constraint on a parameter rather than by its bounds keeps the
                # bounds constant, so they are converted for CasADi once instead of every call.
                path_rows.append(add(current[:_STATE] - measured, True))
                continue
            stage_cost, path = self._stage_terms(
                current[:_STATE],
                current[_OBSTACLE_SLACK],
                current[_KEEP_OUT_SLACK],
                stage_parameters[:, k - 1],
            )
            cost += stage_cost
            path_rows.append(add(path, False))
        final = stage_variables[horizon]
        stage_cost, path = self._stage_terms(
            final[:_STATE],
            final[_ACCELERATION],
            final[_YAW_ACCELERATION],
            stage_parameters[:, horizon - 1],
        )
        cost += stage_cost
        path_rows.append(add(path, False))
        nlp = {
            "x": ca.vertcat(*stage_variables),
            "p": ca.vertcat(measured, ca.vec(stage_parameters)),
            "f": cost,
            "g": ca.vertcat(*rows),
        }
        return nlp, equality, dynamics_rows, path_rows

    def _stage_terms(
        self, state: ca.SX, obstacle_slack: ca.SX, keep_out_slack: ca.SX, parameters: ca.SX
    ) -> tuple[ca.SX, ca.SX]:
        """Cost and path constraints (rows >= 0) of one stage k >= 1."""
        p, slots = self.params, self.params.obstacle_slots
        x, y, heading, speed = state[0], state[1], state[2], state[3]
        reference, tangent, speed_reference = parameters[0:2], parameters[2:4], parameters[4]
        layout = self.layout
        normals = ca.reshape(parameters[layout.normals], 2, slots)
        offsets = parameters[layout.offsets]
        keep_out = parameters[layout.keep_out :]
        human, human_normal = keep_out[_HUMAN], keep_out[_NORMAL]
        exact_weight, linear_weight = keep_out[_EXACT_WEIGHT], keep_out[_LINEAR_WEIGHT]
        relief = keep_out[_RELIEF]
        lateral = tangent[0] * (y - reference[1]) - tangent[1] * (x - reference[0])
        # |(cos, sin) - tangent|^2 less its constant 2: no wrap-around, cheap derivatives.
        heading_error = -2.0 * (tangent[0] * ca.cos(heading) + tangent[1] * ca.sin(heading))
        cost = (
            p.cross_track_weight * lateral**2
            + p.heading_weight * heading_error
            + p.speed_weight * (speed - speed_reference) ** 2
            + p.obstacle_slack_weight * obstacle_slack
            + p.obstacle_slack_quadratic_weight * obstacle_slack**2
            + p.keep_out_slack_weight * keep_out_slack
            + p.keep_out_slack_quadratic_weight * keep_out_slack**2
        )
        obstacle_rows = normals[0, :].T * x + normals[1, :].T * y + obstacle_slack - offsets
        distance_sq = (x - human[0]) ** 2 + (y - human[1]) ** 2
        along_normal = human_normal[0] * (x - human[0]) + human_normal[1] * (y - human[1])
        keep_out_row = (
            exact_weight * (distance_sq - p.keep_out_radius**2)
            + linear_weight * (along_normal - p.keep_out_radius)
            + keep_out_slack
            + relief
        )
        return cost, ca.vertcat(obstacle_rows, keep_out_row)

    def _variable_maps(self, horizon: int) -> None:
        """Where each variable sits in the stage table, and where it sits one stage later."""
        table = np.arange((horizon + 1) * _STAGE).reshape(horizon + 1, _STAGE)
        self.variable_index = np.concatenate(
            [table[:horizon].ravel(), table[horizon, :_STATE], table[horizon, _OBSTACLE_SLACK:]]
        )
        position = np.full(table.size, -1)
        position[self.variable_index] = np.arange(len(self.variable_index))
        stage, column = np.divmod(self.variable_index, _STAGE)
        later = np.minimum(stage + 1, horizon)
        # Stage N has no accelerations: stage N-1 keeps its own.
        later = np.where(position[later * _STAGE + column] < 0, stage, later)
        self.variable_shift = position[later * _STAGE + column]
        # The stage table reads stage N's missing accelerations from stage N-1.
        source = position.reshape(horizon + 1, _STAGE)
        source[horizon, _ACCELERATIONS] = source[horizon - 1, _ACCELERATIONS]
        self.stage_source = position
        """For each entry of the flattened stage table, its variable in the solver's order."""

    def _constraint_maps(
        self,
        dynamics_rows: list[NDArray[np.int_]],
        path_rows: list[NDArray[np.int_]],
        count: int,
    ) -> None:
        """For each constraint row, the row that plays its part one stage later."""
        shift = np.arange(count)
        for k in range(len(dynamics_rows) - 1):
            shift[dynamics_rows[k]] = dynamics_rows[k + 1]
        for k in range(1, len(path_rows) - 1):
            shift[path_rows[k]] = path_rows[k + 1]
        self.constraint_shift = shift
        self.constraint_count = count
        self.is_path_row = np.ones(count, dtype=bool)
        for rows in [*dynamics_rows, path_rows[0]]:
            self.is_path_row[rows] = False

    def _bounds(self, robot: RobotParams) -> None:
        horizon = self.params.horizon
        lower = np.full((horizon + 1, _STAGE), -np.inf)
        upper = np.full((horizon + 1, _STAGE), np.inf)
        lower[1:, _SPEED], upper[1:, _SPEED] = 0.0, robot.max_speed
        lower[1:, _YAW_RATE], upper[1:, _YAW_RATE] = -robot.max_yaw_rate, robot.max_yaw_rate
        lower[:, _ACCELERATION] = -robot.max_acceleration
        upper[:, _ACCELERATION] = robot.max_acceleration
        lower[:, _YAW_ACCELERATION] = -robot.max_yaw_acceleration
        upper[:, _YAW_ACCELERATION] = robot.max_yaw_acceleration
        lower[:, _OBSTACLE_SLACK:] = 0.0
        upper[0, _OBSTACLE_SLACK:] = 0.0  # stage 0 has no obstacle or keep-out constraints
        self.bounds: dict[str, FloatArray] = {
            "lbx": lower.ravel()[self.variable_index],
            "ubx": upper.ravel()[self.variable_index],
            "lbg": np.zeros(self.constraint_count),
            "ubg": np.where(self.is_path_row, np.inf, 0.0),
        }
        """The variable and constraint bounds, the same for every call."""
        self.fixed_arguments = {key: ca.DM(value) for key, value in self.bounds.items()}

    def parameters(
        self,
        measured: FloatArray,
        reference: FloatArray,
        normals: FloatArray,
        offsets: FloatArray,
        keep_out: FloatArray,
    ) -> FloatArray:
        """The flat parameter vector: the measured state, then stage by stage its table row.

        Args:
            measured: Shape (5,): the measured state.
            reference: Shape (N, 5): from :func:`_reference`.
            normals: Shape (N, M, 2): unit normals of the obstacle half-planes.
            offsets: Shape (N, M): their right-hand sides, in m.
            keep_out: Shape (N, 7): from :func:`_keep_out`.
        """
        horizon, layout = self.params.horizon, self.layout
        flat = np.empty(_STATE + horizon * self.parameter_size)
        flat[:_STATE] = measured
        table = flat[_STATE:].reshape(horizon, self.parameter_size)
        table[:, :_REFERENCE_SIZE] = reference
        table[:, layout.normals] = normals.reshape(horizon, 2 * layout.slots)
        table[:, layout.offsets] = offsets
        table[:, layout.keep_out :] = keep_out
        return flat

    def solve(self, guess: _Plan, parameters: FloatArray, warm: bool) -> _Outcome:
        """Solve from ``guess`` with ``parameters`` (which hold the measured state).

        Args:
            guess: The initial guess.
            parameters: From :meth:`parameters`.
            warm: Whether ``guess`` is a shifted solution (else a rollout).
        """
        if self.compiled is not None:
            return self._solve_compiled(guess, parameters, warm)
        solver = self.solver if warm else self.cold_solver
        arguments: dict[str, Any] = {
            "x0": guess.stages.ravel()[self.variable_index],
            "p": parameters,
            **self.fixed_arguments,
        }
        # fatrop computes its own initial multipliers; IPOPT starts from the shifted ones.
        with_multipliers = self.params.solver == "ipopt"
        if with_multipliers and warm and guess.bound_multipliers is not None:
            arguments["lam_x0"] = guess.bound_multipliers
            arguments["lam_g0"] = guess.constraint_multipliers
        result = solver(**arguments)
        stats = solver.stats()
        outcome = self._outcome(
            np.asarray(result["x"].nonzeros()),
            float(result["f"]),
            bool(stats.get("success", False)),
            stats.get("return_status", "unknown"),
            float(stats.get("iter_count", -1)),
        )
        if with_multipliers:
            outcome.plan.bound_multipliers = np.array(result["lam_x"].nonzeros())
            outcome.plan.constraint_multipliers = np.array(result["lam_g"].nonzeros())
        return outcome

    def _solve_compiled(self, guess: _Plan, parameters: FloatArray, warm: bool) -> _Outcome:
        """:meth:`solve` on the compiled fatrop solver."""
        assert self.compiled is not None
        solver = self.compiled[0] if warm else self.compiled[1]
        result = solver.solve(guess.stages.ravel()[self.variable_index], parameters)
        return self._outcome(
            result.x, result.cost, result.success, result.status, float(result.iterations)
        )

    def _outcome(
        self, x: FloatArray, cost: float, success: bool, status: object, iterations: float
    ) -> _Outcome:
        """The solver's flat solution and statistics as an outcome."""
        stages = x.take(self.stage_source).reshape(self.params.horizon + 1, _STAGE)
        finite = bool(np.isfinite(x).all())
        extras = {
            "iterations": iterations,
            "cost": cost,
            "keep_out_slack": float(stages[:, _KEEP_OUT_SLACK].max()),
            "obstacle_slack": float(stages[:, _OBSTACLE_SLACK].max()),
        }
        return _Outcome(
            success and finite,
            _status_name(status) if finite else "non-finite",
            _Plan(stages),
            extras,
        )

    def shift(self, plan: _Plan) -> _Plan:
        """The plan one stage later: stages move forward, the last one coasts for a stage."""
        stages = np.concatenate([plan.stages[1:], plan.stages[-1:]])
        x, y, heading, speed, yaw_rate = stages[-1, :_STATE].tolist()
        sample_time = self.params.sample_time
        stages[-1, :_STATE] = (
            x + speed * sample_time * math.cos(heading),
            y + speed * sample_time * math.sin(heading),
            heading + yaw_rate * sample_time,
            speed,
            yaw_rate,
        )
        shifted = _Plan(stages)
        if plan.bound_multipliers is not None and plan.constraint_multipliers is not None:
            shifted.bound_multipliers = plan.bound_multipliers[self.variable_shift]
            shifted.constraint_multipliers = plan.constraint_multipliers[self.constraint_shift]
        return shifted


_FATROP_STATUS = (
    "Success",
    "MaxIterExceeded",
    "StopAtAcceptablePoint",
    "LocalInfeasibility",
    "LineSearchFailed",
    "ErrorInStepComputation",
    "Unknown",
)
"""fatrop's return flags, which CasADi reports as their number."""


def _status_name(status: object) -> str:
    if isinstance(status, int) and 0 <= status < len(_FATROP_STATUS):
        return _FATROP_STATUS[status]
    return str(status)


def _discrete_dynamics(sample_time: float) -> ca.Function:
    """One stage of the unicycle with the accelerations held over it.

    Speed, yaw rate and heading are exact (linear and quadratic in time); the position is the
    exact integral of the speed along the heading by Simpson's rule, whose error at the speed and
    yaw-rate bounds is below a micrometre per stage (as accurate as an RK4 step, with fewer
    trigonometric terms for the solver's derivatives).
    """
    state, accelerations = ca.SX.sym("state", _STATE), ca.SX.sym("accelerations", 2)
    x, y, heading, speed, yaw_rate = (state[i] for i in range(_STATE))
    acceleration, yaw_acceleration = accelerations[0], accelerations[1]

    def speed_and_heading(elapsed: float) -> tuple[ca.SX, ca.SX]:
        return (
            speed + acceleration * elapsed,
            heading + yaw_rate * elapsed + 0.5 * yaw_acceleration * elapsed**2,
        )

    samples = [speed_and_heading(fraction * sample_time) for fraction in (0.0, 0.5, 1.0)]
    simpson = (1.0, 4.0, 1.0)
    dx = sum(w * v * ca.cos(h) for w, (v, h) in zip(simpson, samples, strict=True))
    dy = sum(w * v * ca.sin(h) for w, (v, h) in zip(simpson, samples, strict=True))
    end_speed, end_heading = samples[2]
    following = ca.vertcat(
        x + sample_time / 6.0 * dx,
        y + sample_time / 6.0 * dy,
        end_heading,
        end_speed,
        yaw_rate + yaw_acceleration * sample_time,
    )
    return ca.Function("stage", [state, accelerations], [following])


def _solver_options(params: NMPCParams, equality: list[bool], warm: bool) -> dict[str, Any]:
    """CasADi options of the warm-start or the cold-start solver."""
    options: dict[str, Any] = {"print_time": False, "error_on_fail": False, "calc_lam_p": False}
    if params.solver == "fatrop":
        fatrop: dict[str, Any] = {
            "print_level": 0,
            "tol": params.tolerance,
            "max_iter": params.max_iterations,
        }
        if warm:
            fatrop.update(
                max_iter=params.warm_max_iterations,
                mu_init=params.initial_barrier,
                mu_superlinear_decrease_power=params.barrier_decrease_power,
                bound_push=params.bound_push,
                bound_frac=params.bound_push,
            )
        options.update(structure_detection="auto", equality=equality, fatrop=fatrop)
    elif params.solver == "ipopt":
        ipopt: dict[str, Any] = {
            "print_level": 0,
            "sb": "yes",
            "tol": params.tolerance,
            "max_iter": params.max_iterations,
        }
        if warm:
            ipopt.update(
                max_iter=params.warm_max_iterations,
                mu_init=params.initial_barrier,
                mu_superlinear_decrease_power=params.barrier_decrease_power,
                warm_start_init_point="yes",
            )
            for name in (
                "bound_push",
                "bound_frac",
                "slack_bound_push",
                "slack_bound_frac",
                "mult_bound_push",
            ):
                ipopt[f"warm_start_{name}"] = params.bound_push
        options["ipopt"] = ipopt
    else:
        raise ValueError(f"unknown solver {params.solver!r}: use 'fatrop' or 'ipopt'")
    if params.jit:
        options.update(jit=True, compiler="shell", jit_options={"flags": ["-O2"]})
    return options


def _rollout(robot: RobotState, horizon: int, sample_time: float, max_speed: float) -> _Plan:
    """A guess without history: straight on at the current speed along the current heading."""
    speed = min(max(robot.speed, 0.0), max_speed)
    distance = speed * sample_time * np.arange(horizon + 1)
    stages = np.zeros((horizon + 1, _STAGE))
    stages[:, 0] = robot.x + distance * math.cos(robot.heading)
    stages[:, 1] = robot.y + distance * math.sin(robot.heading)
    stages[:, 2] = robot.heading
    stages[:, _SPEED] = speed
    stages[0, _SPEED] = robot.speed
    stages[0, _YAW_RATE] = robot.yaw_rate
    return _Plan(stages)


def _braking_positions(robot: RobotState, params: NMPCParams, deceleration: float) -> FloatArray:
    """Positions over the horizon while braking straight ahead, shape (N+1, 2), in m."""
    elapsed = params.sample_time * np.arange(params.horizon + 1)
    speed = max(robot.speed, 0.0)
    stop_time = speed / deceleration
    moving = np.minimum(elapsed, stop_time)
    distance = speed * moving - 0.5 * deceleration * moving**2
    direction = np.array([math.cos(robot.heading), math.sin(robot.heading)])
    positions: FloatArray = np.array([robot.x, robot.y]) + distance[:, None] * direction
    return positions


def _unwrap(angle: float, near: float) -> float:
    """``angle`` plus the multiple of 2 pi that brings it closest to ``near``, in rad."""
    return angle + 2.0 * math.pi * round((near - angle) / (2.0 * math.pi))


def _keep_out(
    predicted_human: FloatArray | None, stages: FloatArray, params: NMPCParams
) -> FloatArray:
    """Keep-out parameters of stages 1..N, shape (N, 7): per stage the human position (m), the
    half-plane normal, the weights of the exact (squared-distance) and linearised rows, and the
    relief (1 when no human is visible, else 0).

    At a stage where the guess already puts the robot inside the keep-out disc, the disc is
    replaced by its tangent half-plane facing the robot. Inside, the squared distance is
    concave with no gradient at the human's centre; with a human walking straight at a standing
    robot, the solver stalled there on the symmetric choice of dodging left or right. The linear
    row is scaled by 2 r so that both rows have the same slope at the disc's edge and the slack
    the same units (m^2). Without a human both weights are 0 and the row reads slack + 1 >= 0:
    inactive, rather than a copy of the slack's own bound, which would leave two active
    constraints on one variable.
    """
    table = np.zeros((params.horizon, _KEEP_OUT_SIZE))
    if predicted_human is None:
        table[:, _RELIEF] = 1.0
        return table
    away = stages[1:, :2] - predicted_human
    distance = np.hypot(away[:, 0], away[:, 1])
    if (distance > 1e-6).all():
        normal = away / distance[:, None]
    else:
        # Where the guess sits on the human, face the robot's current position instead, and
        # where that does too, the way the robot came from.
        fallback = stages[0, :2] - predicted_human
        fallback_distance = np.hypot(fallback[:, 0], fallback[:, 1])
        heading = stages[0, 2]
        backwards = np.array([-math.cos(heading), -math.sin(heading)])
        normal = np.where(
            (distance > 1e-6)[:, None],
            away / np.maximum(distance, 1e-6)[:, None],
            np.where(
                (fallback_distance > 1e-6)[:, None],
                fallback / np.maximum(fallback_distance, 1e-6)[:, None],
                backwards,
            ),
        )
    linear = distance < params.keep_out_radius
    table[:, _HUMAN] = predicted_human
    table[:, _NORMAL] = normal
    table[:, _EXACT_WEIGHT] = ~linear
    table[:, _LINEAR_WEIGHT] = linear * (2.0 * params.keep_out_radius)
    return table


def _reference(route: Route, progress: float, params: NMPCParams) -> FloatArray:
    """Reference points, unit tangents and speeds of stages 1..N.

    The reference moves along the route from ``progress`` at the reference speed and brakes at
    the goal deceleration so that it stops at the route's end.

    Returns:
        Shape (N, 5): per stage the point (m), the route's unit tangent there and the speed
        (m/s).
    """
    cruise, deceleration = params.speed_reference, params.goal_deceleration
    length = route.length
    remaining = max(length - progress, 0.0)
    braking_distance = cruise * cruise / (2.0 * deceleration)
    if remaining >= braking_distance:
        stop_time = remaining / cruise + cruise / (2.0 * deceleration)
    else:
        stop_time = math.sqrt(2.0 * remaining / deceleration)
    braking_start = stop_time - cruise / deceleration
    half_deceleration, sample_time = 0.5 * deceleration, params.sample_time
    rows: list[float] = []
    for stage in range(1, params.horizon + 1):
        elapsed = sample_time * stage
        to_stop = stop_time - elapsed
        if to_stop < 0.0:
            to_stop = 0.0
        if elapsed <= braking_start:
            arc_length = length - (cruise * (braking_start - elapsed) + braking_distance)
        else:
            arc_length = length - half_deceleration * (to_stop * to_stop)
        speed = deceleration * to_stop
        rows += (*route.frame_at(arc_length), cruise if cruise <= speed else speed)
    return np.array(rows).reshape(-1, _REFERENCE_SIZE)


class _Obstacles:
    """The floor's obstacle polygons as flat edge arrays, for queries vectorised over the horizon.

    Every polygon is padded to the same number of edges K with zero-length edges at its first
    vertex: they never straddle a ray and their nearest point is a vertex, so they change neither
    the inside test nor the distance. Per-edge arrays stack x over y where both are needed, so
    that one numpy operation treats both coordinates.
    """

    def __init__(self, floor: FloorMap) -> None:
        polygons = [np.asarray(o.polygon, dtype=np.float64) for o in floor.obstacles]
        self.count = len(polygons)
        self.edges_per_obstacle = max((len(p) for p in polygons), default=0)
        padded_starts = np.zeros((self.count, self.edges_per_obstacle, 2))
        padded_ends = np.zeros((self.count, self.edges_per_obstacle, 2))
        for index, polygon in enumerate(polygons):
            size = len(polygon)
            padded_starts[index, :size] = polygon
            padded_ends[index, :size] = np.roll(polygon, -1, axis=0)
            padded_starts[index, size:] = padded_ends[index, size:] = polygon[0]
        starts, ends = padded_starts.reshape(-1, 2), padded_ends.reshape(-1, 2)
        self.start_x, self.start_y = starts[:, 0], starts[:, 1]
        self.end_y = ends[:, 1]
        self.delta_x, self.delta_y = (ends - starts).T
        self.starts = np.ascontiguousarray(starts.T)[:, None, :]
        """Shape (2, 1, E): the edges' start points, x row over y row, in m."""
        self.deltas = np.ascontiguousarray((ends - starts).T)[:, None, :]
        """Shape (2, 1, E): the edges' vectors from start to end, in m."""
        length_sq = self.delta_x**2 + self.delta_y**2
        degenerate = length_sq == 0.0
        self.inverse_length_sq = np.where(
            degenerate, 0.0, 1.0 / np.where(degenerate, 1.0, length_sq)
        )
        length = np.sqrt(length_sq)
        # Vertices run counter-clockwise: the outward normal is the edge direction turned right.
        safe_length = np.where(degenerate, 1.0, length)
        self.outward = np.stack(
            [
                np.where(degenerate, 0.0, self.delta_y / safe_length),
                np.where(degenerate, 0.0, -self.delta_x / safe_length),
            ]
        )
        """Shape (2, E): the edges' unit outward normals (zero for padding edges)."""
        self.slope = np.where(
            self.delta_y != 0.0,
            self.delta_x / np.where(self.delta_y != 0.0, self.delta_y, 1.0),
            0.0,
        )
        boxes = np.array(floor.bounding_boxes).reshape(-1, 4)
        low, high = boxes[:, :2], boxes[:, 2:]
        self.box_low = (low.T - _BOX_MARGIN)[:, None, :]
        """Shape (2, 1, C): each obstacle's bounding box's lower x and y less a margin, in m."""
        self.box_high = (high.T + _BOX_MARGIN)[:, None, :]
        """Shape (2, 1, C): each obstacle's bounding box's upper x and y plus a margin, in m."""
        self._first_edges: dict[int, tuple[NDArray[np.intp], NDArray[np.intp]]] = {}

    def _offsets(self, count: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """Index offsets for ``count`` points: of each obstacle's first edge in the flattened
        (points, edges) arrays, shape (count, obstacles), and of each point's row in the
        flattened (points, obstacles) arrays, shape (count, 1)."""
        offsets = self._first_edges.get(count)
        if offsets is None:
            edges = self.count * self.edges_per_obstacle
            first_edge = np.arange(count)[:, None] * edges + self.edges_per_obstacle * np.arange(
                self.count
            )
            offsets = first_edge, np.arange(count)[:, None] * self.count
            self._first_edges[count] = offsets
        return offsets

    def half_planes(
        self, points: FloatArray, inflation: float, slots: int
    ) -> tuple[FloatArray, FloatArray]:
        """Half-planes that keep each point ``inflation`` m off its ``slots`` nearest obstacles.

        For a point p and an obstacle, with q the obstacle's boundary point nearest to p and n the
        unit normal at q pointing away from the obstacle (towards p when p lies outside), the
        half-plane is ``n . p >= n . q + inflation``. For a convex obstacle it contains no point
        of the inflated obstacle. Unused slots get a zero normal and a negative offset.

        Args:
            points: Shape (N, 2): the predicted positions, in m.
            inflation: Clearance to keep, in m.
            slots: Number M of obstacles per point.

        Returns:
            Normals (N, M, 2) and offsets (N, M), in m.
        """
        count = len(points)
        used = min(slots, self.count)
        if used == 0:
            return np.zeros((count, slots, 2)), np.full((count, slots), _DISABLED_OFFSET)
        point = points.T[:, :, None]  # (2, N, 1)
        px, py = point[0], point[1]
        # Nearest point of every edge: (2, N, E) arrays hold the x and y parts.
        to = point - self.starts
        products = to * self.deltas
        along = products[0] + products[1]
        along *= self.inverse_length_sq
        np.minimum(np.maximum(along, 0.0, out=along), 1.0, out=along)
        gap = to - along * self.deltas
        squares = gap * gap
        distance_sq = squares[0] + squares[1]
        first_edge, first_obstacle = self._offsets(count)
        # Per point and obstacle its nearest edge, as an index into the flattened (N, E) arrays.
        nearest = distance_sq.reshape(count, self.count, -1).argmin(axis=2) + first_edge
        distance = np.sqrt(distance_sq.take(nearest))
        chosen = np.argsort(distance, axis=1)[:, :slots] + first_obstacle
        edge = nearest.take(chosen)
        distance = distance.take(chosen)
        gap = gap.reshape(2, -1).take(edge, axis=1)
        # Even-odd rule on a ray towards +x: inside points get the normal flipped outwards. A
        # point outside an obstacle's (slightly grown) bounding box crosses its boundary an even
        # number of times, so the rule only runs when some point lies within a box.
        sign: FloatArray | float = 1.0
        in_box = (point > self.box_low) & (point < self.box_high)
        if (in_box[0] & in_box[1]).any():
            straddles = (self.start_y > py) != (self.end_y > py)
            hits = straddles & (px < self.start_x + to[1] * self.slope)
            crossings = hits.reshape(count, self.count, -1).sum(axis=2)
            sign = np.where(crossings.take(chosen) % 2 == 1, -1.0, 1.0)
        apart = distance > 1e-9
        if apart.all():
            normal = gap * (sign / distance)  # (2, N, used)
        else:
            # On the boundary the gap has no direction: take the edge's outward normal.
            scale = np.where(apart, sign / np.where(apart, distance, 1.0), 0.0)
            outward = self.outward.take(edge % self.outward.shape[1], axis=1)
            normal = np.where(apart, gap * scale, outward)
        along_normal = normal * (point - gap)  # the nearest points' parts along the normals
        offsets = along_normal[0] + along_normal[1] + inflation
        normals = normal.transpose(1, 2, 0)
        if used < slots:
            normals = np.concatenate([normals, np.zeros((count, slots - used, 2))], axis=1)
            disabled = np.full((count, slots - used), _DISABLED_OFFSET)
            offsets = np.concatenate([offsets, disabled], axis=1)
        return normals, offsets
