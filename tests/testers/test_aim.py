"""Decisions aimed at the robot or its route: the human goes where each decision says, and the
episode replays from the actions it records."""

import math

import numpy as np
import pytest

from hazardhunt.sim.simulation import Simulation
from hazardhunt.spec.descriptors import measures_of
from hazardhunt.sut.pursuit import PursuitController
from hazardhunt.testers.aim import (
    LEAD_MAX,
    ROUTE_OFFSET_MAX,
    STANDOFF_MAX,
    aim_point,
    aimed_action,
    route_point,
)
from hazardhunt.testers.spaces import DecisionSpace, SearchSpace
from hazardhunt.world.geometry import point_in_body_frame, point_rectangle_clearance
from hazardhunt.world.navigation import MARGIN


@pytest.fixture(scope="module")
def sim():
    # A route follower that ignores the human, so that only the aiming decides the distance.
    return Simulation.build("crossing", "none", controller=PursuitController())


def outline_clearance(sim, point):
    """Clearance between a human disc at ``point`` and the robot's outline where it stands, in m."""
    robot, params = sim.robot, sim.robot_params
    forward, left = point_in_body_frame(point[0], point[1], robot.x, robot.y, robot.heading)
    gap = point_rectangle_clearance(forward, left, params.length, params.width)
    return gap - sim.human_params.radius


def test_a_human_aimed_at_the_robot_walks_into_it_where_it_aims(sim):
    faces = {}
    for bearing in (0.0, -0.5, 1.0):
        aims = np.tile([1.0, bearing, -1.0], (sim.horizon, 1))
        result = DecisionSpace("aim").play(sim, aims, False)
        assert result.summary.outcome == "failure"
        faces[bearing] = result.summary.contact_face
    # Ahead and from behind it meets the robot coming at it; aimed at its right, its right.
    assert faces == {0.0: "front", -0.5: "right", 1.0: "front"}


def test_the_aim_point_lies_the_stand_off_away_from_the_outline(sim):
    sim.reset()
    for bearing in np.linspace(-math.pi, math.pi, 13):
        for standoff in (0.0, 1.0, STANDOFF_MAX):
            point = aim_point(sim, bearing, standoff)
            # At the start the robot stands: the point is where the robot is now.
            assert outline_clearance(sim, point) == pytest.approx(standoff, abs=1e-9)


def test_a_human_aimed_at_a_distance_keeps_it(sim):
    # Aimed 3 m to the robot's right, the human comes up and walks beside it to the goal.
    result = DecisionSpace("aim").play(sim, np.tile([1.0, -0.5, 1.0], (sim.horizon, 1)))
    assert result.summary.outcome == "goal"
    assert result.trajectory is not None
    assert min(s.clearance for s in result.trajectory if s.time >= 2.0) > 2.0


def test_the_slowest_aim_stands_and_turns_to_face_the_point(sim):
    sim.reset()
    aim = np.array([-1.0, 0.5, 0.0])  # 1.5 m to the robot's left

    def facing_error():
        x, y, heading = sim.human_pose
        target = aim_point(sim, math.pi * aim[1], 0.5 * (aim[2] + 1.0) * STANDOFF_MAX)
        return abs(math.remainder(math.atan2(target[1] - y, target[0] - x) - heading, math.tau))

    before, position = facing_error(), sim.human_position
    action = aimed_action(sim, aim)
    assert action[0] == -1.0
    sim.decide(action)
    np.testing.assert_allclose(sim.human_position, position, atol=1e-9)
    assert facing_error() < before


def test_an_aimed_episode_replays_from_the_actions_it_records():
    sim = Simulation.build("crossing", "1.25m", controller=PursuitController())
    rng = np.random.default_rng(0)
    for kind in ("aim", "route", "ambush"):
        for clear_path in (False, True):
            space = DecisionSpace(kind, clear_path)
            result = space.play(sim, rng.uniform(-1.0, 1.0, (sim.horizon, space.size)), False)
            replayed = sim.simulate(result.actions, keep_trajectory=False)
            assert replayed.summary == result.summary
            np.testing.assert_array_equal(replayed.actions, result.actions)


def test_a_route_point_lies_beside_the_route_at_its_share(sim):
    start, goal = sim.route.points[0], sim.route.points[-1]
    np.testing.assert_allclose(route_point(sim, 0.0, 0.0), start)
    np.testing.assert_allclose(route_point(sim, 1.0, 0.0), goal)
    # The built-in routes run east: positive offsets lie to the north (the robot's left).
    np.testing.assert_allclose(
        route_point(sim, 0.5, ROUTE_OFFSET_MAX), (start + goal) / 2 + [0.0, ROUTE_OFFSET_MAX]
    )


def test_with_fitted_offsets_a_point_beside_the_aisle_is_its_edge(sim):
    # The main aisle is 3 m wide (y 8.5 to 11.5) except where the cross aisle crosses it (x 8.5
    # to 11.5). A tenth along the route, 3 m to the left lies in a shelf block: fitted, the
    # point is the aisle's edge, the human disc the margin clear of the block.
    floor, radius = sim.scenario.floor, sim.human_params.radius
    x, y = route_point(sim, 0.1, ROUTE_OFFSET_MAX)
    assert floor.disc_blocked_at(x, y, radius)
    x, y = route_point(sim, 0.1, ROUTE_OFFSET_MAX, fit=True)
    assert y == pytest.approx(11.5 - radius - MARGIN, abs=0.01)
    assert not floor.disc_blocked_at(x, y, radius + MARGIN)
    np.testing.assert_allclose(
        route_point(sim, 0.1, -ROUTE_OFFSET_MAX, fit=True), [x, 20.0 - y], atol=0.01
    )
    # In the cross aisle, or nearer than the edge, the point is where it was.
    for share, offset in ((0.5, ROUTE_OFFSET_MAX), (0.1, 0.5), (0.1, 0.0)):
        np.testing.assert_array_equal(
            route_point(sim, share, offset, fit=True), route_point(sim, share, offset)
        )


