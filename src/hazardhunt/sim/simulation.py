"""The simulation core: the workplace, the system under test and the safety specification.

A :class:`Simulation` advances one decision of the human at a time (:meth:`Simulation.decide`)
or plays a whole episode (:meth:`Simulation.simulate`) from a sequence of actions or a policy.
The Gymnasium environment, the testers, replay and regression cases all drive this one loop.

One decision holds the human's (speed, turn rate) for the decision period while the physics
(0.05 s), the tracking and controller (0.2 s) and the safety layer (every physics step) run
underneath. Within one physics step the order is: (1) at a control instant, the cameras track
the human and the controller computes its command; (2) the safety layer checks its field;
(3) robot and human move; (4) contact, clearance, risk and termination are evaluated.

Long (over 500 lines) because it is the one loop every part of hazardhunt plays episodes with:
its physics step, the SUT's calls and their guards, and the episode's summary and trajectory
read and write the same state, and splitting them would scatter that state over modules.
"""

from __future__ import annotations

import dataclasses
import math
import reprlib
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from hazardhunt.errors import HazardhuntError, InputError
from hazardhunt.sim.effects import EffectsState, SutEffects
from hazardhunt.spec.episode import EpisodeSummary, EpisodeTiming, TrajectorySample
from hazardhunt.spec.outcomes import Outcome, TerminationParams, episode_outcome
from hazardhunt.spec.requirements import Requirement, Verdict, episode_signals, judged
from hazardhunt.spec.risk import RiskParams, risk
from hazardhunt.spec.safety import ContactVerdict, SafetySpecParams, judge_contact
from hazardhunt.sut.guard import (
    TimeLimit,
    TimeLimitError,
    UnusableReturnError,
    checked_command,
    checked_status,
    is_finite_number,
    is_plugin_fault,
)
from hazardhunt.sut.protocols import ControlCommand, Controller, SafetyLayer, SafetyStatus
from hazardhunt.sut.route import Route, RoutePlanningError, scenario_route
from hazardhunt.sut.safety_layer import FieldShape, LaserSafetyLayer, field_shape
from hazardhunt.sut.tracking import HumanTracker
from hazardhunt.world.bodies import HumanParams, RobotParams, RobotState
from hazardhunt.world.geometry import (
    point_in_body_frame,
    point_rectangle_clearance,
    rectangle_face,
)
from hazardhunt.world.kinematics import move_human, step_robot
from hazardhunt.world.scenario import Scenario, ScenarioError, load_scenario

TERMINAL_OUTCOMES = frozenset(
    {Outcome.GOAL, Outcome.FAILURE, Outcome.SAFE_CONTACT, Outcome.STALL, Outcome.SUT_ERROR}
)
"""Outcomes that terminate an episode; a timeout truncates it."""

Action = Sequence[float] | NDArray[np.floating[Any]]
"""The human's normalised action: (speed, turn rate), each in [-1, 1]."""
Policy = Callable[["Simulation"], Action]
"""Chooses the human's next action from the simulation's current state."""

_NO_COMMAND = ControlCommand(speed=0.0, yaw_rate=0.0, status="not started")


@dataclass(frozen=True)
class SimulationSettings:
    """Every setting of a simulation but its scenario, field and plug-ins, in one bundle (the
    simulation, the Gymnasium environment, a run and its configuration all take this one):
    defaults from SPEC."""

    decision_period: float = 2.0
    """Time the human holds each action, in s; a multiple of the controller's period, at most
    the episode's duration."""
    physics_step: float = 0.05
    """Physics time step, in s."""
    termination: TerminationParams = TerminationParams()
    """Episode duration and stall limit."""
    max_failed_commands: int = 5
    """Consecutive failed controller commands that end the episode as ``sut_error``."""
    controller_timeout: float | None = None
    """Wall-clock limit on each call of the controller and of the safety layer, in s (see
    :class:`~hazardhunt.sut.guard.TimeLimit`); a call that exceeds it ends the episode as
    ``sut_error``. None: no limit."""
    solver: str = "fatrop"
    """The built-in NMPC's solver, ``fatrop`` or ``ipopt`` (unused with a controller plug-in)."""
    robot: RobotParams = RobotParams()
    """The robot's size and limits (the controller receives them in ``reset``)."""
    human: HumanParams = HumanParams()
    """The human's size and limits."""
    risk: RiskParams = RiskParams()
    """Constants of the risk metric."""
    safety_spec: SafetySpecParams = SafetySpecParams()
    """Thresholds of the safety specification."""


