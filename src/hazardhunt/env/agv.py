"""The AGV workplace as a Gymnasium environment: the tester moves the human, the SUT the robot.

One ``step`` is one decision of the tester: the human's (speed, turn rate) held for the decision
period while the physics (0.05 s), the tracking and controller (0.2 s) and the safety layer
(every physics step) run underneath.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from hazardhunt.env.observation import OBSERVATION_FEATURES, encode_observation
from hazardhunt.spec.outcomes import Outcome, TerminationParams, episode_outcome
from hazardhunt.spec.rewards import REWARD_KINDS, RewardKind, decision_reward
from hazardhunt.spec.risk import RiskParams, risk
from hazardhunt.spec.safety import ContactVerdict, SafetySpecParams, judge_contact
from hazardhunt.sut.protocols import ControlCommand, Controller, RobotState, SafetyLayer
from hazardhunt.sut.route import Route, RoutePlanningError, plan_route
from hazardhunt.sut.safety_layer import LaserSafetyLayer
from hazardhunt.sut.tracking import HumanTracker
from hazardhunt.world.bodies import HumanParams, RobotParams
from hazardhunt.world.geometry import (
    disc_rectangle_clearance,
    point_rectangle_clearance,
    rectangle_face,
    to_body_frame,
)
from hazardhunt.world.kinematics import step_human, step_robot
from hazardhunt.world.scenario import Scenario, ScenarioError, field_shape, load_scenario

ObsType = NDArray[np.float32]
ActType = NDArray[np.float32]

ROUTE_MARGIN = 0.25
"""Clearance the reference route keeps from obstacles beyond the robot's half width, in m."""

TERMINAL_OUTCOMES = frozenset(
    {Outcome.GOAL, Outcome.FAILURE, Outcome.SAFE_CONTACT, Outcome.STALL, Outcome.SUT_ERROR}
)


@dataclass
class TrajectoryRecorder:
    """Samples the episode at every control instant (0.2 s) and at its end."""

    rows: list[dict[str, Any]] = field(default_factory=list)

    def clear(self) -> None:
        self.rows = []

    def add(self, **row: Any) -> None:
        self.rows.append(row)


