"""A conservative controller no human can make fail, and mutants of it with one planted bug each.

:class:`ConservativeController` follows the route like
:class:`~hazardhunt.sut.pursuit.PursuitController` and stops whenever the human is closer to the
robot's outline than a stop distance derived from the robot's and the human's limits (the
arithmetic is in its docstring). It is the original of the mutation benchmark
(``benchmarks/mutants.py``, docs/search-methods.md): a tester must find no failure against it,
and should find the failure each mutant hides. Each mutant is a subclass that changes one
narrow thing, the way a real bug would, and names in its docstring the human behaviour that
exposes it. All of them are plug-ins like a user's controller::

    hazardhunt run --controller hazardhunt.benchmark.conservative:StaleTrack ...
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from hazardhunt.sut.protocols import ControlCommand, RobotParams, RobotState, TrackedHuman
from hazardhunt.sut.route import Route
from hazardhunt.world.bodies import HumanParams
from hazardhunt.world.floor import FloorMap
from hazardhunt.world.geometry import FloatArray, point_rectangle_clearance, to_body_frame

FEET_PER_METRE = 1 / 0.3048
"""Feet in one metre."""

STOPPED_FOR_HUMAN = "stopped for human"
"""The status of a stop for a human within the stop distance."""
STOPPED_UNSEEN = "stopped: human not seen"
"""The status of a stop because the human is not seen."""


@dataclass(frozen=True)
class StopBudget:
    """The stop distance the controller keeps, term by term, in m (see
    :class:`ConservativeController`)."""

    human_travel: float
    """How far the human can walk from the last look that allowed driving until the robot
    stands: top speed x (control period + braking time)."""
    robot_travel: float
    """How far the robot's centre can drive meanwhile: cruise x control period + braking
    distance."""
    robot_swing: float
    """How far a corner can swing meanwhile while turning: top turn rate x half diagonal x
    (control period + braking time)."""
    margin: float
    """Left over when all of the above happen at once."""

    @property
    def stop_distance(self) -> float:
        """Clearance between the human disc and the robot's outline at which the robot stops,
        in m."""
        return self.human_travel + self.robot_travel + self.robot_swing + self.margin


class ConservativeController:
    """Follows the route slowly and stops whenever a human could reach the robot before it stands.

    **The worst case.** The controller looks at control instants only, ``T`` = 0.2 s apart, at the
    tracked position of that instant. Say that at one instant it sees the human with clearance
    ``c`` (between the human disc and the robot's rectangle) and keeps driving. The earliest it
    can react to anything is the next instant, ``T`` later; then it commands speed 0 and the
    robot brakes at its normal deceleration ``a`` (``RobotParams.max_acceleration``, 1 m/s^2)
    from at most the cruise speed ``v``, which takes ``v / a``. Over the whole window
    ``W = T + v / a`` the clearance can shrink by at most:

    - the human walking straight at the robot: ``v_h W`` (``v_h`` = 1.5 m/s);
    - the robot's centre driving towards the human: ``v T + v^2 / (2 a)``;
    - a corner of the rectangle swinging towards the human while the robot turns (it may turn
      while it brakes): ``omega_max r W``, ``r`` the half diagonal (0.41 m), ``omega_max``
      the robot's top turn rate (0.5 rad/s).

    (Clearance to a moving rectangle shrinks no faster than the human's speed plus the speed of
    the rectangle's fastest point, ``v + omega_max r``.) With the defaults, ``v`` = 0.6 m/s:
    ``W`` = 0.8 s, human 1.20 m + robot 0.30 m + swing 0.16 m + margin 0.10 m = **1.76 m**. The
    controller stops when the clearance is at most that **stop distance** and drives on only when
    it is larger, so the robot stands (speed 0 < 0.05 m/s: SPEC 4 exception i) before any human
    can touch it. The thresholds are computed in :meth:`reset` from the robot parameters it
    receives and the human limits it is given (:meth:`stop_budget`); nothing is hard-coded.

    **Every side.** The clearance is measured to the whole outline, so the rule is the same in
    front, beside and behind the robot. It does not lean on exception ii (a human running into
    the rear of a moving robot faster than it is safe): a slower human behind a robot that turns
    (its rear corner swings sideways into the human) is not safe, and the stop rule covers it
    like any other approach. A human the cameras do not see (a blind zone) could be anywhere
    near: the robot stops until it is seen again.

    **The route.** It steers towards a look-ahead point on the route (pure pursuit) at
    ``cruise_speed``: 0.6 m/s reaches the built-in scenarios' goal 16 m away in about 27 s of
    the 30 s episode when nobody is in the way.
    """

    def __init__(
        self,
        cruise_speed: float = 0.6,
        lookahead: float = 1.0,
        human_max_speed: float = HumanParams.max_speed,
        human_radius: float = HumanParams.radius,
        margin: float = 0.1,
        control_period: float = 0.2,
    ) -> None:
        """Args:
        cruise_speed: Speed along the route, in m/s.
        lookahead: Distance ahead on the route the robot steers towards, in m.
        human_max_speed: The human's top speed the stop distance allows for, in m/s.
        human_radius: The radius of the human disc, in m.
        margin: Clearance left when everything goes against the robot at once, in m.
        control_period: Time between two calls, in s.
        """
        values = {
            "cruise_speed": cruise_speed,
            "lookahead": lookahead,
            "human_max_speed": human_max_speed,
            "control_period": control_period,
        }
        for name, value in values.items():
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, not {value!r}")
        if not (math.isfinite(human_radius) and human_radius >= 0 and margin >= 0):
            raise ValueError("human_radius and margin must be non-negative")
        self.cruise_speed = cruise_speed
        self.lookahead = lookahead
        self.human_max_speed = human_max_speed
        self.human_radius = human_radius
        self.margin = margin
        self.control_period = control_period
        self.robot = RobotParams()
        self.stop_distance = self.stop_budget(self.robot).stop_distance
        self.floor: FloorMap | None = None
        self._route: Route | None = None
        self._progress = 0.0

    def stop_budget(self, params: RobotParams) -> StopBudget:
        """The stop distance's terms for a robot with ``params`` (see the class docstring)."""
        speed = min(self.cruise_speed, params.max_speed)
        window = self.control_period + speed / params.max_acceleration
        return StopBudget(
            human_travel=self.human_max_speed * window,
            robot_travel=speed * self.control_period + speed**2 / (2 * params.max_acceleration),
            robot_swing=params.max_yaw_rate * params.half_diagonal * window,
            margin=self.margin,
        )

    def reset(self, floor: FloorMap, route: Route, robot: RobotState, params: RobotParams) -> None:
        """Start following ``route`` on ``floor``; the stop distance is derived from ``params``."""
        self.floor = floor
        self.robot = params
        self.stop_distance = self.stop_budget(params).stop_distance
        self._route = route
        self._progress = route.project(np.array([robot.x, robot.y]))

    def control(self, time: float, robot: RobotState, human: TrackedHuman | None) -> ControlCommand:
        """Stop if the human is (or could be) within the stop distance, else follow the route."""
        route = self._route
        if route is None:
            raise RuntimeError("reset() must be called before control()")
        self._progress = route.project(
            np.array([robot.x, robot.y]), self._progress, self._progress + 2.0
        )
        if self.human_threatens(time, robot, human):
            status = STOPPED_UNSEEN if human is None else STOPPED_FOR_HUMAN
            return ControlCommand(speed=0.0, yaw_rate=0.0, status=status)
        return self.follow_route(robot, self.cruise_speed)

    def follow_route(self, robot: RobotState, cruise_speed: float) -> ControlCommand:
        """The command towards the look-ahead point on the route at up to ``cruise_speed``
        (slowing down for the goal), from the progress :meth:`control` last found."""
        route = self._route
        if route is None:
            raise RuntimeError("reset() must be called before control()")
        remaining = route.length - self._progress
        if remaining < 0.05:
            return ControlCommand(speed=0.0, yaw_rate=0.0, status="at goal")
        target = route.point_at(min(self._progress + self.lookahead, route.length))
        forward, left = to_body_frame(target, robot.x, robot.y, robot.heading)
        curvature = 2.0 * left / max(forward * forward + left * left, 1e-9)
        speed = min(cruise_speed, self.robot.max_speed, 2.0 * remaining)
        limit = self.robot.max_yaw_rate
        yaw_rate = float(np.clip(speed * curvature, -limit, limit))
        return ControlCommand(speed=speed, yaw_rate=yaw_rate)

    def human_threatens(self, time: float, robot: RobotState, human: TrackedHuman | None) -> bool:
        """Whether the robot must stop: the human is not seen, or within the stop distance."""
        if human is None:
            return True
        return self.clearance(robot, self.human_position(time, human)) <= self.stop_distance

    def human_position(self, time: float, human: TrackedHuman) -> FloatArray:
        """Where the controller takes the human to be, in m (the tracked position)."""
        return human.position

    def clearance(self, robot: RobotState, human_position: FloatArray) -> float:
        """Clearance between the human disc at ``human_position`` and the robot's outline, in m."""
        forward, left = to_body_frame(human_position, robot.x, robot.y, robot.heading)
        outline = point_rectangle_clearance(forward, left, self.robot.length, self.robot.width)
        return outline - self.human_radius

    @property
    def remaining_route(self) -> float:
        """Distance left along the route to the goal, in m."""
        return math.inf if self._route is None else self._route.length - self._progress


# ---------------------------------------------------------------------------------- mutants
class BlindRightRear(ConservativeController):
    """Mutant: humans in the robot's right rear quarter are ignored (a sensor sector dropped).

    The bug: a scanner's or camera's sector is missing from the merged view, so a human whose
    bearing from the robot's centre lies between straight behind and straight right is never
    seen. Exposed by a human who comes up from behind on the robot's right and walks into the
    rear half of its right side while it drives: the robot notices only once the human is
    abeam, too late to stand before the contact.
    """

    def human_threatens(self, time: float, robot: RobotState, human: TrackedHuman | None) -> bool:
        if human is not None:
            forward, left = to_body_frame(human.position, robot.x, robot.y, robot.heading)
            if forward < 0 and left < 0:
                return False
        return super().human_threatens(time, robot, human)


class StaleTrack(ConservativeController):
    """Mutant: the controller uses where the human was ``lag`` seconds ago (a stale track).

    The bug: the tracking results reach the controller through a queue that is read a second
    late, so every decision is taken on the human's position of about 1 s before. A human
    standing or strolling is placed almost right; one who sprints at the robot from just
    outside the stop distance has covered 1.5 m before the controller notices. Exposed by a
    human who waits beside the route and dashes into the robot's side at full speed as it
    passes.
    """

    def __init__(self, lag: float = 1.0, **options: float) -> None:
        """Args:
        lag: How old the position the controller uses is, in s.
        **options: Those of :class:`ConservativeController`.
        """
        super().__init__(**options)
        self.lag = lag
        self._track: deque[tuple[float, FloatArray]] = deque()

    def reset(self, floor: FloorMap, route: Route, robot: RobotState, params: RobotParams) -> None:
        super().reset(floor, route, robot, params)
        self._track.clear()

    def human_position(self, time: float, human: TrackedHuman) -> FloatArray:
        self._track.append((time, human.position.copy()))
        while len(self._track) > 1 and self._track[1][0] <= time - self.lag + 1e-9:
            self._track.popleft()
        return self._track[0][1]


class BlindAfterRestart(ConservativeController):
    """Mutant: after stopping for a human, the first ``blind_time`` seconds of driving again
    ignore humans (a bug after a restart).

    The bug: the "resume" path of the stop logic suppresses the human check while the robot
    gets going, so that it does not stop again at once for the same human walking away. Exposed
    by a human who makes the robot stop, steps back out of the stop distance, and walks into it
    as soon as it moves off again.
    """

    def __init__(self, blind_time: float = 3.0, **options: float) -> None:
        """Args:
        blind_time: How long after driving off the human check stays off, in s.
        **options: Those of :class:`ConservativeController`.
        """
        super().__init__(**options)
        self.blind_time = blind_time
        self._stopped = False
        self._driving_since: float | None = None

    def reset(self, floor: FloorMap, route: Route, robot: RobotState, params: RobotParams) -> None:
        super().reset(floor, route, robot, params)
        self._stopped = False
        self._driving_since = None

    def human_threatens(self, time: float, robot: RobotState, human: TrackedHuman | None) -> bool:
        if self._driving_since is not None and time - self._driving_since < self.blind_time:
            return False
        threatens = super().human_threatens(time, robot, human)
        if self._stopped and not threatens:
            self._driving_since = time
        self._stopped = threatens
        return threatens


class StopDistanceConvertedTwice(ConservativeController):
    """Mutant: the stop distance is converted from feet to metres although it is in metres (a
    units slip).

    The bug: the derived stop distance passes through a settings layer that stores distances
    in feet and converts what it reads to metres, so the 1.76 m are read as 1.76 ft: 0.54 m. A
    human strolling up to the robot is still stopped for in time; exposed by a human who waits
    beside the route and runs into the robot's side as it passes.
    """

    def reset(self, floor: FloorMap, route: Route, robot: RobotState, params: RobotParams) -> None:
        super().reset(floor, route, robot, params)
        self.stop_distance /= FEET_PER_METRE


class DockingMode(ConservativeController):
    """Mutant: within ``docking_distance`` of the goal the human check is off (a docking mode).

    The bug: a docking mode for the last metres to the goal, meant for a fenced station, turns
    the human check off so that the robot can drive close to the station's structure. Exposed
    by a human who waits near the goal and walks into the robot as it docks.
    """

    def __init__(self, docking_distance: float = 3.0, **options: float) -> None:
        """Args:
        docking_distance: Distance to the goal along the route below which the robot docks,
            in m.
        **options: Those of :class:`ConservativeController`.
        """
        super().__init__(**options)
        self.docking_distance = docking_distance

    def human_threatens(self, time: float, robot: RobotState, human: TrackedHuman | None) -> bool:
        if self.remaining_route < self.docking_distance:
            return False
        return super().human_threatens(time, robot, human)


class StandingHumanInLaneOnly(ConservativeController):
    """Mutant: a human slower than ``standing_speed`` counts only when it stands in the robot's
    lane ahead.

    The bug: a filter meant to keep the robot from stopping for people who stand at the side of
    the aisle (no hazard unless they are in the robot's way) decides "standing" with a speed
    threshold of 0.5 m/s, estimated from the last two tracked positions. A person stepping
    slowly is taken for a standing one. Exposed by a human who waits beside the route and steps
    slowly into the robot's side as it passes.
    """

    def __init__(self, standing_speed: float = 0.5, **options: float) -> None:
        """Args:
        standing_speed: Below this estimated speed a human counts as standing, in m/s.
        **options: Those of :class:`ConservativeController`.
        """
        super().__init__(**options)
        self.standing_speed = standing_speed

    def human_threatens(self, time: float, robot: RobotState, human: TrackedHuman | None) -> bool:
        if human is not None and estimated_speed(human) < self.standing_speed:
            forward, left = to_body_frame(human.position, robot.x, robot.y, robot.heading)
            in_lane = abs(left) < self.robot.width / 2 + self.human_radius
            if not (forward > 0 and in_lane):
                return False
        return super().human_threatens(time, robot, human)


def estimated_speed(human: TrackedHuman) -> float:
    """The human's speed from its last two tracked positions, in m/s (0 from one sighting)."""
    if len(human.recent_times) < 2:
        return 0.0
    step = human.recent_positions[-1] - human.recent_positions[-2]
    elapsed = float(human.recent_times[-1] - human.recent_times[-2])
    return float(np.hypot(*step)) / elapsed if elapsed > 0 else 0.0


class IgnoresHumanWalkingAlongside(ConservativeController):
    """Mutant: a human walking in about the robot's own direction is ignored.

    The bug: a filter meant to let the robot follow people who walk ahead of it down an aisle
    ignores every human whose heading is within ``alongside_angle`` of the robot's heading, on
    the belief that someone walking the same way cannot run into it. A human who walks
    alongside and veers into the robot at a shallow angle is never seen. Exposed when the robot
    overtakes a human who then cuts into its side.
    """

    def __init__(self, alongside_angle: float = math.radians(30), **options: float) -> None:
        """Args:
        alongside_angle: Largest angle between the two headings that counts as walking
            alongside, in rad.
        **options: Those of :class:`ConservativeController`.
        """
        super().__init__(**options)
        self.alongside_angle = alongside_angle

    def human_threatens(self, time: float, robot: RobotState, human: TrackedHuman | None) -> bool:
        if human is not None and math.cos(human.heading - robot.heading) > math.cos(
            self.alongside_angle
        ):
            return False
        return super().human_threatens(time, robot, human)


MUTANTS: tuple[type[ConservativeController], ...] = (
    BlindRightRear,
    StaleTrack,
    BlindAfterRestart,
    StopDistanceConvertedTwice,
    DockingMode,
    StandingHumanInLaneOnly,
    IgnoresHumanWalkingAlongside,
)
"""The mutants of :class:`ConservativeController`, one planted bug each."""