@dataclass(frozen=True)
class DecisionReport:
    """What happened during one decision of the human."""

    risk: float = 0.0
    """The largest risk of the decision's physics steps."""
    risk_sum: float = 0.0
    """The risk summed over the decision's physics steps."""
    contact: bool = False
    """Human and robot touched."""
    unsafe: bool = False
    """The contact was unsafe (a failure)."""
    contact_verdict: str = ContactVerdict.NONE.value
    """How the contact was judged (see :class:`~hazardhunt.spec.safety.ContactVerdict`)."""
    controller_failures: int = 0
    """Failed controller commands within the decision."""
    outcome: str | None = None
    """How the episode ended in this decision; None while it goes on."""

    @property
    def terminated(self) -> bool:
        """The episode ended by termination (anything but a timeout)."""
        return self.outcome is not None and Outcome(self.outcome) in TERMINAL_OUTCOMES

    @property
    def truncated(self) -> bool:
        """The episode ran out of time."""
        return self.outcome == Outcome.TIMEOUT.value


@dataclass(frozen=True)
class EpisodeResult:
    """A played episode: what it amounts to, what it cost, and what replays it."""

    summary: EpisodeSummary
    timing: EpisodeTiming
    actions: NDArray[np.float32]
    """Shape (decisions, 2): the normalised actions played, enough to replay the episode."""
    risks: NDArray[np.float64]
    """The risk at every physics step."""
    trajectory: tuple[TrajectorySample, ...] | None = None
    """The episode at every control instant and at its end, when it was kept."""
    verdicts: Mapping[str, Verdict] = field(default_factory=dict)
    """Each of the simulation's :attr:`Simulation.requirements`' verdict on the episode; none
    for an episode that ended as ``sut_error``, which tested nothing to judge."""

    @property
    def outcome(self) -> str | None:
        """How the episode ended; None when the actions ran out first."""
        return self.summary.outcome