def test_fitted_offsets_reach_every_decision_space_a_searcher_plays():
    space = SearchSpace.model_validate({"kind": "mixed", "detour": True, "fit_offsets": True})
    assert [each.fit_offsets for each in space.decision_spaces] == [True, True, True]
    assert not any(each.fit_offsets for each in SearchSpace(kind="mixed").decision_spaces)


def test_with_fitted_offsets_the_plain_ambush_at_the_goal_waits_at_the_aisle_edge():
    # The plain ambushes wait 3 m beside the route. At the goal that is inside a shelf block:
    # walked to as it is, the human heads for the free place nearest it, round the block's end
    # by the east wall (x 18.5 to 19.8); fitted, it waits at the aisle's edge beside the goal.
    sim = Simulation.build("overtaking", "none", controller=PursuitController())
    plan = [1.0, 1.0, 1.0, 1.0, 0.0]  # at the goal, on the left, running 3 m before abreast
    lead = sim.route.length - LEAD_MAX

    def waiting(space: DecisionSpace) -> tuple[float, float]:
        sim.reset()
        while sim.route.project(np.array([sim.robot.x, sim.robot.y])) < lead:
            assert sim.decide(space.action(sim, np.array(plan))).outcome is None
        return sim.human_position

    x, y = waiting(DecisionSpace("ambush", detour=True, fit_offsets=True))
    assert (x, y) == pytest.approx((18.0, 11.5 - sim.human_params.radius - MARGIN), abs=0.05)
    x, y = waiting(DecisionSpace("ambush", detour=True))
    assert x > 18.5  # beyond the block's end, past the goal


def test_a_human_sent_onto_the_route_waits_there_and_the_robot_runs_into_it(sim):
    # Three quarters along the route, on its centre line: the route follower, which ignores
    # the human, hits it standing, late in its mission.
    result = DecisionSpace("route").play(sim, np.tile([1.0, 0.5, 0.0], (sim.horizon, 1)))
    summary = result.summary
    assert summary.outcome == "failure"
    assert summary.contact_face == "front"
    assert result.trajectory is not None
    waiting = result.trajectory[-1]
    np.testing.assert_allclose(
        [waiting.human_x, waiting.human_y], route_point(sim, 0.75, 0.0), atol=0.05
    )
    assert summary.closest_human_speed < 0.1  # standing
    # The robot's front met it: its centre was half a robot short of the point.
    half_length = sim.robot_params.length / 2 + sim.human_params.radius
    assert summary.closest_route_share == pytest.approx(
        0.75 - half_length / sim.route.length, abs=0.02
    )
    assert list(measures_of(summary, ["route_share", "human_speed"])) == [
        summary.closest_route_share,
        summary.closest_human_speed,
    ]


def test_with_clear_path_a_human_walks_round_a_shelf_to_its_route_point():
    # In the crossing the human starts in the cross aisle south of the main aisle; the route's
    # goal lies east, behind a shelf block. Walked straight at, the block stops the human at its
    # corner; with clear_path it walks round the block and stands on the goal when the robot,
    # which ignores it, arrives.
    sim = Simulation.build("crossing", "none", controller=PursuitController())
    goal = np.tile([1.0, 1.0, 0.0], (sim.horizon, 1))
    walked = DecisionSpace("route", detour=True).play(sim, goal)
    assert walked.trajectory is not None
    arrived = [s for s in walked.trajectory if math.hypot(s.human_x - 18.0, s.human_y - 10.0) < 0.1]
    assert arrived, "the human never reached the goal"
    assert arrived[0].time < 15.0
    assert walked.summary.outcome == "failure"
    assert walked.summary.contact_face == "front"
    floor, radius = sim.scenario.floor, sim.human_params.radius
    assert not any(floor.disc_blocked_at(s.human_x, s.human_y, radius) for s in walked.trajectory)


def test_an_ambush_waits_beside_the_route_until_the_robot_comes_abreast_then_runs_at_its_side(sim):
    # Half way along the route, 3 m to its right (south), running when the robot's centre is
    # 1.5 m short of abreast, at the middle of the robot's side.
    ambush = np.array([1.0, 0.0, -1.0, 0.5, 0.0])
    waiting_point = route_point(sim, 0.5, -ROUTE_OFFSET_MAX)
    trigger = 0.5 * sim.route.length - 0.5 * LEAD_MAX
    space = DecisionSpace("ambush")
    sim.reset()
    ran = False
    while sim.route.project(np.array([sim.robot.x, sim.robot.y])) < trigger:
        outcome = sim.decide(space.action(sim, ambush)).outcome
        assert outcome is None
    # Waiting: where the decision said, and the robot, which ignores the human, not yet near.
    np.testing.assert_allclose(sim.human_position, waiting_point, atol=0.05)
    while (outcome := sim.decide(space.action(sim, ambush)).outcome) is None:
        ran = True
    assert ran
    result = sim.result(keep_trajectory=False)
    assert (outcome, result.summary.contact_face) == ("failure", "right")
    # Mirrored, it waits on the left and meets the robot's left side.
    mirrored = DecisionSpace("ambush").mirrored(np.tile(ambush, (sim.horizon, 1)))
    assert DecisionSpace("ambush").play(sim, mirrored, False).summary.contact_face == "left"