class AGVEnv(gym.Env[ObsType, ActType]):
    """The simulated human (the agent) against the robot's control stack (the SUT).

    Action: two numbers in [-1, 1]: the human's walking speed, mapped linearly to
    [0, ``human.max_speed``] m/s, and turn rate, mapped to [-``human.max_turn_rate``,
    ``human.max_turn_rate``] rad/s. Observation: ``OBSERVATION_FEATURES``, in [-1, 1].

    ``info`` after every step (and reset) holds:

    - ``outcome`` (str or None): how the episode ended, None while it goes on;
    - ``unsafe`` / ``contact`` (bool): an unsafe contact / any contact in this decision step;
    - ``contact_verdict`` (str): see :class:`~hazardhunt.spec.safety.ContactVerdict`;
    - ``clearance`` (m): gap between human and robot at the end of the step;
      ``min_clearance`` (m): smallest gap in the episode so far;
    - ``risk``: largest risk within the step; ``risk_sum``: sum over its physics steps;
      ``max_risk``: largest risk of the episode so far;
    - ``estop`` (bool): the emergency stop holds at the end of the step; ``estop_count``: stops
      triggered in the episode; ``human_in_field`` (bool); ``time_in_field`` (s, episode);
    - ``human_visible`` (bool): the cameras see the human;
    - ``nmpc_status`` (str): status of the controller's last command; ``nmpc_solve_time_s`` (s):
      controller solve time within the step (0 when ``measure_time`` is False);
      ``nmpc_failures``: failed commands within the step;
    - ``sim_time`` (s), ``decision_step`` (int);
    - at the episode's end also ``summary``: see :meth:`episode_summary`.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 5}  # noqa: RUF012

    def __init__(
        self,
        scenario: str | Scenario = "crossing",
        field: str = "1.25m",
        reward: RewardKind = "max",
        decision_period: float = 2.0,
        *,
        solver: str = "fatrop",
        controller: Controller | None = None,
        safety_layer: SafetyLayer | None = None,
        physics_step: float = 0.05,
        termination: TerminationParams = TerminationParams(),
        max_failed_commands: int = 5,
        robot: RobotParams = RobotParams(),
        human: HumanParams = HumanParams(),
        risk_params: RiskParams = RiskParams(),
        safety_spec: SafetySpecParams = SafetySpecParams(),
        measure_time: bool = True,
        record_trajectory: bool = True,
        render_mode: str | None = None,
    ) -> None:
        """Build the environment.

        Args:
            scenario: A built-in scenario name (``crossing``, ``head-on``, ``overtaking``), a
                scenario file path, or a loaded :class:`Scenario`.
            field: Protective-field setting: ``none``, ``1.25m``, ``2m`` or a field the
                scenario defines.
            reward: ``acc`` (accumulated risk) or ``max`` (episode's maximum risk at the end).
            decision_period: Time the human holds each action, in s; a multiple of the
                controller's period.
            solver: NMPC solver, ``fatrop`` or ``ipopt`` (ignored with ``controller``).
            controller: The robot's controller; the CasADi NMPC when None.
            safety_layer: The safety layer; the laser field of ``field`` when None.
            physics_step: Physics time step, in s.
            termination: Episode duration and stall limit.
            max_failed_commands: Consecutive failed controller commands that end the episode
                as ``sut_error``.
            robot: Robot parameters.
            human: Human parameters.
            risk_params: Constants of the risk metric.
            safety_spec: Thresholds of the safety specification.
            measure_time: Report wall-clock solve times; False reports 0 so that infos compare
                bit for bit between runs.
            record_trajectory: Keep the episode's trajectory (see :meth:`trajectory`).
            render_mode: None or ``rgb_array``.
        """
        if reward not in REWARD_KINDS:
            raise ValueError(f"reward must be one of {list(REWARD_KINDS)}, not {reward!r}")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', not {render_mode!r}")
        self.scenario = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
        self.field = field
        self.field_shape = field_shape(self.scenario, field)
        self.reward_kind: RewardKind = reward
        self.robot_params = robot
        self.human_params = human
        self.risk_params = risk_params
        self.safety_spec = safety_spec
        self.termination = termination
        self.max_failed_commands = max_failed_commands
        self.measure_time = measure_time
        self.record_trajectory = record_trajectory
        self.render_mode = render_mode
        self.physics_step = physics_step

        try:
            self.route: Route = plan_route(
                self.scenario.floor,
                self.scenario.robot_start.position,
                self.scenario.waypoints,
                self.scenario.goal,
                robot.width / 2 + ROUTE_MARGIN,
            )
        except RoutePlanningError as error:
            raise ScenarioError(f"{self.scenario.source}: robot: {error}") from error

        if controller is None:
            from hazardhunt.sut.nmpc import NMPCController, NMPCParams

            controller = NMPCController(
                NMPCParams(solver=solver),  # type: ignore[arg-type]
                robot=robot,
                human=human,
            )
        self.controller = controller
        self.safety_layer: SafetyLayer = (
            safety_layer
            if safety_layer is not None
            else LaserSafetyLayer(
                self.field_shape.diameter, robot=robot, side_margin=self.field_shape.side_margin
            )
        )
        self.tracker = HumanTracker(self.scenario.floor)
        self._control_every = _whole_multiple(
            controller.control_period, physics_step, "controller period", "physics step"
        )
        self._physics_per_decision = self._control_every * _whole_multiple(
            decision_period, controller.control_period, "decision_period", "controller period"
        )
        self.decision_period = decision_period
        self._max_steps = round(termination.episode_duration / physics_step)

        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.observation_space = spaces.Box(
            -1.0, 1.0, shape=(len(OBSERVATION_FEATURES),), dtype=np.float32
        )
        self._trajectory = TrajectoryRecorder()
        self._outcome: Outcome | None = None
        self._started = False

    # ------------------------------------------------------------------ episode
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[ObsType, dict[str, Any]]:
        """Put human and robot at the scenario's initial state."""
        super().reset(seed=seed)
        start = self.scenario.robot_start
        self._robot = [start.x, start.y, start.heading, 0.0, 0.0]
        self._human_position = self.scenario.human_start.position.copy()
        self._human_heading = self.scenario.human_start.heading
        self._human_velocity = np.zeros(2)
        self._steps = 0
        self._decision = 0
        self._command = ControlCommand(speed=0.0, yaw_rate=0.0, status="not started")
        self._stopping = False
        self._in_field = False
        self._visible = True
        self._stop_steps = 0
        self._failed_in_a_row = 0
        self._sut_error = False
        self._outcome = None
        self._route_progress = 0.0
        self._clearance = self._current_clearance()
        self._episode: dict[str, Any] = {
            "return": 0.0,
            "max_risk": 0.0,
            "min_clearance": self._clearance,
            "estop_count": 0,
            "field_steps": 0,
            "solve_times": [],
            "failed_commands": 0,
            "controller_errors": [],
            "actions": [],
            "started": time.perf_counter(),
        }
        self._step_report = self._fresh_step_report()
        self.safety_layer.reset()
        self.tracker.reset()
        self._trajectory.clear()
        self.controller.reset(self.scenario.floor, self.route, self._robot_state())
        self._started = True
        return self._observation(), self._info()

    def step(self, action: ActType) -> tuple[ObsType, float, bool, bool, dict[str, Any]]:
        """Hold the human's action for one decision period."""
        if not self._started:
            raise RuntimeError("call reset() before step()")
        if self._outcome is not None:
            raise RuntimeError(f"the episode has ended ({self._outcome.value}); call reset()")
        self._episode["actions"].append(np.asarray(action, dtype=np.float32).copy())
        speed, turn_rate = self.decode_action(action)

        self._step_report = self._fresh_step_report()
        risks = []
        outcome = None
        for _ in range(self._physics_per_decision):
            step_risk, outcome = self._physics(speed, turn_rate)
            risks.append(step_risk)
            if outcome is not None:
                break
        self._decision += 1
        terminated = outcome in TERMINAL_OUTCOMES
        truncated = outcome is Outcome.TIMEOUT
        reward = decision_reward(
            self.reward_kind, risks, self._episode["max_risk"], terminated or truncated
        )
        self._episode["return"] += reward
        if outcome is not None:
            self._record_row()
        return self._observation(), reward, terminated, truncated, self._info()

    def decode_action(self, action: ActType) -> tuple[float, float]:
        """The human's (speed in m/s, turn rate in rad/s) for a normalised action (clipped)."""
        clipped = np.clip(np.asarray(action, dtype=np.float64).reshape(2), -1.0, 1.0)
        speed = 0.5 * (float(clipped[0]) + 1.0) * self.human_params.max_speed
        return speed, float(clipped[1]) * self.human_params.max_turn_rate

    @property
    def field_diameter(self) -> float | None:
        """Diameter of the protective field's half-disc ahead of the robot, in m (None: none)."""
        return self.field_shape.diameter

    # ------------------------------------------------------------------ physics
    def _physics(self, speed: float, turn_rate: float) -> tuple[float, Outcome | None]:
        """One physics step; returns its risk and the outcome if it ends the episode."""
        dt = self.physics_step
        robot_state = self._robot_state()
        if self._steps % self._control_every == 0:
            self._control(self._steps * dt, robot_state)
        human_radius = self.human_params.radius
        status = self.safety_layer.update(robot_state, self._human_position, human_radius)
        if status.emergency_stop and not self._stopping:
            self._episode["estop_count"] += 1
        if self._stopping and not status.emergency_stop:
            # The controller resumes from standstill at its next period.
            self._command = ControlCommand(speed=0.0, yaw_rate=0.0, status=self._command.status)
        self._stopping = status.emergency_stop
        self._in_field = status.human_in_field

        x, y, heading, robot_speed, yaw_rate = self._robot
        motion = step_robot(
            x,
            y,
            heading,
            robot_speed,
            yaw_rate,
            self._command.speed,
            self._command.yaw_rate,
            dt,
            self.robot_params,
            emergency_stop=self._stopping,
        )
        self._robot = [motion.x, motion.y, motion.heading, motion.speed, motion.yaw_rate]
        human = step_human(
            self._human_position,
            self._human_heading,
            speed,
            turn_rate,
            dt,
            self.scenario.floor,
            human_radius,
        )
        self._human_position, self._human_heading = human.position, human.heading
        self._human_velocity = human.velocity
        self._steps += 1

        # The clearance of _current_clearance, from the human's place in the robot's frame,
        # which also names the face of a contact.
        forward, left = to_body_frame(self._human_position, motion.x, motion.y, motion.heading)
        length, width = self.robot_params.length, self.robot_params.width
        self._clearance = point_rectangle_clearance(forward, left, length, width) - human_radius
        contact = self._clearance <= 0.0
        face = rectangle_face(forward, left, length, width) if contact else ""
        verdict = judge_contact(
            contact, face, motion.speed, motion.heading, human.velocity, self.safety_spec
        )
        velocity_x, velocity_y = human.velocity.tolist()
        human_speed = float(np.hypot(velocity_x, velocity_y))
        step_risk = risk(
            verdict is ContactVerdict.UNSAFE,
            contact,
            human_speed,
            motion.speed,
            self._clearance,
            self.risk_params,
        )
        self._stop_steps = self._stop_steps + 1 if self._stopping else 0
        goal_x, goal_y = self.route.points[-1].tolist()
        goal_distance = math.hypot(motion.x - goal_x, motion.y - goal_y)
        self._outcome = episode_outcome(
            verdict,
            goal_reached=goal_distance <= self.robot_params.goal_tolerance,
            sim_time=self._steps * dt,
            stop_held_for=self._stop_steps * dt,
            sut_error=self._sut_error,
            params=self.termination,
        )
        if self._outcome is None and self._steps >= self._max_steps:
            self._outcome = Outcome.TIMEOUT

        report, episode = self._step_report, self._episode
        report["risk"] = max(report["risk"], step_risk)
        report["risk_sum"] += step_risk
        report["contact"] = report["contact"] or contact
        report["unsafe"] = report["unsafe"] or verdict is ContactVerdict.UNSAFE
        if verdict is not ContactVerdict.NONE:
            report["contact_verdict"] = verdict.value
            report["contact_face"] = face
        episode["max_risk"] = max(episode["max_risk"], step_risk)
        episode["min_clearance"] = min(episode["min_clearance"], self._clearance)
        episode["field_steps"] += int(status.human_in_field)
        return step_risk, self._outcome

    def _control(self, now: float, robot: RobotState) -> None:
        """One tracking and control instant, with the robot's current state."""
        tracked = self.tracker.observe(now, self._human_position, self._human_heading)
        self._visible = tracked is not None
        if not self._stopping:
            try:
                command = self.controller.control(now, robot, tracked)
            except Exception as error:
                command = ControlCommand(
                    speed=0.0, yaw_rate=0.0, failed=True, status=f"raised {type(error).__name__}"
                )
                self._episode["controller_errors"].append(f"{type(error).__name__}: {error}")
                self._sut_error = True
            if not (math.isfinite(command.speed) and math.isfinite(command.yaw_rate)):
                command = ControlCommand(
                    speed=0.0, yaw_rate=0.0, failed=True, status="non-finite command"
                )
            if command.failed:
                # A failed command brakes the robot at its normal deceleration.
                command = ControlCommand(
                    speed=0.0,
                    yaw_rate=0.0,
                    status=command.status,
                    failed=True,
                    solve_time_s=command.solve_time_s,
                    predicted_human=command.predicted_human,
                )
                self._failed_in_a_row += 1
                self._episode["failed_commands"] += 1
                self._step_report["nmpc_failures"] += 1
            else:
                self._failed_in_a_row = 0
            if self._failed_in_a_row >= self.max_failed_commands:
                self._sut_error = True
            solve_time = command.solve_time_s if self.measure_time else 0.0
            self._episode["solve_times"].append(solve_time)
            self._step_report["nmpc_solve_time_s"] += solve_time
            self._command = command
        self._record_row()

    # ------------------------------------------------------------------ reporting
    def _robot_state(self) -> RobotState:
        return RobotState(*self._robot)

    def _current_clearance(self) -> float:
        x, y, heading = self._robot[:3]
        return disc_rectangle_clearance(
            self._human_position,
            self.human_params.radius,
            x,
            y,
            heading,
            self.robot_params.length,
            self.robot_params.width,
        )

    def _observation(self) -> ObsType:
        x, y, heading, speed, yaw_rate = self._robot
        self._route_progress = self.route.project(
            np.array([x, y]), self._route_progress, self._route_progress + 5.0
        )
        floor = self.scenario.floor
        return encode_observation(
            floor_size=(floor.width, floor.height),
            human_position=self._human_position,
            human_heading=self._human_heading,
            human_visible=self._visible,
            human_speed=float(np.hypot(*self._human_velocity)),
            human_max_speed=self.human_params.max_speed,
            robot_pose=(x, y, heading),
            robot_speed=speed,
            robot_max_speed=self.robot_params.max_speed,
            robot_yaw_rate=yaw_rate,
            robot_max_yaw_rate=self.robot_params.max_yaw_rate,
            emergency_stop=self._stopping,
            contact=self._clearance <= 0.0,
            human_in_field=self._in_field,
            clearance=self._clearance,
            elapsed_fraction=self._steps / self._max_steps,
            route_fraction=self._route_progress / max(self.route.length, 1e-9),
        )

    @staticmethod
    def _fresh_step_report() -> dict[str, Any]:
        return {
            "risk": 0.0,
            "risk_sum": 0.0,
            "contact": False,
            "unsafe": False,
            "contact_verdict": ContactVerdict.NONE.value,
            "contact_face": None,
            "nmpc_solve_time_s": 0.0,
            "nmpc_failures": 0,
        }

    def _info(self) -> dict[str, Any]:
        episode = self._episode
        info: dict[str, Any] = {
            "outcome": None if self._outcome is None else self._outcome.value,
            **self._step_report,
            "clearance": self._clearance,
            "min_clearance": episode["min_clearance"],
            "max_risk": episode["max_risk"],
            "estop": self._stopping,
            "estop_count": episode["estop_count"],
            "human_in_field": self._in_field,
            "time_in_field": episode["field_steps"] * self.physics_step,
            "human_visible": self._visible,
            "nmpc_status": self._command.status,
            "sim_time": self._steps * self.physics_step,
            "decision_step": self._decision,
        }
        if self._outcome is not None:
            info["summary"] = self.episode_summary()
        return info

    def episode_summary(self) -> dict[str, Any]:
        """What the episode so far amounts to (SPEC 7): outcome, decision steps, simulated time,
        return, maximum risk, minimum clearance, emergency stops, time the human spent in the
        field, wall time and the controller's solve-time statistics (s)."""
        episode = self._episode
        solve_times = np.asarray(episode["solve_times"], dtype=np.float64)
        has_solves = solve_times.size > 0
        wall_time = time.perf_counter() - episode["started"] if self.measure_time else 0.0
        return {
            "outcome": None if self._outcome is None else self._outcome.value,
            "contact_face": self._step_report["contact_face"],
            "decision_steps": self._decision,
            "sim_time": self._steps * self.physics_step,
            "return": episode["return"],
            "max_risk": episode["max_risk"],
            "min_clearance": episode["min_clearance"],
            "estop_count": episode["estop_count"],
            "time_in_field": episode["field_steps"] * self.physics_step,
            "wall_time_s": wall_time,
            "solves": int(solve_times.size),
            "failed_commands": episode["failed_commands"],
            "controller_errors": list(episode["controller_errors"]),
            "solve_time_mean_s": float(solve_times.mean()) if has_solves else 0.0,
            "solve_time_median_s": float(np.median(solve_times)) if has_solves else 0.0,
            "solve_time_max_s": float(solve_times.max()) if has_solves else 0.0,
        }

    @property
    def robot_state(self) -> RobotState:
        """The robot's current pose and speeds."""
        return self._robot_state()

    @property
    def human_pose(self) -> tuple[float, float, float]:
        """The human's current position (m) and heading (rad)."""
        return float(self._human_position[0]), float(self._human_position[1]), self._human_heading

    @property
    def sim_time(self) -> float:
        """Simulated time since reset, in s."""
        return self._steps * self.physics_step

    @property
    def emergency_stop(self) -> bool:
        """Whether the safety layer's stop holds."""
        return self._stopping

    @property
    def episode_actions(self) -> NDArray[np.float32]:
        """The actions of the current episode, shape (steps, 2): enough to replay it."""
        return np.array(self._episode["actions"], dtype=np.float32).reshape(-1, 2)

    def _record_row(self) -> None:
        if not self.record_trajectory:
            return
        x, y, heading, speed, yaw_rate = self._robot
        command = self._command
        self._trajectory.add(
            time=self._steps * self.physics_step,
            human_x=float(self._human_position[0]),
            human_y=float(self._human_position[1]),
            human_heading=self._human_heading,
            human_visible=self._visible,
            robot_x=x,
            robot_y=y,
            robot_heading=heading,
            robot_speed=speed,
            robot_yaw_rate=yaw_rate,
            emergency_stop=self._stopping,
            human_in_field=self._in_field,
            clearance=self._clearance,
            controller_status=command.status,
            controller_failed=command.failed,
            solve_time_s=command.solve_time_s if self.measure_time else 0.0,
            predicted_human=command.predicted_human,
            planned_positions=command.planned_positions,
        )

    def trajectory(self) -> list[dict[str, Any]]:
        """The episode sampled at every control instant and at its end, one dict per sample:
        time (s), human and robot poses and speeds, emergency stop, field occupancy, clearance,
        controller status, solve time, predicted human positions and planned robot positions."""
        return list(self._trajectory.rows)

    # ------------------------------------------------------------------ rendering
    def render(self) -> NDArray[np.uint8] | None:
        """An RGB picture of the floor, route, robot with its field, and the human."""
        if self.render_mode != "rgb_array":
            return None
        from hazardhunt.env.rendering import render_rgb

        return render_rgb(self)


def _whole_multiple(value: float, unit: float, name: str, unit_name: str) -> int:
    count = round(value / unit)
    if count < 1 or abs(count * unit - value) > 1e-9:
        raise ValueError(
            f"{name} ({value:g} s) must be a positive multiple of the {unit_name} ({unit:g} s)"
        )
    return count
