import numpy as np
import pytest

from hazardhunt.sut.route import Route, RoutePlanningError, plan_route
from hazardhunt.world.floor import FloorMap, Obstacle
from hazardhunt.world.scenario import load_scenario

FLOOR = load_scenario("crossing").floor


def test_the_builtin_route_runs_straight_along_the_main_aisle():
    scenario = load_scenario("crossing")
    route = plan_route(FLOOR, scenario.robot_start.position, scenario.waypoints, scenario.goal, 0.5)
    assert route.points.tolist() == [[2.0, 10.0], [18.0, 10.0]]


def test_a_route_around_shelves_keeps_its_clearance_and_passes_the_waypoints():
    start, waypoint, goal = np.array([2.0, 10.0]), np.array([10.0, 5.0]), np.array([16.0, 15.25])
    route = plan_route(FLOOR, start, waypoint[None, :], goal, 0.5)
    assert any(np.allclose(p, waypoint) for p in route.points)
    samples = [route.point_at(s) for s in np.linspace(0.0, route.length, 400)]
    assert min(FLOOR.obstacle_clearance(p) for p in samples) >= 0.5 - 1e-3
    # Longer than the straight lines, shorter than a silly detour.
    direct = np.hypot(*(waypoint - start)) + np.hypot(*(goal - waypoint))
    assert direct < route.length < 1.3 * direct


def test_an_unreachable_goal_is_a_clear_error():
    with pytest.raises(RoutePlanningError, match=r"within 0.50 m of an obstacle"):
        plan_route(FLOOR, np.array([2.0, 10.0]), np.zeros((0, 2)), np.array([5.0, 8.8]), 0.5)


def test_a_route_around_a_column_of_10000_vertices_keeps_its_clearance():
    angles = np.linspace(0.0, 2 * np.pi, 10_000, endpoint=False)
    column = np.column_stack([10 + 2 * np.cos(angles), 10 + 2 * np.sin(angles)])
    floor = FloorMap("open", 20.0, 20.0, (Obstacle("column", column),))
    route = plan_route(floor, np.array([2.0, 10.0]), np.zeros((0, 2)), np.array([18.0, 10.0]), 0.5)
    samples = [route.point_at(s) for s in np.linspace(0.0, route.length, 2000)]
    assert min(floor.obstacle_clearance(p) for p in samples) >= 0.5 - 1e-6
    # Around the column at 2.5 m from its centre: the straight legs and half the circle.
    tangent = 2 * np.sqrt(8.0**2 - 2.5**2)
    assert tangent < route.length < tangent + np.pi * 2.5 + 0.1


def test_route_projection_and_interpolation():
    route = Route(np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 3.0]]))
    assert route.length == pytest.approx(7.0)
    assert route.point_at(5.0) == pytest.approx([4.0, 1.0])
    assert route.tangent_at(5.0) == pytest.approx([0.0, 1.0])
    assert route.project(np.array([4.5, 2.0])) == pytest.approx(6.0)
    assert route.project(np.array([1.0, 0.5]), s_min=3.0) == pytest.approx(3.0)
