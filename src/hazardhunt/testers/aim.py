"""Decisions aimed at the robot or at its route: search spaces in which a decision says where to go.

An open-loop sequence of (speed, turn rate) decisions reaches the robot only where the robot
happens to be when the sequence is played; most of a search over such sequences is spent on
episodes in which the human never comes near it. Here each decision is three numbers in
[-1, 1] instead, read in the robot's frame at the moment the decision is played:

- the human's speed (-1 stands, 1 is its top speed),
- the bearing around the robot it walks towards (0 straight ahead of the robot, +-0.5 its
  left and right, +-1 behind it),
- how far from the robot's outline it aims to end up (-1 touching it, 1 ``STANDOFF_MAX`` away).

While played, each decision becomes the (speed, turn rate) action whose arc over the decision
period ends nearest that point, with the robot's motion extrapolated over the period from its
current speed and turn rate; the human slows down rather than overshoot. A sequence can so
follow the robot, wait beside it, step back out of its field and come back in, which is how the
failures behind a safety layer happen.

A route decision (the ``route`` space) names a point beside the robot's route instead, three
numbers as well: the speed, how far along the route (-1 its start, 1 its goal) and how far
beside it (+-1: ``ROUTE_OFFSET_MAX`` to the left or right). The human walks there and waits,
which is how it stands in the robot's way, or waits where the robot will be late in its
mission (docking at the goal, say) without making it stop on the way.

An ambush decision (the ``ambush`` space) is five numbers: the speed, a point beside the route
as in ``route`` (how far along, how far beside), a lead (+-1: ``LEAD_MAX`` before or after the
robot comes abreast of the point) and where on the robot's side to run at (-1 its front
corner, 0 the middle, 1 its rear corner). The human walks to the point and waits there until
the robot's centre, along the route, is within the lead of it, then runs at the robot's side
that faces it: the human who waits at the side of an aisle and steps into a robot as it
passes, beside its protective field rather than through it.

The actions played are what the episode records, so it replays exactly without this module.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from hazardhunt.sim.simulation import Simulation
from hazardhunt.testers.clear_path import human_path
from hazardhunt.world.geometry import point_in_body_frame
from hazardhunt.world.navigation import reach

STANDOFF_MAX = 3.0
"""The farthest a decision aims from the robot's outline, in m."""

ROUTE_OFFSET_MAX = 3.0
"""The farthest a route decision aims beside the robot's route, in m."""

LEAD_MAX = 3.0
"""The farthest before (or after) the robot comes abreast of its waiting point that an ambush
decision runs at it, in m along the route."""

TURN_CHOICES = np.linspace(-1.0, 1.0, 17)
"""Normalised turn rates an aimed decision chooses from."""


def aim_point(simulation: Simulation, bearing: float, standoff: float) -> NDArray[np.float64]:
    """Where a decision with ``bearing`` (rad, robot frame) and ``standoff`` (m) aims: the point
    on that bearing from the robot's centre at which the human disc keeps ``standoff`` from the
    robot's outline, with the robot's pose extrapolated over one decision period."""
    robot, period = simulation.robot, simulation.decision_period
    # The robot drives on the same unicycle arc as a human holding its speed and turn rate.
    pose = (robot.x, robot.y, robot.heading)
    x, y = human_path(pose, robot.speed, robot.yaw_rate, period, period)[-1]
    heading = robot.heading + robot.yaw_rate * period
    reach = _ray_to_clearance(
        simulation.robot_params.length / 2,
        simulation.robot_params.width / 2,
        bearing,
        simulation.human_params.radius + standoff,
    )
    return np.array(
        [x + reach * math.cos(heading + bearing), y + reach * math.sin(heading + bearing)]
    )


def aimed_action(
    simulation: Simulation, aim: NDArray[np.floating[Any]], detour: bool = False
) -> NDArray[np.float32]:
    """The normalised (speed, turn rate) action that walks the human, over the next decision
    period, towards the point ``aim`` (speed, bearing, stand-off in [-1, 1]) names (round the
    obstacles with ``detour``: :func:`walk_towards`)."""
    wanted_speed, bearing, standoff = np.clip(np.asarray(aim, dtype=np.float64), -1.0, 1.0)
    target = aim_point(simulation, math.pi * bearing, 0.5 * (standoff + 1.0) * STANDOFF_MAX)
    return walk_towards(simulation, target, wanted_speed, detour)


def route_point(
    simulation: Simulation, along: float, offset: float, fit: bool = False
) -> NDArray[np.float64]:
    """The point ``offset`` (m, positive to the left) beside the robot's route, at the share
    ``along`` (0 the start, 1 the goal) of the route's length.

    With ``fit``, a point the human does not fit at (in a wall or a shelf) is pulled back
    towards the route, to the last place it fits on the way out: in an aisle narrower than
    the offset, the aisle's edge. Without it such a point is walked to as it is, which leaves
    the human wherever the nearest free place is, behind the shelf as often as not.
    """
    route = simulation.route
    x, y, tangent_x, tangent_y = route.frame_at(along * route.length)
    if fit and offset != 0.0:
        side = math.copysign(1.0, offset)
        outwards = np.array([-side * tangent_y, side * tangent_x])
        floor, radius = simulation.scenario.floor, simulation.human_params.radius
        offset = side * reach(floor, radius, np.array([x, y]), outwards, abs(offset))
    return np.array([x - offset * tangent_y, y + offset * tangent_x])


