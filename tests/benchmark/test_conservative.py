"""The conservative controller survives every scripted attack; each mutant falls to its own."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np
import pytest

from hazardhunt.benchmark.conservative import (
    MUTANTS,
    BlindAfterRestart,
    BlindRightRear,
    ConservativeController,
    DockingMode,
    IgnoresHumanWalkingAlongside,
    StaleTrack,
    StandingHumanInLaneOnly,
    StopDistanceConvertedTwice,
)
from hazardhunt.benchmark.held_out import (
    HELD_OUT_MUTANTS,
    AbsorbedIntoStaticMap,
    BoostsInClearAisle,
    CreepsAfterWaiting,
    DebouncedStop,
    FastTracksTakenForGhosts,
    ForgetsPassedHuman,
    HurriesAfterDelay,
    PriorityAtCrossings,
    SlowsForPeopleBeside,
    TakenForTheRacks,
    TakesSlowingForYielding,
    TrackHeldWhileRelocalising,
)
from hazardhunt.sim.simulation import Simulation
from hazardhunt.sut.plugins import build_controller
from hazardhunt.sut.protocols import RobotState, TrackedHuman
from hazardhunt.sut.safety_layer import FIELD_SETTINGS
from hazardhunt.testers.spaces import DecisionSpace
from hazardhunt.world.bodies import RobotParams
from hazardhunt.world.scenario import BUILTIN_SCENARIOS, Pose, Scenario, load_scenario
from tests.scripted import (
    Policy,
    intercept,
    keep_heading,
    lie_in_wait,
    run,
    stand_still,
    steer_towards,
    walk_to,
)

NORTH, EAST = math.pi / 2, 0.0


def make(scenario: str | Scenario, field: str, controller: ConservativeController) -> Simulation:
    return Simulation.build(scenario, field, controller=controller, decision_period=0.2)


def robot_past(x: float) -> Callable[[Simulation], bool]:
    """Trigger: the robot's centre has passed ``x`` (the routes run east)."""
    return lambda sim: sim.robot.x > x


def robot_past_or_standing(x: float) -> Callable[[Simulation], bool]:
    """Trigger: the robot has passed ``x``, or it stands (it stopped for the waiting human)."""
    return lambda sim: sim.robot.x > x or (sim.sim_time > 2.0 and sim.robot.speed == 0.0)


# ------------------------------------------------------------------ attacks on the original
def side_attack() -> Policy:
    """Wait south of the route, run into the robot's right side as it comes abeam."""
    attack: Policy = lambda sim: intercept(sim, 1.5)  # noqa: E731
    return lie_in_wait((10.0, 8.8), NORTH, robot_past_or_standing(9.55), attack)


def charge_head_on() -> Policy:
    """Run at the robot's front from the first instant."""
    return lambda sim: intercept(sim, 1.5, offset=0.32)


def step_in_late() -> Policy:
    """Wait beside the route and step into the path when the robot's front is 1 m away."""
    attack: Policy = lambda sim: intercept(sim, 1.5, offset=0.32)  # noqa: E731
    return lie_in_wait((12.0, 9.0), NORTH, robot_past_or_standing(10.7), attack)


def chase_rear(speed: float) -> Policy:
    """Let the robot pass, then run after its rear at ``speed``."""
    attack: Policy = lambda sim: intercept(sim, speed, offset=-0.32)  # noqa: E731
    return lie_in_wait((9.0, 8.8), NORTH, robot_past_or_standing(10.0), attack)


def stand_beside_route() -> Policy:
    """Stand 0.3 m beside the robot's path, for good."""
    return lambda sim: walk_to(sim, (10.0, 9.2)) if sim.sim_time < 8.0 else (0.0, 0.0)


# ------------------------------------------------------------------ each mutant's killer
def run_into_rear_right() -> Policy:
    """BlindRightRear: from behind on the right, into the rear half of the right side."""
    return lie_in_wait((10.0, 7.0), NORTH, robot_past(10.0), lambda sim: intercept(sim, 1.5))


def dash_at_rear_half() -> Policy:
    """StaleTrack, StopDistanceConvertedTwice, SlowsForPeopleBeside, FastTracksTakenForGhosts,
    DebouncedStop: wait 2 m beside the route, let the robot pass and sprint at the rear half of
    its right side (out of the protective field's reach)."""
    attack: Policy = lambda sim: intercept(sim, 1.5, offset=-0.35)  # noqa: E731
    return lie_in_wait((10.0, 7.6), NORTH, robot_past(9.6), attack)