class Simulation:
    """The simulated human against the robot's control stack, on one scenario's floor."""

    def __init__(
        self,
        scenario: Scenario,
        field: FieldShape,
        controller: Controller,
        safety_layer: SafetyLayer,
        settings: SimulationSettings = SimulationSettings(),
    ) -> None:
        """Assemble a simulation from its parts (:meth:`build` builds them from names).

        Args:
            scenario: The floor and the initial state.
            field: The protective field's shape (what the classifier and pictures see).
            controller: The robot's controller.
            safety_layer: The safety layer.
            settings: Periods, limits, the robot's and human's parameters, risk and
                specification constants.

        Raises:
            ScenarioError: No route leads through the scenario's waypoints to its goal.
            PeriodError: The periods do not fit into each other or into the episode.
            ValueError: ``controller_timeout`` is not a positive number of seconds.
        """
        self.scenario, self.field, self.settings = scenario, field, settings
        self.controller, self.safety_layer = controller, safety_layer
        self.robot_params, self.human_params = settings.robot, settings.human
        self.risk_params, self.safety_spec = settings.risk, settings.safety_spec
        self.termination = termination = settings.termination
        self.max_failed_commands = settings.max_failed_commands
        self.physics_step = physics_step = settings.physics_step
        self.decision_period = settings.decision_period
        robot = settings.robot
        self._control_every, controls_per_decision = check_periods(
            physics_step,
            controller.control_period,
            settings.decision_period,
            termination.episode_duration,
        )
        self._physics_per_decision = self._control_every * controls_per_decision
        self._time_limit = TimeLimit(settings.controller_timeout)
        self._call_control: Callable[..., Any] = controller.control
        """The controller's ``control``, under the time limit if there is one (bound again at
        every reset, so that a method replaced in between is the one called)."""
        self._call_safety: Callable[..., Any] = safety_layer.update
        """The safety layer's ``update``, likewise."""
        self._call_sense: Callable[..., Any] | None = None
        """The controller's optional ``sense_human``
        (:class:`~hazardhunt.sut.protocols.SensesHuman`), likewise; None without it."""
        try:
            self.route: Route = scenario_route(scenario, robot.width)
        except RoutePlanningError as error:
            raise ScenarioError(f"{scenario.source}: robot: {error}") from error
        self.tracker = HumanTracker(scenario.floor)
        self._human_x, self._human_y = 0.0, 0.0  # the human's position: reset() sets it
        goal_x, goal_y = self.route.points[-1].tolist()
        self._goal: tuple[float, float] = (goal_x, goal_y)
        self._max_steps = round(termination.episode_duration / physics_step)
        self._started = False
        self.effects: SutEffects | None = None
        """The SUT's uncertainties in the episodes that start from now on; None: nominal."""
        self.requirements: tuple[Requirement, ...] = ()
        """Requirements beyond the contact rule, each episode judged by them
        (:attr:`EpisodeResult.verdicts`)."""
        self._effects: EffectsState | None = None
        self._braking = self.robot_params
        """The robot's parameters the physics brakes with (the effects may change them)."""

    @classmethod
    def build(
        cls,
        scenario: str | Scenario = "crossing",
        field: str = "1.25m",
        settings: SimulationSettings | float = SimulationSettings(),
        *,
        controller: Controller | None = None,
        safety_layer: SafetyLayer | None = None,
        **changes: Any,
    ) -> Simulation:
        """A simulation from names: the built-in NMPC and laser field unless given others.

        Args:
            scenario: A built-in scenario name, a scenario file path, or a loaded scenario.
            field: ``none``, ``1.25m``, ``2m`` or a field setting the scenario defines.
            settings: The simulation's settings (a number: the decision period, as the third
                argument was before 0.2.0, with a warning).
            controller: The robot's controller; the CasADi NMPC when None.
            safety_layer: The safety layer; the laser field of ``field`` when None.
            **changes: Fields of :class:`SimulationSettings` to change in ``settings``
                (``decision_period=0.2``, ``robot=RobotParams(...)``, ...).

        Raises:
            ScenarioError: The scenario does not load.
            PeriodError: Periods that do not fit.
            ValueError: An unknown field setting or solver.
            TypeError: A change that is no field of :class:`SimulationSettings`.
        """
        if isinstance(settings, (int, float)):
            warnings.warn(
                "Simulation.build(scenario, field, DECISION_PERIOD) is the call of hazardhunt "
                "0.1.0; pass decision_period=... or settings=SimulationSettings(...)",
                FutureWarning,
                stacklevel=2,
            )
            settings, changes = SimulationSettings(), {"decision_period": settings, **changes}
        if not isinstance(settings, SimulationSettings):
            raise TypeError(f"settings must be a SimulationSettings, not {type(settings).__name__}")
        settings = dataclasses.replace(settings, **changes) if changes else settings
        loaded = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
        shape = field_shape(loaded, field)
        if controller is None:
            from hazardhunt.sut.nmpc import NMPCController, NMPCParams

            params = NMPCParams(solver=settings.solver)  # type: ignore[arg-type]
            controller = NMPCController(params, robot=settings.robot, human=settings.human)
        if safety_layer is None:
            safety_layer = LaserSafetyLayer.for_field(shape, settings.robot)
        return cls(loaded, shape, controller, safety_layer, settings)

    # ------------------------------------------------------------------ episode
    @property
    def horizon(self) -> int:
        """Decisions in an episode that runs its full duration."""
        return decisions_in(self.termination.episode_duration, self.decision_period)

    def reset(self) -> None:
        """Put human and robot at the scenario's initial state."""
        start = self.scenario.robot_start
        self.robot = RobotState(start.x, start.y, start.heading, 0.0, 0.0)
        self.human_position = self.scenario.human_start.position
        self.human_heading = self.scenario.human_start.heading
        self._human_velocity = (0.0, 0.0)
        self.emergency_stop = False
        self.human_in_field = False
        self.human_visible = True
        self.outcome: Outcome | None = None
        forward, left, self.clearance = self._human_in_robot_frame()
        self.decision_step = 0
        self._steps = 0
        self._command = _NO_COMMAND
        self._stop_steps = 0
        self._failed_in_a_row = 0
        self._sut_error = False
        self._counts = _EpisodeCounts(
            self.clearance,
            math.atan2(left, forward),
            closest_robot_position=(self.robot.x, self.robot.y),
        )
        self._actions: list[NDArray[np.float32]] = []
        self._risks: list[float] = []
        self._samples: list[tuple[Any, ...]] = []
        self._started_at = time.perf_counter()
        self._effects = (
            None if self.effects is None else EffectsState(self.effects, self.physics_step)
        )
        brake = None if self.effects is None else self.effects.brake_deceleration
        self._braking = self.robot_params
        if brake is not None:
            self._braking = dataclasses.replace(self.robot_params, emergency_deceleration=brake)
        self.tracker.reset()
        self._reset_sut()
        self._started = True

    def _reset_sut(self) -> None:
        """Reset the safety layer and the controller. One that raises (or outlasts the time
        limit) is not called again: the episode ends after its first physics step as
        ``sut_error``."""
        counts = self._counts
        # The plug-ins' per-step calls for this episode, under the time limit if there is one.
        self._call_control = self._time_limit.bound("control()", self.controller.control)
        self._call_safety = self._time_limit.bound("update()", self.safety_layer.update)
        sense = getattr(self.controller, "sense_human", None)
        self._call_sense = None if sense is None else self._time_limit.bound("sense_human()", sense)
        try:
            self._time_limit.call("the safety layer's reset()", self.safety_layer.reset)
        except BaseException as error:  # a plug-in may raise anything, SystemExit too
            if not is_plugin_fault(error):
                raise
            counts.safety_layer_errors.append(f"reset() raised {_named(error)}")
            self._sut_error = True
        try:
            self._time_limit.call(
                "reset()",
                self.controller.reset,
                self.scenario.floor,
                self.route,
                self.robot,
                self.robot_params,
            )
        except BaseException as error:  # a plug-in may raise anything, SystemExit too
            if not is_plugin_fault(error):
                raise
            counts.controller_errors.append(f"reset() raised {_named(error)}")
            self._command = ControlCommand(
                speed=0.0, yaw_rate=0.0, failed=True, status=f"reset {_status(error)}"
            )
            self._sut_error = True

    def decide(self, action: Action) -> DecisionReport:
        """Hold the human's normalised ``action`` for one decision period (or until the
        episode ends)."""
        if not self._started:
            raise RuntimeError("call reset() before playing a decision")
        if self.outcome is not None:
            raise RuntimeError(f"the episode has ended ({self.outcome.value}); call reset()")
        action = human_action(action)
        self._actions.append(action)
        speed, turn_rate = self.decode_action(action)
        first_step, failures_before = len(self._risks), self._counts.controller_failures
        outcome = None
        for _ in range(self._physics_per_decision):
            outcome = self._physics(speed, turn_rate)
            if outcome is not None:
                break
        self.decision_step += 1
        if outcome is not None:
            self._record_sample()
        return self._report(first_step, failures_before, outcome)

    def _report(
        self, first_step: int, failures_before: int, outcome: Outcome | None
    ) -> DecisionReport:
        """The decision that began at physics step ``first_step``. A contact ends the episode,
        so the decision has one only if the episode ended in it."""
        risks = self._risks[first_step:]
        verdict = self._counts.contact_verdict if outcome is not None else ContactVerdict.NONE
        return DecisionReport(
            risk=max(risks, default=0.0),
            risk_sum=sum(risks),
            contact=verdict is not ContactVerdict.NONE,
            unsafe=verdict is ContactVerdict.UNSAFE,
            contact_verdict=verdict.value,
            controller_failures=self._counts.controller_failures - failures_before,
            outcome=None if outcome is None else outcome.value,
        )

    def simulate(
        self,
        actions: Sequence[Action] | NDArray[np.floating[Any]] | Policy,
        keep_trajectory: bool | Callable[[EpisodeSummary], bool] = True,
    ) -> EpisodeResult:
        """Play one episode from the scenario's start.

        Args:
            actions: The human's normalised actions, one per decision (the episode ends when
                they run out, with outcome None, if it has not ended before), or a policy that
                chooses each one from the simulation's state.
            keep_trajectory: Whether to return the trajectory, or a rule on the summary.

        Returns:
            The episode's result.
        """
        self.reset()
        if callable(actions):
            while self.outcome is None:
                self.decide(actions(self))
        else:
            for action in actions:
                if self.decide(action).outcome is not None:
                    break
        return self.result(keep_trajectory)

    def result(
        self, keep_trajectory: bool | Callable[[EpisodeSummary], bool] = True
    ) -> EpisodeResult:
        """The episode so far as a result (its trajectory when ``keep_trajectory`` says so)."""
        summary = self.summary()
        keep = keep_trajectory(summary) if callable(keep_trajectory) else keep_trajectory
        trajectory = tuple(self.trajectory()) if keep or self.requirements else None
        verdicts = {}
        if self.requirements and trajectory and summary.outcome != "sut_error":
            response = self.field.response_time
            if self._effects is not None:
                response += self._effects.effects.response_time
            signals = episode_signals(
                trajectory, self._braking.emergency_deceleration, response, self._goal
            )
            verdicts = judged(self.requirements, signals)
        return EpisodeResult(
            summary=summary,
            timing=self.timing(),
            actions=self.actions,
            risks=np.asarray(self._risks, dtype=np.float64),
            trajectory=trajectory if keep else None,
            verdicts=verdicts,
        )

    def decode_action(self, action: Action) -> tuple[float, float]:
        """The human's (speed in m/s, turn rate in rad/s) for a normalised action (clipped)."""
        clipped = np.clip(np.asarray(action, dtype=np.float64).reshape(2), -1.0, 1.0)
        speed = 0.5 * (float(clipped[0]) + 1.0) * self.human_params.max_speed
        return speed, float(clipped[1]) * self.human_params.max_turn_rate

    # ------------------------------------------------------------------ physics
    def _physics(self, speed: float, turn_rate: float) -> Outcome | None:
        """One physics step; the outcome if it ends the episode."""
        dt = self.physics_step
        now = self._steps * dt
        if self._effects is not None:
            self._effects.note_pose(self.human_pose)
        if not self._sut_error:  # else a reset failed: the SUT is not called again
            if self._steps % self._control_every == 0:
                self._control(now)
            self._safety(now)
        self.robot = step_robot(
            self.robot,
            self._command.speed,
            self._command.yaw_rate,
            dt,
            self._braking,
            emergency_stop=self.emergency_stop,
        )
        human = move_human(
            self._human_x,
            self._human_y,
            self.human_heading,
            speed,
            turn_rate,
            dt,
            self.scenario.floor,
            self.human_params.radius,
        )
        self._human_x, self._human_y, self.human_heading = human.x, human.y, human.heading
        self._human_velocity = (human.velocity_x, human.velocity_y)
        self._steps += 1
        return self._judge()

    def _safety(self, now: float) -> None:
        """The safety layer's verdict on the current state; when it raises or returns something
        else than a SafetyStatus, the episode ends as ``sut_error`` with the state unchanged."""
        try:
            status = checked_status(
                self._call_safety(now, self.robot, self.human_position, self.human_params.radius)
            )
        except BaseException as error:  # a plug-in may raise anything, SystemExit too
            if not is_plugin_fault(error):
                raise
            self._counts.safety_layer_errors.append(_named(error))
            self._sut_error = True
            status = SafetyStatus(self.emergency_stop, self.human_in_field)
        stop = status.emergency_stop
        if self._effects is not None:
            stop = self._effects.brake_engaged(stop)
        if stop and not self.emergency_stop:
            self._counts.emergency_stops += 1
        if self.emergency_stop and not stop:
            # The controller resumes from standstill at its next period.
            self._command = ControlCommand(speed=0.0, yaw_rate=0.0, status=self._command.status)
        self.emergency_stop = stop
        self.human_in_field = status.human_in_field
        self._counts.field_steps += int(status.human_in_field)

    def _judge(self) -> Outcome | None:
        """Contact, clearance, risk and termination after a physics step."""
        robot = self.robot
        forward, left, self.clearance = self._human_in_robot_frame()
        contact = self.clearance <= 0.0
        face, verdict, human_speed = "", ContactVerdict.NONE, 0.0
        if contact:
            length, width = self.robot_params.length, self.robot_params.width
            face = rectangle_face(forward, left, length, width)
            verdict = judge_contact(
                contact, face, robot.speed, robot.heading, self.human_velocity, self.safety_spec
            )
            # The risk reads the human's speed only on an unsafe contact.
            human_speed = float(np.hypot(*self._human_velocity))
        step_risk = risk(
            verdict is ContactVerdict.UNSAFE,
            contact,
            human_speed,
            robot.speed,
            self.clearance,
            self.risk_params,
        )
        self._risks.append(step_risk)
        self._stop_steps = self._stop_steps + 1 if self.emergency_stop else 0
        goal_x, goal_y = self._goal
        self.outcome = episode_outcome(
            verdict,
            goal_reached=math.hypot(robot.x - goal_x, robot.y - goal_y)
            <= self.robot_params.goal_tolerance,
            sim_time=self._steps * self.physics_step,
            emergency_stop_duration=self._stop_steps * self.physics_step,
            sut_error=self._sut_error,
            params=self.termination,
        )
        if self.outcome is None and self._steps >= self._max_steps:
            self.outcome = Outcome.TIMEOUT
        counts = self._counts
        counts.add(step_risk, face if contact else None, verdict)
        if self.clearance < counts.min_clearance or contact:
            counts.closest(
                self.clearance,
                math.atan2(left, forward),
                robot.speed,
                self._stop_state(),
                (robot.x, robot.y),
                self._human_velocity,
            )
        return self.outcome

    def _stop_state(self) -> str:
        """The safety layer's history: ``never`` stopped, stop ``holding`` or ``released``."""
        if self.emergency_stop:
            return "holding"
        return "released" if self._counts.emergency_stops else "never"

    def _control(self, now: float) -> None:
        """One tracking and control instant."""
        if self._effects is None:
            tracked = self.tracker.observe(now, self.human_position, self.human_heading)
        else:
            sighting = self._effects.sighting()
            tracked = None if sighting is None else self.tracker.observe(now, *sighting)
        self.human_visible = tracked is not None
        if not self.emergency_stop:
            self._command = self._checked_command(now, tracked)
        self._record_sample()

    def _checked_command(self, now: float, tracked: Any) -> ControlCommand:
        """The controller's command, or a brake when it fails; one that raises, outlasts the
        time limit or returns something unusable (a non-finite command, not a ControlCommand)
        also ends the episode as ``sut_error``."""
        counts = self._counts
        counts.controller_calls += 1
        try:
            if self._call_sense is not None:  # the true human, for a sensor of the controller's
                self._call_sense(now, self.human_position, self.human_params.radius)
            command = checked_command(self._call_control(now, self.robot, tracked))
        except BaseException as error:  # a plug-in may raise anything, SystemExit too
            if not is_plugin_fault(error):
                raise
            command = ControlCommand(speed=0.0, yaw_rate=0.0, failed=True, status=_status(error))
            counts.controller_errors.append(_named(error))
            self._sut_error = True
        counts.solve_times.append(command.solve_time_s)
        if not command.failed:
            self._failed_in_a_row = 0
            return command
        self._failed_in_a_row += 1
        counts.controller_failures += 1
        if self._failed_in_a_row >= self.max_failed_commands:
            self._sut_error = True
        # A failed command brakes the robot at its normal deceleration.
        return ControlCommand(
            speed=0.0,
            yaw_rate=0.0,
            status=command.status,
            failed=True,
            solve_time_s=command.solve_time_s,
            predicted_human=command.predicted_human,
        )

    # ------------------------------------------------------------------ state and records
    def _human_in_robot_frame(self) -> tuple[float, float, float]:
        """The human's centre in the robot's frame (ahead, to the left, in m) and the clearance
        between the human disc and the robot's rectangle (m, negative: overlap)."""
        robot = self.robot
        forward, left = point_in_body_frame(
            self._human_x, self._human_y, robot.x, robot.y, robot.heading
        )
        outline = point_rectangle_clearance(
            forward, left, self.robot_params.length, self.robot_params.width
        )
        return forward, left, outline - self.human_params.radius

    @property
    def sim_time(self) -> float:
        """Simulated time since reset, in s."""
        return self._steps * self.physics_step

    @property
    def controller_status(self) -> str:
        """Status of the controller's last command."""
        return self._command.status

    @property
    def elapsed_fraction(self) -> float:
        """Simulated time as a fraction of the episode's duration."""
        return self._steps / self._max_steps

    @property
    def human_pose(self) -> tuple[float, float, float]:
        """The human's current position (m) and heading (rad)."""
        return self._human_x, self._human_y, self.human_heading

    @property
    def human_position(self) -> NDArray[np.float64]:
        """The human's current position, (x, y) in m (a new array at every call)."""
        return np.array([self._human_x, self._human_y])

    @human_position.setter
    def human_position(self, position: Sequence[float] | NDArray[np.floating[Any]]) -> None:
        self._human_x, self._human_y = float(position[0]), float(position[1])

    @property
    def human_velocity(self) -> NDArray[np.float64]:
        """The human's velocity over the last physics step, (x, y) in m/s (zero when blocked;
        a new array at every call)."""
        return np.array(self._human_velocity)

    @property
    def actions(self) -> NDArray[np.float32]:
        """The actions of the current episode, shape (decisions, 2): enough to replay it."""
        return np.array(self._actions, dtype=np.float32).reshape(-1, 2)

    def summary(self) -> EpisodeSummary:
        """What the episode so far amounts to (SPEC 7)."""
        counts = self._counts
        return EpisodeSummary(
            outcome=None if self.outcome is None else self.outcome.value,
            contact_face=counts.contact_face,
            contact_verdict=counts.contact_verdict.value,
            decision_steps=self.decision_step,
            sim_time=self.sim_time,
            risk_sum=counts.risk_sum,
            max_risk=counts.max_risk,
            min_clearance=counts.min_clearance,
            closest_bearing=counts.closest_bearing,
            closest_robot_speed=counts.closest_robot_speed,
            closest_emergency_stop=counts.closest_emergency_stop,
            closest_route_share=self._route_share(counts.closest_robot_position),
            closest_human_speed=math.hypot(*counts.closest_human_velocity),
            emergency_stops=counts.emergency_stops,
            time_in_field=counts.field_steps * self.physics_step,
            controller_calls=counts.controller_calls,
            controller_failures=counts.controller_failures,
            controller_errors=tuple(counts.controller_errors),
            safety_layer_errors=tuple(counts.safety_layer_errors),
        )

    def _route_share(self, position: tuple[float, float]) -> float:
        """The share of the route's length from its start to the route point nearest
        ``position``."""
        return self.route.project(np.asarray(position)) / max(self.route.length, 1e-12)

    def timing(self) -> EpisodeTiming:
        """Wall-clock time of the episode so far and of the controller's solves."""
        return EpisodeTiming.of(time.perf_counter() - self._started_at, self._counts.solve_times)

    def _record_sample(self) -> None:
        robot, command = self.robot, self._command
        self._samples.append(
            (
                self.sim_time,
                self._human_x,
                self._human_y,
                self.human_heading,
                robot.x,
                robot.y,
                robot.heading,
                robot.speed,
                robot.yaw_rate,
                self.human_visible,
                self.emergency_stop,
                self.human_in_field,
                self.clearance,
                command.status,
                command.failed,
                command.solve_time_s,
                command.predicted_human,
                command.planned_positions,
            )
        )

    def trajectory(self) -> list[TrajectorySample]:
        """The episode sampled at every control instant and at its end."""
        return [TrajectorySample(*values) for values in self._samples]


