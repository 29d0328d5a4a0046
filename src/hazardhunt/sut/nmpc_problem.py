"""The NMPC's optimal control problem (SPEC 3): its tuning (:class:`NMPCParams`), the layout of
its variables and parameters stage by stage, its formulation in CasADi and its solve with
fatrop or IPOPT (:class:`Problem`). :mod:`hazardhunt.sut.nmpc_stages` computes what fills a
stage's parameters; :class:`hazardhunt.sut.nmpc.NMPCController` drives both.

Long (over 500 lines) because the problem's tuning, layout, formulation, bounds and solve are
one piece: each reads the layout the others write."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any, Literal

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from hazardhunt.sut.compiled import CompiledSolver, CompileError, compile_solvers
from hazardhunt.world.bodies import RobotParams

FloatArray = NDArray[np.float64]

STATE_SIZE = 5
"""State size: x (m), y (m), heading (rad), speed (m/s), yaw rate (rad/s)."""
STAGE_SIZE = 9
"""Variables of a stage in the stage table: the state, then acceleration (m/s^2), yaw
acceleration (rad/s^2), obstacle slack (m) and keep-out slack (m^2)."""
SPEED, YAW_RATE = 3, 4
ACCELERATION, YAW_ACCELERATION = 5, 6
ACCELERATIONS = slice(ACCELERATION, YAW_ACCELERATION + 1)
OBSTACLE_SLACK, KEEP_OUT_SLACK = 7, 8

REFERENCE_SIZE = 5
"""Columns of a stage's reference (:func:`reference_table`): the point (m), the route's unit tangent
and the speed (m/s). A stage's parameter row is the reference, then the obstacle slots' normals
(2 each) and offsets (1 each), then the keep-out columns (:func:`keep_out_table`)."""
KEEP_OUT_SIZE = 7
"""Keep-out columns of a stage: the human's position, the half-plane normal, the weights of the
exact and linearised rows, and the relief."""
KEEP_OUT_HUMAN, KEEP_OUT_NORMAL = slice(0, 2), slice(2, 4)
KEEP_OUT_EXACT_WEIGHT, KEEP_OUT_LINEAR_WEIGHT, KEEP_OUT_RELIEF = 4, 5, 6
"""Where each quantity sits among the keep-out columns."""


@dataclass(frozen=True)
class StageLayout:
    """Where each quantity sits in a stage's parameter row, for ``slots`` obstacle slots."""

    slots: int

    @property
    def normals(self) -> slice:
        return slice(REFERENCE_SIZE, REFERENCE_SIZE + 2 * self.slots)

    @property
    def offsets(self) -> slice:
        return slice(REFERENCE_SIZE + 2 * self.slots, self.keep_out)

    @property
    def keep_out(self) -> int:
        """The first keep-out column."""
        return REFERENCE_SIZE + 3 * self.slots

    @property
    def size(self) -> int:
        return self.keep_out + KEEP_OUT_SIZE


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
class Plan:
    """A primal (and dual) point of the problem."""

    stages: FloatArray
    """Shape (N+1, 9): per stage the state, accelerations and slacks (stage N has no
    accelerations; its columns repeat stage N-1's)."""
    bound_multipliers: FloatArray | None = None
    """Multipliers of the variable bounds in the solver's order, or None."""
    constraint_multipliers: FloatArray | None = None
    """Multipliers of the constraints in the solver's order, or None."""


@dataclass
class Outcome:
    success: bool
    status: str
    plan: Plan
    extras: dict[str, float] = field(default_factory=dict)