def stop_step_back_and_return() -> Policy:
    """BlindAfterRestart: come close so that the robot stops, turn away and swing out of its
    stop distance on an arc, and run into it as soon as it drives off again."""
    phase = "wait"

    def policy(sim: Simulation) -> tuple[float, float]:
        nonlocal phase
        x, y, heading = sim.human_pose
        if phase == "wait":
            phase = "close" if sim.robot.x > 9.85 else phase
            return walk_to(sim, (9.0, 7.4)) if y < 7.39 else keep_heading(sim, NORTH, 0.0)
        if phase == "close":
            at_spot = math.hypot(x - 9.0, y - 8.5) < 0.05 and math.sin(heading) < -0.999
            if not (sim.robot.speed < 0.01 and at_spot):
                if math.hypot(x - 9.0, y - 8.5) > 0.02:
                    return walk_to(sim, (9.0, 8.5))
                return keep_heading(sim, -NORTH, 0.0)
            phase = "arc"
        if phase == "arc" and sim.robot.speed < 0.05:
            return 1.5, math.pi / 2  # a U-turn to the left, out of the stop distance and back
        phase = "attack"
        return intercept(sim, 1.5)

    return policy


def wait_near_goal_then_step_in() -> Policy:
    """DockingMode: wait beside the route 0.7 m short of the goal, step in as the robot docks."""
    return lie_in_wait((17.3, 8.75), NORTH, robot_past(17.1), lambda sim: (1.5, 0.0))


def step_in_slowly() -> Policy:
    """StandingHumanInLaneOnly: wait just outside the protective field's reach beside the
    route and walk, slower than 0.5 m/s, into the robot's side as it passes."""
    return lie_in_wait((10.0, 9.1), 0.8, robot_past(9.8), lambda sim: (0.48, 0.0))


def walk_alongside_then_cut_in() -> Policy:
    """IgnoresHumanWalkingAlongside: walk east ahead of the robot, beside its path, and cut into
    its side at under 30 degrees once it is overtaking."""
    cutting = False

    def policy(sim: Simulation) -> tuple[float, float]:
        nonlocal cutting
        x, y, _ = sim.human_pose
        if y < 10.98 and not cutting:
            return steer_towards(sim, (x + 1.0, 11.0), 1.0)
        cutting = cutting or sim.robot.x > x + 0.4
        if cutting:
            return keep_heading(sim, -0.5, 1.0)
        return keep_heading(sim, EAST, 0.3)

    return policy


def wait_beside_route_then_step_into_side() -> Policy:
    """CreepsAfterWaiting, AbsorbedIntoStaticMap: stand still 0.4 m beside the route (out of
    the protective field's reach), and step into the rear half of the robot's side as it
    passes (it stands for good if it sees the human)."""
    attack: Policy = lambda sim: intercept(sim, 1.5, offset=-0.3)  # noqa: E731
    return lie_in_wait((10.0, 9.1), NORTH, robot_past(10.1), attack)


def hold_up_then_walk_into_side() -> Policy:
    """HurriesAfterDelay: stand in the robot's way until it has stood 3 s, step aside 2 m south
    of the route and ahead, and walk straight into its side as it comes by at its catch-up
    speed."""
    standing = 0.0
    attack: Policy = lambda sim: keep_heading(sim, NORTH, 1.5)  # noqa: E731
    step_aside = lie_in_wait((11.0, 7.7), NORTH, robot_past(10.2), attack)

    def policy(sim: Simulation) -> tuple[float, float]:
        nonlocal standing
        if standing >= 3.0:
            return step_aside(sim)
        standing += sim.decision_period if sim.robot.speed == 0.0 else 0.0
        x, y, _ = sim.human_pose
        if math.hypot(x - 10.0, y - 10.0) > 0.01:
            return walk_to(sim, (10.0, 10.0))
        return keep_heading(sim, -NORTH, 0.0)

    return policy