@dataclass
class _EpisodeCounts:
    """What the episode has tallied so far."""

    min_clearance: float
    closest_bearing: float
    closest_robot_speed: float = 0.0
    closest_emergency_stop: str = "never"
    closest_robot_position: tuple[float, float] = (0.0, 0.0)
    closest_human_velocity: tuple[float, float] = (0.0, 0.0)
    risk_sum: float = 0.0
    max_risk: float = 0.0
    contact_face: str | None = None
    contact_verdict: ContactVerdict = ContactVerdict.NONE
    emergency_stops: int = 0
    field_steps: int = 0
    controller_calls: int = 0
    controller_failures: int = 0
    controller_errors: list[str] = field(default_factory=list)
    safety_layer_errors: list[str] = field(default_factory=list)
    solve_times: list[float] = field(default_factory=list)

    def add(self, step_risk: float, face: str | None, verdict: ContactVerdict) -> None:
        self.risk_sum += step_risk
        self.max_risk = max(self.max_risk, step_risk)
        if face is not None:
            self.contact_face, self.contact_verdict = face, verdict

    def closest(
        self,
        clearance: float,
        bearing: float,
        robot_speed: float,
        stop: str,
        robot_position: tuple[float, float],
        human_velocity: tuple[float, float],
    ) -> None:
        """The human is as close as ever (or touches): remember where, and how things stood."""
        self.min_clearance = min(self.min_clearance, clearance)
        self.closest_bearing, self.closest_robot_speed = bearing, robot_speed
        self.closest_emergency_stop = stop
        self.closest_robot_position, self.closest_human_velocity = robot_position, human_velocity