class Problem:
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
        self.layout = StageLayout(params.obstacle_slots)
        self.parameter_size = self.layout.size
        nlp, equality, dynamics_rows, path_rows = self._formulate()
        # Warm-started solves start close to the solution and use a small barrier parameter;
        # from a rollout (first call, after an emergency stop or a failure) the solver's own
        # cold-start settings converge in fewer iterations and more reliably.
        self.solver = ca.nlpsol("nmpc", params.solver, nlp, solver_options(params, equality, True))
        self.cold_solver = ca.nlpsol(
            "nmpc_cold", params.solver, nlp, solver_options(params, equality, False)
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
        stage_variables = [ca.SX.sym(f"stage_{k}", STAGE_SIZE) for k in range(horizon)]
        stage_variables.append(ca.SX.sym(f"stage_{horizon}", STATE_SIZE + 2))
        measured = ca.SX.sym("measured", STATE_SIZE)
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
            cost += params.acceleration_weight * current[ACCELERATION] ** 2
            cost += params.yaw_acceleration_weight * current[YAW_ACCELERATION] ** 2
            dynamics = following[:STATE_SIZE] - step(current[:STATE_SIZE], current[ACCELERATIONS])
            dynamics_rows.append(add(dynamics, True))
            if k == 0:
                # Fixing x0 by a constraint on a parameter rather than by its bounds keeps the
                # bounds constant, so they are converted for CasADi once instead of every call.
                path_rows.append(add(current[:STATE_SIZE] - measured, True))
                continue
            stage_cost, path = self._stage_terms(
                current[:STATE_SIZE],
                current[OBSTACLE_SLACK],
                current[KEEP_OUT_SLACK],
                stage_parameters[:, k - 1],
            )
            cost += stage_cost
            path_rows.append(add(path, False))
        final = stage_variables[horizon]
        stage_cost, path = self._stage_terms(
            final[:STATE_SIZE],
            final[ACCELERATION],
            final[YAW_ACCELERATION],
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
        human, human_normal = keep_out[KEEP_OUT_HUMAN], keep_out[KEEP_OUT_NORMAL]
        exact_weight, linear_weight = (
            keep_out[KEEP_OUT_EXACT_WEIGHT],
            keep_out[KEEP_OUT_LINEAR_WEIGHT],
        )
        relief = keep_out[KEEP_OUT_RELIEF]
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
        table = np.arange((horizon + 1) * STAGE_SIZE).reshape(horizon + 1, STAGE_SIZE)
        self.variable_index = np.concatenate(
            [table[:horizon].ravel(), table[horizon, :STATE_SIZE], table[horizon, OBSTACLE_SLACK:]]
        )
        position = np.full(table.size, -1)
        position[self.variable_index] = np.arange(len(self.variable_index))
        stage, column = np.divmod(self.variable_index, STAGE_SIZE)
        later = np.minimum(stage + 1, horizon)
        # Stage N has no accelerations: stage N-1 keeps its own.
        later = np.where(position[later * STAGE_SIZE + column] < 0, stage, later)
        self.variable_shift = position[later * STAGE_SIZE + column]
        # The stage table reads stage N's missing accelerations from stage N-1.
        source = position.reshape(horizon + 1, STAGE_SIZE)
        source[horizon, ACCELERATIONS] = source[horizon - 1, ACCELERATIONS]
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
        lower = np.full((horizon + 1, STAGE_SIZE), -np.inf)
        upper = np.full((horizon + 1, STAGE_SIZE), np.inf)
        lower[1:, SPEED], upper[1:, SPEED] = 0.0, robot.max_speed
        lower[1:, YAW_RATE], upper[1:, YAW_RATE] = -robot.max_yaw_rate, robot.max_yaw_rate
        lower[:, ACCELERATION] = -robot.max_acceleration
        upper[:, ACCELERATION] = robot.max_acceleration
        lower[:, YAW_ACCELERATION] = -robot.max_yaw_acceleration
        upper[:, YAW_ACCELERATION] = robot.max_yaw_acceleration
        lower[:, OBSTACLE_SLACK:] = 0.0
        upper[0, OBSTACLE_SLACK:] = 0.0  # stage 0 has no obstacle or keep-out constraints
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
            reference: Shape (N, 5): from :func:`reference_table`.
            normals: Shape (N, M, 2): unit normals of the obstacle half-planes.
            offsets: Shape (N, M): their right-hand sides, in m.
            keep_out: Shape (N, 7): from :func:`keep_out_table`.
        """
        horizon, layout = self.params.horizon, self.layout
        flat = np.empty(STATE_SIZE + horizon * self.parameter_size)
        flat[:STATE_SIZE] = measured
        table = flat[STATE_SIZE:].reshape(horizon, self.parameter_size)
        table[:, :REFERENCE_SIZE] = reference
        table[:, layout.normals] = normals.reshape(horizon, 2 * layout.slots)
        table[:, layout.offsets] = offsets
        table[:, layout.keep_out :] = keep_out
        return flat

    def solve(self, guess: Plan, parameters: FloatArray, warm: bool) -> Outcome:
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

    def _solve_compiled(self, guess: Plan, parameters: FloatArray, warm: bool) -> Outcome:
        """:meth:`solve` on the compiled fatrop solver."""
        assert self.compiled is not None
        solver = self.compiled[0] if warm else self.compiled[1]
        result = solver.solve(guess.stages.ravel()[self.variable_index], parameters)
        return self._outcome(
            result.x, result.cost, result.success, result.status, float(result.iterations)
        )

    def _outcome(
        self, x: FloatArray, cost: float, success: bool, status: object, iterations: float
    ) -> Outcome:
        """The solver's flat solution and statistics as an outcome."""
        stages = x.take(self.stage_source).reshape(self.params.horizon + 1, STAGE_SIZE)
        finite = bool(np.isfinite(x).all())
        extras = {
            "iterations": iterations,
            "cost": cost,
            "keep_out_slack": float(stages[:, KEEP_OUT_SLACK].max()),
            "obstacle_slack": float(stages[:, OBSTACLE_SLACK].max()),
        }
        return Outcome(
            success and finite,
            _status_name(status) if finite else "non-finite",
            Plan(stages),
            extras,
        )

    def shift(self, plan: Plan) -> Plan:
        """The plan one stage later: stages move forward, the last one coasts for a stage."""
        stages = np.concatenate([plan.stages[1:], plan.stages[-1:]])
        x, y, heading, speed, yaw_rate = stages[-1, :STATE_SIZE].tolist()
        sample_time = self.params.sample_time
        stages[-1, :STATE_SIZE] = (
            x + speed * sample_time * math.cos(heading),
            y + speed * sample_time * math.sin(heading),
            heading + yaw_rate * sample_time,
            speed,
            yaw_rate,
        )
        shifted = Plan(stages)
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
    state, accelerations = ca.SX.sym("state", STATE_SIZE), ca.SX.sym("accelerations", 2)
    x, y, heading, speed, yaw_rate = (state[i] for i in range(STATE_SIZE))
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


def solver_options(params: NMPCParams, equality: list[bool], warm: bool) -> dict[str, Any]:
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