def route_action(
    simulation: Simulation,
    decision: NDArray[np.floating[Any]],
    detour: bool = False,
    fit: bool = False,
) -> NDArray[np.float32]:
    """The normalised (speed, turn rate) action that walks the human, over the next decision
    period, towards the point of the robot's route ``decision`` (speed, share of the route,
    offset beside it in [-1, 1]) names (round the obstacles with ``detour``:
    :func:`walk_towards`; pulled back to where the human fits with ``fit``:
    :func:`route_point`)."""
    wanted_speed, along, offset = np.clip(np.asarray(decision, dtype=np.float64), -1.0, 1.0)
    target = route_point(simulation, 0.5 * (along + 1.0), offset * ROUTE_OFFSET_MAX, fit)
    return walk_towards(simulation, target, wanted_speed, detour)


def ambush_action(
    simulation: Simulation,
    decision: NDArray[np.floating[Any]],
    detour: bool = False,
    fit: bool = False,
) -> NDArray[np.float32]:
    """The normalised (speed, turn rate) action of an ambush ``decision`` (speed, share of the
    route, offset beside it, lead, place on the robot's side, in [-1, 1]): towards the waiting
    point beside the route until the robot's centre (the route point nearest it) comes within
    the lead of it, then at the robot's side that faces the human, aimed as
    :func:`aimed_action` aims (a quarter turn from the robot's heading, an eighth turn more
    towards its rear or its front). With ``fit`` the waiting point is pulled back to where
    the human fits (:func:`route_point`)."""
    wanted_speed, along, offset, lead, at = np.clip(
        np.asarray(decision, dtype=np.float64), -1.0, 1.0
    )
    route, robot = simulation.route, simulation.robot
    share = 0.5 * (along + 1.0)
    if route.project(np.array([robot.x, robot.y])) < share * route.length - lead * LEAD_MAX:
        target = route_point(simulation, share, offset * ROUTE_OFFSET_MAX, fit)
        return walk_towards(simulation, target, wanted_speed, detour)
    x, y, _ = simulation.human_pose
    _, left = point_in_body_frame(x, y, robot.x, robot.y, robot.heading)
    side = 0.5 + 0.25 * at
    return aimed_action(
        simulation, np.array([wanted_speed, side if left >= 0.0 else -side, -1.0]), detour
    )


def walk_towards(
    simulation: Simulation,
    target: NDArray[np.float64],
    wanted_speed: float,
    detour: bool = False,
) -> NDArray[np.float32]:
    """The normalised action whose arc over the next decision period ends nearest ``target``,
    at the normalised ``wanted_speed`` or slower where that would overshoot; standing, the
    human turns to face the target.

    With ``detour``, a target behind an obstacle is reached the short way round it: the human
    heads for the next point of that way (:meth:`~hazardhunt.world.navigation.WalkGrid.waypoint`)
    and slows down only near the target itself. Without it, the human walks straight at the
    target and stops where an obstacle is in the way.
    """
    human = simulation.human_params
    period = simulation.decision_period
    x, y, heading = simulation.human_pose
    if detour:
        grid = simulation.scenario.floor.walk_grid(human.radius)
        target, distance = grid.waypoint(np.array([x, y]), target)
    else:
        distance = math.hypot(target[0] - x, target[1] - y)
    speed = min(0.5 * (wanted_speed + 1.0) * human.max_speed, distance / period)
    if speed < 1e-6:
        # Standing: face the point, so that the next step towards it starts well.
        error = math.remainder(math.atan2(target[1] - y, target[0] - x) - heading, math.tau)
        turn = float(np.clip(error / period / human.max_turn_rate, -1.0, 1.0))
        return np.array([-1.0, turn], dtype=np.float32)
    ends = np.array(
        [
            human_path((x, y, heading), speed, turn * human.max_turn_rate, period, period)[-1]
            for turn in TURN_CHOICES
        ]
    )
    best = int(np.argmin(np.hypot(ends[:, 0] - target[0], ends[:, 1] - target[1])))
    return np.array([2.0 * speed / human.max_speed - 1.0, TURN_CHOICES[best]], dtype=np.float32)


def _ray_to_clearance(half_length: float, half_width: float, bearing: float, gap: float) -> float:
    """How far from a rectangle's centre, along ``bearing`` from its long axis, a point lies
    ``gap`` from the rectangle (where the ray leaves the rectangle grown by ``gap``, through a
    flat side or a rounded corner)."""
    u, v = abs(math.cos(bearing)), abs(math.sin(bearing))
    if u > 1e-12 and (half_length + gap) / u * v <= half_width:
        return (half_length + gap) / u  # through the front or the rear
    if v > 1e-12 and (half_width + gap) / v * u <= half_length:
        return (half_width + gap) / v  # through the left or the right side
    # Through a corner: |t (u, v) - (half_length, half_width)| = gap.
    along = half_length * u + half_width * v
    return along + math.sqrt(along**2 - (half_length**2 + half_width**2 - gap**2))
