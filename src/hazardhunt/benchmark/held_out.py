"""Mutants of the conservative controller written after the testers' defaults were settled.

The mutants of :mod:`hazardhunt.benchmark.conservative` were at hand while the defaults (the
portfolio's arms, the searchers' settings) were chosen, so a score on them flatters those
defaults. The mutants here were written afterwards, to judge the defaults on bugs they were not
tuned to; no default may be tuned on them (``benchmarks/mutants.py --held-out``). Like the
others, each is a subclass of :class:`~hazardhunt.benchmark.conservative.ConservativeController`
with one planted bug, and a plug-in::

    hazardhunt run --controller hazardhunt.benchmark.held_out:CreepsAfterWaiting ...
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from hazardhunt.benchmark.conservative import (
    STOPPED_FOR_HUMAN,
    STOPPED_UNSEEN,
    ConservativeController,
    estimated_speed,
)
from hazardhunt.sut.protocols import ControlCommand, RobotParams, RobotState, TrackedHuman
from hazardhunt.sut.route import Route
from hazardhunt.world.floor import FloorMap
from hazardhunt.world.geometry import FloatArray, to_body_frame


class CreepsAfterWaiting(ConservativeController):
    """Mutant: after standing ``patience`` seconds for a human, the robot creeps on with a stop
    distance of ``creep_distance`` (an anti-deadlock mode).

    The bug: to get through aisles where people linger, a robot that has waited long enough
    for a human drives on at ``creep_speed`` and stops only for a human within
    ``creep_distance``, on the belief that at a creep it can always stop in time. It cannot for
    a human who moves: the stop distance no longer covers how far a person walks before the
    robot stands. Exposed by a human who stands close beside the route until the robot has
    waited, and steps into its side as it creeps past.
    """

    def __init__(
        self,
        patience: float = 4.0,
        creep_speed: float = 0.3,
        creep_distance: float = 0.2,
        **options: float,
    ) -> None:
        """Args:
        patience: How long the robot stands for a human before it creeps on, in s.
        creep_speed: Its speed while it creeps, in m/s.
        creep_distance: The stop distance while it creeps, in m.
        **options: Those of :class:`ConservativeController`.
        """
        super().__init__(**options)
        self.patience = patience
        self.creep_speed = creep_speed
        self.creep_distance = creep_distance
        self._waiting_since: float | None = None
        self._creeping = False

    def reset(self, floor: FloorMap, route: Route, robot: RobotState, params: RobotParams) -> None:
        super().reset(floor, route, robot, params)
        self._waiting_since = None
        self._creeping = False

    def control(self, time: float, robot: RobotState, human: TrackedHuman | None) -> ControlCommand:
        command = super().control(time, robot, human)
        if self._creeping and command.speed > 0.0:
            return ControlCommand(
                speed=min(command.speed, self.creep_speed),
                yaw_rate=command.yaw_rate,
                status="creeping",
            )
        return command

    def human_threatens(self, time: float, robot: RobotState, human: TrackedHuman | None) -> bool:
        if human is None:
            return True
        clearance = self.clearance(robot, self.human_position(time, human))
        if self._creeping:
            return clearance <= self.creep_distance
        if clearance > self.stop_distance:
            self._waiting_since = None
            return False
        if self._waiting_since is None:
            self._waiting_since = time
        self._creeping = time - self._waiting_since >= self.patience
        return not self._creeping


class AbsorbedIntoStaticMap(ConservativeController):
    """Mutant: a human who stands still for ``absorb_time`` seconds becomes part of the static
    map and is ignored until they have moved ``release_distance`` from where they stood (a
    clutter filter).

    The bug: the tracker folds objects that stop moving into the map of static obstacles (so
    that pallets and racks are not tracked as people), and takes them out again only once they
    have left their spot. A person who waits is such an object. Exposed by a human who stands
    still beside the route and, as the robot passes, steps the few decimetres into its side.
    """

    def __init__(
        self,
        absorb_time: float = 2.0,
        still_speed: float = 0.1,
        release_distance: float = 0.5,
        **options: float,
    ) -> None:
        """Args:
        absorb_time: How long a human must stand still to be folded into the map, in s.
        still_speed: Below this estimated speed a human stands still, in m/s.
        release_distance: How far a folded-in human must move to be tracked again, in m.
        **options: Those of :class:`ConservativeController`.
        """
        super().__init__(**options)
        self.absorb_time = absorb_time
        self.still_speed = still_speed
        self.release_distance = release_distance
        self._still_since: float | None = None
        self._absorbed_at: FloatArray | None = None

    def reset(self, floor: FloorMap, route: Route, robot: RobotState, params: RobotParams) -> None:
        super().reset(floor, route, robot, params)
        self._still_since = None
        self._absorbed_at = None

    def human_threatens(self, time: float, robot: RobotState, human: TrackedHuman | None) -> bool:
        if human is not None:
            if self._absorbed_at is not None:
                moved = float(np.hypot(*(human.position - self._absorbed_at)))
                if moved < self.release_distance:
                    return False
                self._absorbed_at = None
            if estimated_speed(human) >= self.still_speed or len(human.recent_times) < 2:
                self._still_since = None
            elif self._still_since is None:
                self._still_since = time
            elif time - self._still_since >= self.absorb_time:
                self._absorbed_at = human.position.copy()
                self._still_since = None
                return False
        return super().human_threatens(time, robot, human)


class HurriesAfterDelay(ConservativeController):
    """Mutant: once it has stood ``delay`` seconds for a human in all, the robot makes up the
    lost time at ``catch_up_speed``, with the stop distance still reckoned for its cruise speed
    (a schedule catch-up).

    The bug: a fleet manager that holds robots to a timetable lets a delayed robot drive at its
    top speed until it is back on time; the stop distance was computed once, for the cruise
    speed, and nobody recomputed it for the faster one. At 1.2 m/s a human coming at the
    robot's side needs 2.5 m of it (:meth:`ConservativeController.stop_budget` without the
    robot's own travel), and it keeps 1.76. Exposed by a human who holds the robot up, steps
    aside, and walks into its side once it has sped up.
    """

    def __init__(self, delay: float = 2.0, catch_up_speed: float = 1.2, **options: float) -> None:
        """Args:
        delay: How long the robot must have stood for a human before it hurries, in s.
        catch_up_speed: Its speed while it makes up the time, in m/s.
        **options: Those of :class:`ConservativeController`.
        """
        super().__init__(**options)
        self.delay = delay
        self.catch_up_speed = catch_up_speed
        self._planned_speed = self.cruise_speed
        self._stood = 0.0
        self._last_time: float | None = None

    def reset(self, floor: FloorMap, route: Route, robot: RobotState, params: RobotParams) -> None:
        self.cruise_speed = self._planned_speed  # the stop distance is reckoned for it
        super().reset(floor, route, robot, params)
        self._stood = 0.0
        self._last_time = None

    def control(self, time: float, robot: RobotState, human: TrackedHuman | None) -> ControlCommand:
        elapsed = 0.0 if self._last_time is None else time - self._last_time
        self._last_time = time
        hurrying = self._stood >= self.delay
        if hurrying:  # the route is followed faster; the stop distance stays as it was
            self.cruise_speed = self.catch_up_speed
        command = super().control(time, robot, human)
        if command.status in (STOPPED_FOR_HUMAN, STOPPED_UNSEEN):
            self._stood += elapsed
        elif hurrying and command.speed > 0.0:
            return dataclasses.replace(command, status="catching up")
        return command


class TakenForTheRacks(ConservativeController):
    """Mutant: a human within ``band`` m of a shelf or wall is taken for part of it and ignored
    (a map-matching filter).

    The bug: to keep the racks' own reflections from stopping the robot, the perception drops
    whatever it sees within a band along the mapped obstacles, and a person standing against a
    rack is inside that band. Exposed by a human who waits against a rack beside the aisle and
    steps out into the robot's side as it passes: seen only once out of the band, too close to
    stop for.
    """

    def __init__(self, band: float = 0.5, **options: float) -> None:
        """Args:
        band: Distance from a mapped obstacle within which a human is ignored, in m.
        **options: Those of :class:`ConservativeController`.
        """
        super().__init__(**options)
        self.band = band

    def human_threatens(self, time: float, robot: RobotState, human: TrackedHuman | None) -> bool:
        if (
            human is not None
            and self.floor is not None
            and self.floor.obstacle_clearance(human.position) < self.band
        ):
            return False
        return super().human_threatens(time, robot, human)


class ForgetsPassedHuman(ConservativeController):
    """Mutant: a human the robot has driven past is forgotten for the rest of the episode (a
    "dealt with" flag).

    The bug: a planner that keeps the people on its way in a list strikes off each one the
    robot has passed, so that someone walking away behind it does not hold it up; nothing puts
    them back. Exposed by a human who keeps clear of the robot until it has passed, then runs
    after it and into its side.
    """

    def __init__(self, **options: float) -> None:
        """Args:
        **options: Those of :class:`ConservativeController`.
        """
        super().__init__(**options)
        self._passed = False

    def reset(self, floor: FloorMap, route: Route, robot: RobotState, params: RobotParams) -> None:
        super().reset(floor, route, robot, params)
        self._passed = False

    def human_threatens(self, time: float, robot: RobotState, human: TrackedHuman | None) -> bool:
        if human is not None and not self._passed:
            forward, _ = to_body_frame(human.position, robot.x, robot.y, robot.heading)
            self._passed = forward < -self.robot.length / 2  # behind the robot's rear
        if self._passed:
            return False
        return super().human_threatens(time, robot, human)


class PriorityAtCrossings(ConservativeController):
    """Mutant: where the floor opens out round the robot (a crossing), it stops only for a
    human in its lane ahead (a right-of-way rule).

    The bug: a traffic rule for the floor gives the robot right of way at crossings, where
    people coming from the side aisles are expected to wait for it, and the human check there
    keeps only the people in the robot's way ahead. Nobody told the people. Exposed by a human
    who comes from a side aisle into the robot's side as it crosses.
    """

    def __init__(self, open_clearance: float = 1.6, **options: float) -> None:
        """Args:
        open_clearance: Distance from the robot's centre to every shelf and wall beyond which
            the robot is at a crossing, in m.
        **options: Those of :class:`ConservativeController`.
        """
        super().__init__(**options)
        self.open_clearance = open_clearance

    def human_threatens(self, time: float, robot: RobotState, human: TrackedHuman | None) -> bool:
        at_crossing = (
            self.floor is not None
            and self.floor.obstacle_clearance(np.array([robot.x, robot.y])) > self.open_clearance
        )
        if human is not None and at_crossing:
            forward, left = to_body_frame(human.position, robot.x, robot.y, robot.heading)
            lane = self.robot.width / 2 + self.human_radius
            if not (forward > 0 and abs(left) < lane):
                return False
        return super().human_threatens(time, robot, human)


class TrackHeldWhileRelocalising(ConservativeController):
    """Mutant: every ``period`` seconds, for ``hold`` seconds, the controller keeps using the
    human's position from the start of the hold (the track is held while the robot
    relocalises).

    The bug: to bound its drift, the localisation restarts every 5 s; while it settles, the
    tracker cannot place people in the map and hands on the last position it had, as if
    nobody had moved. A person standing or strolling is placed almost right; one who sprints
    at the robot just as a hold begins has covered 1.2 m before the controller sees them move.
    Exposed by a human who waits beside the route and runs into the robot's side at the start
    of a hold.
    """

    def __init__(self, period: float = 5.0, hold: float = 0.8, **options: float) -> None:
        """Args:
        period: Time between two holds, in s (the first starts at 0).
        hold: How long each hold lasts, in s.
        **options: Those of :class:`ConservativeController`.
        """
        super().__init__(**options)
        self.period = period
        self.hold = hold
        self._held: FloatArray | None = None

    def reset(self, floor: FloorMap, route: Route, robot: RobotState, params: RobotParams) -> None:
        super().reset(floor, route, robot, params)
        self._held = None

    def human_position(self, time: float, human: TrackedHuman) -> FloatArray:
        if (time + 1e-9) % self.period < self.hold - 1e-9:  # a first instant rounded down too
            if self._held is None:
                self._held = human.position.copy()
            return self._held
        self._held = None
        return human.position


class SlowsForPeopleBeside(ConservativeController):
    """Mutant: for a human within the stop distance but beside or behind the robot (more than
    ``beside_angle`` off its heading), it slows to ``slow_speed`` instead of stopping.

    The bug: a comfort rule meant to keep the robot moving past people who stand at the side
    of the aisle replaces the stop by a slow-down when the human is not ahead, on the belief
    that at a walking pace nobody gets hurt. The contact rule counts any contact with a robot
    that moves. Exposed by a human who waits beside the route and runs into the robot's side as
    it passes.
    """

    def __init__(
        self, beside_angle: float = math.radians(60), slow_speed: float = 0.2, **options: float
    ) -> None:
        """Args:
        beside_angle: Smallest angle between the robot's heading and the bearing of the human
            at which it only slows down, in rad.
        slow_speed: The speed it slows to, in m/s.
        **options: Those of :class:`ConservativeController`.
        """
        super().__init__(**options)
        self.beside_angle = beside_angle
        self.slow_speed = slow_speed

    def control(self, time: float, robot: RobotState, human: TrackedHuman | None) -> ControlCommand:
        command = super().control(time, robot, human)
        if command.status != STOPPED_FOR_HUMAN or human is None:
            return command
        forward, left = to_body_frame(human.position, robot.x, robot.y, robot.heading)
        if abs(math.atan2(left, forward)) <= self.beside_angle:
            return command
        return self.follow_route(robot, self.slow_speed)


class FastTracksTakenForGhosts(ConservativeController):
    """Mutant: a human tracked faster than ``plausible_speed`` is taken for a false detection
    and ignored (a plausibility filter).

    The bug: to keep reflections and sensor ghosts, which jump from scan to scan, from stopping
    the robot, the perception drops every track whose speed, estimated from its last two
    positions, is beyond what a walking person does (1.2 m/s). A person who runs is faster.
    Exposed by a human who runs into the robot's side.
    """

    def __init__(self, plausible_speed: float = 1.2, **options: float) -> None:
        """Args:
        plausible_speed: Above this estimated speed a track is ignored, in m/s.
        **options: Those of :class:`ConservativeController`.
        """
        super().__init__(**options)
        self.plausible_speed = plausible_speed

    def human_threatens(self, time: float, robot: RobotState, human: TrackedHuman | None) -> bool:
        if human is not None and estimated_speed(human) > self.plausible_speed:
            return False
        return super().human_threatens(time, robot, human)


class TakesSlowingForYielding(ConservativeController):
    """Mutant: a human who slowed down by more than ``slowing`` between the last two looks is
    taken to be giving way, and the robot drives on for that look.

    The bug: to pass people who stop for it (as people at a crossing do), the robot reads a
    human who slows down as one who yields, and does not stop for them. A person slowing down
    is not standing still: someone who runs in uneven strides, or who checks their stride before
    running on, is ignored at every look that follows a slower stride. Exposed by a human who
    runs at the robot's side, every other stride slower.
    """

    def __init__(self, slowing: float = 0.3, **options: float) -> None:
        """Args:
        slowing: The drop in speed between the last two looks, in m/s, above which the
            human is taken to give way.
        **options: Those of :class:`ConservativeController`.
        """
        super().__init__(**options)
        self.slowing = slowing

    def human_threatens(self, time: float, robot: RobotState, human: TrackedHuman | None) -> bool:
        if human is not None and len(human.recent_times) == 3:
            steps = np.diff(human.recent_positions, axis=0)  # consecutive tracking instants
            speeds = np.linalg.norm(steps, axis=1) / np.diff(human.recent_times)
            if speeds[0] - speeds[1] > self.slowing:
                return False
        return super().human_threatens(time, robot, human)


class BoostsInClearAisle(ConservativeController):
    """Mutant: while nobody is in its lane ahead, the robot drives at ``boost_speed``; its stop
    distance stays the one for its cruise speed.

    The bug: to make up time on long free stretches, the robot speeds up whenever its lane is
    clear for ``lookout`` m ahead, but the stop distance was derived once, for the cruise speed
    (0.6 m/s, 1.76 m): at 1.2 m/s it would need 3.45 m. A human in the lane ahead slows it back
    down; one beside the lane does not. With no human tracked it keeps to its cruise speed.
    Exposed by a human who waits beside the route and runs into the robot's side as it passes.
    """

    def __init__(self, boost_speed: float = 1.2, lookout: float = 4.0, **options: float) -> None:
        """Args:
        boost_speed: The speed on a clear stretch, in m/s.
        lookout: How far ahead of its front face the lane (0.5 m beyond either side of the
            robot) must be clear, in m.
        **options: Those of :class:`ConservativeController`.
        """
        super().__init__(**options)
        self.boost_speed = boost_speed
        self.lookout = lookout

    def control(self, time: float, robot: RobotState, human: TrackedHuman | None) -> ControlCommand:
        command = super().control(time, robot, human)
        if command.speed <= 0.0 or human is None:
            return command
        forward, left = to_body_frame(human.position, robot.x, robot.y, robot.heading)
        front = 0.5 * self.robot.length
        in_lane = abs(left) <= 0.5 * self.robot.width + 0.5 + self.human_radius
        if in_lane and front <= forward <= front + self.lookout + self.human_radius:
            return command
        return self.follow_route(robot, self.boost_speed)


class DebouncedStop(ConservativeController):
    """Mutant: the robot stops for a human only once they have been within the stop distance
    at ``confirm`` looks in a row (a debounce).

    The bug: to keep a flickering detection at the edge of the stop distance from making the
    robot stop and go, the stop is confirmed over several looks; a human who steps out again
    starts the count anew. Each look of confirmation is 0.2 s in which the robot drives on
    and a running person covers 0.3 m, which the stop distance does not allow for. Exposed by
    a human who runs straight into the robot's side.
    """

    def __init__(self, confirm: int = 4, **options: float) -> None:
        """Args:
        confirm: Looks in a row the human must be within the stop distance for the robot to
            stop.
        **options: Those of :class:`ConservativeController`.
        """
        super().__init__(**options)
        self.confirm = confirm
        self._within = 0

    def reset(self, floor: FloorMap, route: Route, robot: RobotState, params: RobotParams) -> None:
        super().reset(floor, route, robot, params)
        self._within = 0

    def human_threatens(self, time: float, robot: RobotState, human: TrackedHuman | None) -> bool:
        threatened = super().human_threatens(time, robot, human)
        if human is None:  # not seen: stop at once, as the original does
            self._within = 0
            return threatened
        self._within = self._within + 1 if threatened else 0
        return self._within >= self.confirm


HELD_OUT_MUTANTS: tuple[type[ConservativeController], ...] = (
    CreepsAfterWaiting,
    AbsorbedIntoStaticMap,
    HurriesAfterDelay,
    TakenForTheRacks,
    ForgetsPassedHuman,
    PriorityAtCrossings,
    TrackHeldWhileRelocalising,
    SlowsForPeopleBeside,
    FastTracksTakenForGhosts,
    TakesSlowingForYielding,
    BoostsInClearAisle,
    DebouncedStop,
)
"""The held-out mutants, one planted bug each. The first three were written once the
portfolio's arms were settled; the next two after its ``closer_gain`` was; the sixth after
every setting of the portfolio had been published, the next three after that, and the last
three (the fifth set) before any variant of the portfolio with the ``ambush`` space was run
on them. No default has been tuned on any of them."""