class UnusableActionError(HazardhuntError, ValueError):
    """The human's action is not two finite numbers: whoever chose it (a tester, a model of
    people) is at fault, and the episode is not played."""


def human_action(action: object) -> NDArray[np.float32]:
    """``action`` as the human's normalised (speed, turn rate), a new array.

    Raises:
        UnusableActionError: It is not two finite numbers (None, NaN, infinite, a string), which
            no rule turns into a behaviour: clipped, a NaN speed would stand the human still.
    """
    try:
        with np.errstate(over="ignore"):  # beyond a float32's range: infinite, refused below
            array = np.array(action, dtype=np.float64).astype(np.float32)
    except (TypeError, ValueError):
        array = None
    if array is None or array.size != 2 or not np.isfinite(array).all():
        shown = action.tolist() if isinstance(action, np.ndarray) else action
        raise UnusableActionError(
            f"the human's action is {reprlib.repr(shown)}, not two finite numbers "
            "(speed, turn rate)"
        )
    return array.reshape(2)


class PeriodError(InputError):
    """Time settings of a simulation that cannot work together; the message names the setting,
    its value and what it must be."""


def check_periods(
    physics_step: float, control_period: float, decision_period: float, episode_duration: float
) -> tuple[int, int]:
    """Physics steps per control period and control periods per decision.

    Args:
        physics_step: Physics time step, in s.
        control_period: The controller's period, in s: a multiple of the physics step.
        decision_period: Time the human holds each action, in s: a multiple of the control
            period, at most the episode's duration.
        episode_duration: Simulated time after which an episode times out, in s.

    Raises:
        PeriodError: One line naming the setting at fault.
    """
    for name, value in (
        ("physics_step", physics_step),
        ("the controller's control_period", control_period),
        ("decision_period", decision_period),
        ("episode_duration", episode_duration),
    ):
        if not (is_finite_number(value) and value > 0):
            raise PeriodError(f"{name} must be a positive, finite number of seconds, not {value!r}")
    if decision_period > episode_duration:
        raise PeriodError(
            f"decision_period ({decision_period:g} s) must be at most the episode's duration "
            f"({episode_duration:g} s)"
        )
    return (
        _whole_multiple(
            control_period, physics_step, "the controller's control_period", "the physics step"
        ),
        _whole_multiple(
            decision_period, control_period, "decision_period", "the controller's control_period"
        ),
    )