def wait_against_a_rack_then_step_into_side() -> Policy:
    """TakenForTheRacks: stand against the corner of the shelf block south-east of the crossing
    (0.36 m from it, 0.7 m from the robot's path) and step into the rear half of the robot's
    side as it passes."""
    attack: Policy = lambda sim: intercept(sim, 1.5, offset=-0.3)  # noqa: E731
    return lie_in_wait((11.3, 8.8), NORTH, robot_past_or_standing(11.6), attack)


def let_it_pass_then_run_into_side() -> Policy:
    """ForgetsPassedHuman: wait 2.1 m south of the robot's path (beyond its stop distance)
    until its rear has passed, then run after it into the rear half of its right side."""
    attack: Policy = lambda sim: intercept(sim, 1.5, offset=-0.3)  # noqa: E731
    return lie_in_wait((9.0, 7.4), NORTH, robot_past_or_standing(9.6), attack)


def come_from_the_side_aisle_into_side() -> Policy:
    """PriorityAtCrossings: wait in the side aisle south of the crossing, 2 m from the robot's
    path (beyond its stop distance), and run into the rear half of its right side as it
    crosses."""
    attack: Policy = lambda sim: intercept(sim, 1.5, offset=-0.3)  # noqa: E731
    return lie_in_wait((10.5, 7.8), NORTH, robot_past_or_standing(9.9), attack)


def run_out_of_the_side_aisle_as_a_hold_begins() -> Policy:
    """TrackHeldWhileRelocalising: wait in the side aisle south of the crossing and start
    running into the rear half of the robot's right side 0.8 s before the hold at 15 s, so
    that the human is at full speed, beyond the stop distance, when the hold begins and keeps
    running while the controller goes on seeing them where they were."""
    attack: Policy = lambda sim: intercept(sim, 1.5, offset=-0.3)  # noqa: E731
    return lie_in_wait((10.9, 6.5), NORTH, lambda sim: sim.sim_time >= 14.2 - 1e-9, attack)


def run_in_uneven_strides() -> Policy:
    """TakesSlowingForYielding: wait 2.4 m beside the route, let the robot pass and run at the
    rear half of its right side, every other step at 1.05 m/s instead of 1.5 m/s."""
    steps = 0

    def attack(sim: Simulation) -> tuple[float, float]:
        nonlocal steps
        steps += 1
        return intercept(sim, 1.5 if steps % 2 else 1.05, offset=-0.2)

    return lie_in_wait((10.0, 7.6), NORTH, robot_past(9.6), attack)


def run_straight_across_its_path() -> Policy:
    """BoostsInClearAisle: wait 3 m beside the route, out of the robot's lane, and run straight
    north, across its path, when its centre passes 1.5 m short of the human: into its right
    side, out of the protective field's reach."""
    attack: Policy = lambda sim: keep_heading(sim, NORTH, 1.5)  # noqa: E731
    return lie_in_wait((10.0, 7.0), NORTH, robot_past(8.5), attack)


MUTANT_KILLERS: dict[type[ConservativeController], tuple[str, Callable[[], Policy]]] = {
    BlindRightRear: ("crossing", run_into_rear_right),
    StaleTrack: ("crossing", dash_at_rear_half),
    BlindAfterRestart: ("crossing", stop_step_back_and_return),
    StopDistanceConvertedTwice: ("crossing", dash_at_rear_half),
    DockingMode: ("head-on", wait_near_goal_then_step_in),
    StandingHumanInLaneOnly: ("crossing", step_in_slowly),
    IgnoresHumanWalkingAlongside: ("overtaking", walk_alongside_then_cut_in),
    CreepsAfterWaiting: ("crossing", wait_beside_route_then_step_into_side),
    AbsorbedIntoStaticMap: ("crossing", wait_beside_route_then_step_into_side),
    HurriesAfterDelay: ("crossing", hold_up_then_walk_into_side),
    TakenForTheRacks: ("crossing", wait_against_a_rack_then_step_into_side),
    ForgetsPassedHuman: ("crossing", let_it_pass_then_run_into_side),
    PriorityAtCrossings: ("crossing", come_from_the_side_aisle_into_side),
    TrackHeldWhileRelocalising: ("crossing", run_out_of_the_side_aisle_as_a_hold_begins),
    SlowsForPeopleBeside: ("crossing", dash_at_rear_half),
    FastTracksTakenForGhosts: ("crossing", dash_at_rear_half),
    TakesSlowingForYielding: ("crossing", run_in_uneven_strides),
    BoostsInClearAisle: ("crossing", run_straight_across_its_path),
    DebouncedStop: ("crossing", dash_at_rear_half),
}
"""Per mutant: a built-in scenario and the scripted human that exposes its bug there."""

