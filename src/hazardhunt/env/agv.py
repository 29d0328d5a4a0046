"""The AGV workplace as a Gymnasium environment: the tester moves the human, the SUT the robot.

A thin shell around :class:`~hazardhunt.sim.Simulation`: one ``step`` is one decision of the
simulation, encoded as an observation, a reward and an ``info`` dict.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from hazardhunt.env.observation import OBSERVATION_FEATURES, encode_observation
from hazardhunt.sim.simulation import DecisionReport, Simulation, SimulationSettings
from hazardhunt.spec.episode import EpisodeSummary
from hazardhunt.spec.rewards import REWARD_KINDS, RewardKind, decision_reward
from hazardhunt.sut.protocols import Controller, SafetyLayer
from hazardhunt.world.scenario import Scenario

ObsType = NDArray[np.float32]
ActType = NDArray[np.float32]

_NO_DECISION = DecisionReport()


class AGVEnv(gym.Env[ObsType, ActType]):
    """The simulated human (the agent) against the robot's control stack (the SUT).

    Action: two numbers in [-1, 1]: the human's walking speed, mapped linearly to
    [0, ``human.max_speed``] m/s, and turn rate, mapped to [-``human.max_turn_rate``,
    ``human.max_turn_rate``] rad/s. Observation: ``OBSERVATION_FEATURES``, in [-1, 1].

    ``info`` after every step (and reset) holds only simulated values, so that the same seed
    and actions give the same infos (wall-clock times are in ``simulation.timing()``):

    - ``outcome`` (str or None): how the episode ended, None while it goes on;
    - ``unsafe`` / ``contact`` (bool): an unsafe contact / any contact in this decision step;
    - ``contact_verdict`` (str): see :class:`~hazardhunt.spec.safety.ContactVerdict`;
      ``contact_face`` (str or None): the robot's face the human touched;
    - ``clearance`` (m): gap between human and robot at the end of the step;
      ``min_clearance`` (m): smallest gap in the episode so far;
    - ``risk``: largest risk within the step; ``risk_sum``: sum over its physics steps;
      ``max_risk``: largest risk of the episode so far;
    - ``emergency_stop`` (bool): the safety layer's stop holds at the end of the step;
      ``emergency_stops``: stops triggered in the episode; ``human_in_field`` (bool);
      ``time_in_field`` (s, episode);
    - ``human_visible`` (bool): the cameras see the human;
    - ``controller_status`` (str): status of the controller's last command;
      ``controller_failures``: failed commands within the step;
    - ``sim_time`` (s), ``decision_step`` (int);
    - at the episode's end also ``summary``: the
      :class:`~hazardhunt.spec.episode.EpisodeSummary`.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 5}  # noqa: RUF012

    def __init__(
        self,
        scenario: str | Scenario = "crossing",
        field: str = "1.25m",
        reward: RewardKind = "max",
        settings: SimulationSettings | float = SimulationSettings(),
        *,
        controller: Controller | None = None,
        safety_layer: SafetyLayer | None = None,
        render_mode: str | None = None,
        **changes: Any,
    ) -> None:
        """Build the environment (see :meth:`Simulation.build`).

        Args:
            scenario: A built-in scenario name (``crossing``, ``head-on``, ``overtaking``), a
                scenario file path, or a loaded :class:`Scenario`.
            field: Protective-field setting: ``none``, ``1.25m``, ``2m`` or a field the
                scenario defines.
            reward: ``acc`` (accumulated risk) or ``max`` (episode's maximum risk at the end).
            settings: The simulation's settings (periods, limits, the robot's and human's
                parameters, the NMPC's solver; defaults from SPEC). A number: the decision
                period, as the fourth argument was before 0.2.0, with a warning.
            controller: The robot's controller; the CasADi NMPC when None.
            safety_layer: The safety layer; the laser field of ``field`` when None.
            render_mode: None or ``rgb_array``.
            **changes: Fields of :class:`~hazardhunt.sim.simulation.SimulationSettings` to
                change in ``settings``, e.g. ``decision_period=1.0`` (also through
                ``gymnasium.make``).
        """
        simulation = Simulation.build(
            scenario,
            field,
            settings,
            controller=controller,
            safety_layer=safety_layer,
            **changes,
        )
        self._wrap(simulation, reward, render_mode)

    @classmethod
    def wrapping(
        cls, simulation: Simulation, reward: RewardKind = "max", render_mode: str | None = None
    ) -> AGVEnv:
        """The environment around an already built simulation."""
        env = cls.__new__(cls)
        env._wrap(simulation, reward, render_mode)
        return env

    def _wrap(self, simulation: Simulation, reward: RewardKind, render_mode: str | None) -> None:
        if reward not in REWARD_KINDS:
            raise ValueError(f"reward must be one of {list(REWARD_KINDS)}, not {reward!r}")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', not {render_mode!r}")
        self.simulation = simulation
        self.reward_kind: RewardKind = reward
        self.render_mode = render_mode
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.observation_space = spaces.Box(
            -1.0, 1.0, shape=(len(OBSERVATION_FEATURES),), dtype=np.float32
        )
        self._route_progress = 0.0

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[ObsType, dict[str, Any]]:
        """Put human and robot at the scenario's initial state (the simulation draws no random
        numbers: the seed only seeds ``np_random``)."""
        super().reset(seed=seed)
        self.simulation.reset()
        self._route_progress = 0.0
        return self._observation(), self._info(_NO_DECISION, self.simulation.summary())

    def step(self, action: ActType) -> tuple[ObsType, float, bool, bool, dict[str, Any]]:
        """Hold the human's action for one decision period."""
        report = self.simulation.decide(action)
        summary = self.simulation.summary()
        ended = report.terminated or report.truncated
        reward = decision_reward(self.reward_kind, report.risk_sum, summary.max_risk, ended)
        info = self._info(report, summary)
        return self._observation(), reward, report.terminated, report.truncated, info

    def _observation(self) -> ObsType:
        sim = self.simulation
        robot = sim.robot
        self._route_progress = sim.route.project(
            np.array([robot.x, robot.y]), self._route_progress, self._route_progress + 5.0
        )
        floor = sim.scenario.floor
        return encode_observation(
            floor_size=(floor.width, floor.height),
            human_position=sim.human_position,
            human_heading=sim.human_heading,
            human_visible=sim.human_visible,
            human_speed=float(np.hypot(*sim.human_velocity)),
            human_max_speed=sim.human_params.max_speed,
            robot_pose=(robot.x, robot.y, robot.heading),
            robot_speed=robot.speed,
            robot_max_speed=sim.robot_params.max_speed,
            robot_yaw_rate=robot.yaw_rate,
            robot_max_yaw_rate=sim.robot_params.max_yaw_rate,
            emergency_stop=sim.emergency_stop,
            contact=sim.clearance <= 0.0,
            human_in_field=sim.human_in_field,
            clearance=sim.clearance,
            elapsed_fraction=sim.elapsed_fraction,
            route_fraction=self._route_progress / max(sim.route.length, 1e-9),
        )

    def _info(self, report: DecisionReport, summary: EpisodeSummary) -> dict[str, Any]:
        sim = self.simulation
        info: dict[str, Any] = {
            "outcome": summary.outcome,
            "unsafe": report.unsafe,
            "contact": report.contact,
            "contact_verdict": report.contact_verdict,
            "contact_face": summary.contact_face,
            "clearance": sim.clearance,
            "min_clearance": summary.min_clearance,
            "risk": report.risk,
            "risk_sum": report.risk_sum,
            "max_risk": summary.max_risk,
            "emergency_stop": sim.emergency_stop,
            "emergency_stops": summary.emergency_stops,
            "human_in_field": sim.human_in_field,
            "time_in_field": summary.time_in_field,
            "human_visible": sim.human_visible,
            "controller_status": sim.controller_status,
            "controller_failures": report.controller_failures,
            "sim_time": summary.sim_time,
            "decision_step": summary.decision_steps,
        }
        if summary.outcome is not None:
            info["summary"] = summary
        return info

    def render(self) -> NDArray[np.uint8] | None:
        """An RGB picture of the floor, route, robot with its field, and the human."""
        if self.render_mode != "rgb_array":
            return None
        from hazardhunt.env.rendering import render_rgb

        return render_rgb(self.simulation)