def whole_multiple(value: float, unit: float) -> int | None:
    """How many ``unit`` make ``value`` (to 1e-9), None if no whole number of them does."""
    count = round(value / unit)
    return count if count >= 1 and abs(count * unit - value) <= 1e-9 else None


def decisions_in(episode_duration: float, decision_period: float) -> int:
    """Decisions in an episode that runs its full duration (the last one may be cut short)."""
    return math.ceil(episode_duration / decision_period - 1e-9)


def _whole_multiple(value: float, unit: float, name: str, unit_name: str) -> int:
    count = whole_multiple(value, unit)
    if count is not None:
        return count
    below, above = max(math.floor(value / unit), 1) * unit, math.ceil(value / unit) * unit
    nearest = f"{below:g} s" if below >= above else f"{below:g} s or {above:g} s"
    raise PeriodError(
        f"{name} ({value:g} s) must be a multiple of {unit_name} ({unit:g} s), e.g. {nearest}"
    )


def _named(error: BaseException) -> str:
    """An error as recorded: ``Type: message`` (``Type`` alone without a message)."""
    return f"{type(error).__name__}: {error}" if str(error) else type(error).__name__


def _status(error: BaseException) -> str:
    """The controller status of a brake that replaced a call that went wrong."""
    if isinstance(error, UnusableReturnError):
        return "unusable return"
    if isinstance(error, TimeLimitError):
        return "time limit exceeded"
    return f"raised {type(error).__name__}"