ATTACKS: dict[str, Callable[[], Policy]] = {
    "side attack": side_attack,
    "charge head-on": charge_head_on,
    "step in late": step_in_late,
    "chase the rear fast": lambda: chase_rear(1.5),
    "follow the rear slowly": lambda: chase_rear(0.4),
    "stand beside the route": stand_beside_route,
    **{f"{mutant.__name__}'s killer": killer for mutant, (_, killer) in MUTANT_KILLERS.items()},
}
TOUCHING_ATTACKS = [
    "side attack",
    "charge head-on",
    "step in late",
    "chase the rear fast",
    "follow the rear slowly",
]
"""The attacks that reach the original's body in every scenario (it stops; they walk on)."""


# ------------------------------------------------------------------ tests
@pytest.mark.parametrize(
    "cls", [ConservativeController, *MUTANTS, *HELD_OUT_MUTANTS], ids=lambda c: c.__name__
)
def test_every_controller_loads_as_a_plugin(cls):
    controller = build_controller(f"{cls.__module__}:{cls.__name__}", {})
    assert type(controller) is cls
    assert controller.control_period == pytest.approx(0.2)


def test_the_stop_distance_is_the_docstrings_arithmetic():
    controller = ConservativeController()
    budget = controller.stop_budget(RobotParams())
    assert budget.human_travel == pytest.approx(1.5 * 0.8)
    assert budget.robot_travel == pytest.approx(0.6 * 0.2 + 0.6**2 / 2)
    assert budget.robot_swing == pytest.approx(0.5 * math.hypot(0.32, 0.25) * 0.8)
    assert budget.stop_distance == pytest.approx(1.76, abs=0.005)


@pytest.mark.parametrize("field", list(FIELD_SETTINGS))
@pytest.mark.parametrize("name", BUILTIN_SCENARIOS)
def test_with_the_human_away_the_robot_reaches_its_goal(name, field):
    scenario = dataclasses.replace(load_scenario(name), human_start=Pose(0.85, 0.85, 0.0))
    result = run(make(scenario, field, ConservativeController()), stand_still)
    assert result.outcome == "goal"
    assert result.summary.emergency_stops == 0


@pytest.mark.parametrize("field", list(FIELD_SETTINGS))
@pytest.mark.parametrize("name", BUILTIN_SCENARIOS)
@pytest.mark.parametrize("attack", list(ATTACKS))
def test_no_scripted_human_makes_the_original_fail(attack, name, field):
    result = run(make(name, field, ConservativeController()), ATTACKS[attack]())
    assert result.outcome != "failure", result.summary


@pytest.mark.parametrize("field", list(FIELD_SETTINGS))
@pytest.mark.parametrize("name", BUILTIN_SCENARIOS)
def test_no_plain_ambush_makes_the_original_fail(name, field):
    # The searchers' own ambushes (wait beside the route, run at the robot's side as it
    # passes), at the default decision period; the units slip falls to some of them.
    space = DecisionSpace("ambush", detour=True)
    failures = {}
    for controller in (ConservativeController(), StopDistanceConvertedTwice()):
        simulation = Simulation.build(name, field, controller=controller)
        outcomes = [
            space.play(simulation, plan, False).summary.outcome
            for plan in space.plain_attacks(simulation.horizon)
        ]
        failures[type(controller).__name__] = outcomes.count("failure")
    assert failures["ConservativeController"] == 0
    if field == "none":
        assert failures["StopDistanceConvertedTwice"] > 0


@pytest.mark.parametrize("field", list(FIELD_SETTINGS))
@pytest.mark.parametrize("name", BUILTIN_SCENARIOS)
@pytest.mark.parametrize("attack", TOUCHING_ATTACKS)
def test_a_human_who_reaches_the_original_meets_it_standing(attack, name, field):
    result = run(make(name, field, ConservativeController()), ATTACKS[attack]())
    assert result.outcome == "safe_contact"
    assert result.summary.contact_verdict == "robot_standing"


@pytest.mark.parametrize("field", ["none", "1.25m"])
@pytest.mark.parametrize("mutant", MUTANTS + HELD_OUT_MUTANTS, ids=lambda m: m.__name__)
def test_each_mutant_falls_to_its_scripted_human(mutant, field):
    scenario, killer = MUTANT_KILLERS[mutant]
    result = run(make(scenario, field, mutant()), killer())
    assert result.outcome == "failure"
    assert result.summary.closest_robot_speed > 0.05  # the robot drove into the contact


def test_every_mutant_has_a_scripted_killer():
    assert set(MUTANT_KILLERS) == set(MUTANTS + HELD_OUT_MUTANTS)


def test_a_robot_with_weaker_brakes_stops_further_from_a_human_in_its_way():
    def standing_clearance(robot: RobotParams) -> float:
        sim = Simulation.build(
            "head-on", "none", controller=ConservativeController(), robot=robot, decision_period=0.2
        )
        result = run(sim, stand_still)
        assert result.outcome == "timeout"
        assert sim.robot.speed == 0.0
        return sim.clearance

    default = standing_clearance(RobotParams())
    weak_brakes = standing_clearance(RobotParams(max_acceleration=0.5))
    assert 1.3 < default < 1.76
    assert weak_brakes > default + 1.0


def turning_crossing() -> Scenario:
    """The crossing, but the route turns north at the crossing (the rear swings out)."""
    return dataclasses.replace(
        load_scenario("crossing"), waypoints=np.array([[10.0, 10.0]]), goal=np.array([10.0, 17.0])
    )


def human_at(
    controller: ConservativeController, robot: RobotState, bearing: float, clearance: float
):
    """A tracked human at ``clearance`` m from the robot's outline, ``bearing`` rad from its
    heading (found by bisection along the ray from the robot's centre)."""
    direction = np.array([math.cos(robot.heading + bearing), math.sin(robot.heading + bearing)])
    centre = np.array([robot.x, robot.y])
    near, far = 0.0, 10.0
    for _ in range(50):
        middle = (near + far) / 2
        if controller.clearance(robot, centre + middle * direction) < clearance:
            near = middle
        else:
            far = middle
    position = centre + far * direction
    return TrackedHuman(0.0, position, 0.0, position[None, :], np.array([0.0]))


@pytest.mark.parametrize("bearing_deg", range(-180, 180, 15))
def test_a_turning_robot_stops_for_a_human_within_the_stop_distance_on_every_side(bearing_deg):
    controller = ConservativeController()
    make(turning_crossing(), "none", controller).reset()
    robot = RobotState(10.0, 10.0, 0.7, speed=0.6, yaw_rate=0.5)  # turning left at the corner
    bearing = math.radians(bearing_deg)
    inside = human_at(controller, robot, bearing, controller.stop_distance - 0.01)
    outside = human_at(controller, robot, bearing, controller.stop_distance + 0.01)
    assert controller.control(0.0, robot, inside).speed == 0.0
    assert controller.control(0.0, robot, outside).speed > 0.0


@pytest.mark.parametrize("attack", ["side attack", "chase the rear fast", "follow the rear slowly"])
def test_no_scripted_human_makes_the_original_fail_on_a_turning_route(attack):
    result = run(make(turning_crossing(), "1.25m", ConservativeController()), ATTACKS[attack]())
    assert result.outcome != "failure", result.summary


def test_the_robot_stands_while_the_human_is_hidden():
    base = load_scenario("crossing")
    hidden_start = np.array([[8.6, 3.0], [11.4, 3.0], [11.4, 6.0], [8.6, 6.0]])
    floor = dataclasses.replace(base.floor, blind_zones=(hidden_start,))
    sim = make(dataclasses.replace(base, floor=floor), "none", ConservativeController())

    def hide_then_walk_out(sim: Simulation) -> tuple[float, float]:
        return (0.0, 0.0) if sim.sim_time < 10.0 else walk_to(sim, (10.0, 7.0))

    run(sim, hide_then_walk_out)
    samples = sim.trajectory()
    hidden = [s for s in samples if not s.human_visible]
    assert hidden
    assert all(s.robot_speed == 0.0 for s in hidden)
    assert max(s.robot_speed for s in samples) > 0.5  # it drove off once the human was seen
