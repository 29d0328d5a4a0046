"""Failure classes (SPEC 6): hand-built trajectories for every class, and scripted humans."""

import dataclasses
import math

import pytest

from hazardhunt.sim.simulation import Simulation
from hazardhunt.spec.episode import EpisodeSummary, TrajectorySample
from hazardhunt.spec.failure_classes import (
    OTHER,
    FailureClassifier,
    MechanismClassifier,
    classify_failures,
)
from hazardhunt.sut.nmpc import NMPCController
from hazardhunt.sut.safety_layer import FIELD_SETTINGS
from hazardhunt.world.bodies import HumanParams, RobotParams, RobotState
from hazardhunt.world.kinematics import step_robot
from hazardhunt.world.scenario import Pose, load_scenario
from tests.scripted import Policy, keep_heading, lie_in_wait, run, steer_towards, walk_to

CLASSIFIER = MechanismClassifier()
FIELD = FIELD_SETTINGS["1.25m"]
NO_FIELD = FIELD_SETTINGS["none"]


def sample(time, human, *, robot_speed=1.0, stop=False, in_field=False):
    """One trajectory sample; the robot stands at the origin facing +x, so world = robot frame."""
    return TrajectorySample(
        time=time,
        human_x=human[0],
        human_y=human[1],
        human_heading=0.0,
        robot_x=0.0,
        robot_y=0.0,
        robot_heading=0.0,
        robot_speed=robot_speed,
        emergency_stop=stop,
        human_in_field=in_field,
    )


def contact(face, *, moving=True, **kwargs):
    """The last two rows before a contact on ``face``, the human moving 0.2 m in 0.2 s or not."""
    at = {"front": (0.55, 0.0), "rear": (-0.55, 0.0), "left": (0.0, 0.5), "right": (0.0, -0.5)}
    x, y = at[face]
    before = (x + 0.2, y) if moving else (x, y)
    return [sample(9.8, before, **kwargs), sample(10.0, (x, y), **kwargs)]


def classify(rows, face, field=FIELD):
    return CLASSIFIER.classify(rows, EpisodeSummary("failure", contact_face=face), field)


def far_away(count=5, **kwargs):
    return [sample(0.2 * i, (5.0, 5.0), **kwargs) for i in range(count)]


@pytest.mark.parametrize("face", ["front", "left", "right", "rear"])
@pytest.mark.parametrize("moving", [True, False])
def test_without_a_field_the_class_is_the_face_and_the_humans_motion(face, moving):
    rows = far_away() + contact(face, moving=moving)
    motion = "moving" if moving else "standing"
    assert classify(rows, face, field=NO_FIELD) == f"{face}/{motion}"


@pytest.mark.parametrize("side", ["left", "right"])
def test_a_side_contact_the_field_never_saw_is_no_stop(side):
    assert classify(far_away() + contact(side), side) == f"side-{side}/no-stop"


@pytest.mark.parametrize("side", ["left", "right"])
def test_a_side_contact_after_the_robot_stopped_and_drove_again_is_restarted(side):
    stop = [
        sample(1.0, (1.0, 0.0), stop=True, in_field=True),
        sample(1.2, (1.0, 0.0), robot_speed=0.0, stop=True, in_field=True),
    ]
    left_field = [sample(1.4, (1.0, 2.0), robot_speed=0.0), sample(1.6, (1.0, 2.0))]
    rows = far_away() + stop + left_field + contact(side)
    assert classify(rows, side) == f"side-{side}/restarted"


def test_a_contact_after_a_released_stop_without_driving_again_is_other():
    stop = [sample(1.0, (1.0, 0.0), stop=True, in_field=True)]
    rows = far_away() + stop + contact("left", robot_speed=0.0)
    assert classify(rows, "left") == OTHER


def entered_ahead():
    """The human crosses the field's arc well ahead of the front face; the stop triggers."""
    return [sample(1.0, (1.5, 0.0)), sample(1.2, (0.9, 0.0), stop=True, in_field=True)]


@pytest.mark.parametrize("side", ["left", "right"])
def test_a_side_contact_while_the_robot_still_brakes_is_braking(side):
    rows = far_away() + entered_ahead() + contact(side, stop=True)
    assert classify(rows, side) == f"side-{side}/braking"


@pytest.mark.parametrize("moving", [True, False])
def test_a_front_contact_while_braking_after_entering_from_ahead_is_field_braking(moving):
    rows = far_away() + entered_ahead() + contact("front", moving=moving, stop=True, in_field=True)
    motion = "moving" if moving else "standing"
    assert classify(rows, "front") == f"field/braking/{motion}"


@pytest.mark.parametrize("moving", [True, False])
def test_entering_the_field_from_beside_the_robot_is_edge_entry(moving):
    # Beside the front corner (forward 0.3 m <= half length 0.32 m), stepping in sideways.
    beside = [sample(1.0, (0.3, 0.9)), sample(1.2, (0.3, 0.6), stop=True, in_field=True)]
    rows = far_away() + beside + contact("front", moving=moving, stop=True, in_field=True)
    motion = "moving" if moving else "standing"
    assert classify(rows, "front") == f"edge-entry/{motion}"


def test_the_last_entry_into_the_field_decides_edge_entry():
    beside = [sample(1.6, (0.3, 0.9)), sample(1.8, (0.3, 0.6), stop=True, in_field=True)]
    rows = far_away() + entered_ahead() + [sample(1.4, (3.0, 3.0))] + beside + contact("left")
    rows[-1] = dataclasses.replace(rows[-1], emergency_stop=True)
    assert classify(rows, "left") == "edge-entry/moving"


def test_a_graze_of_the_field_between_two_samples_is_read_where_the_stop_began():
    # The human walks into the robot's right side; between the last two samples its disc grazes
    # the field beside the front corner, which stops the robot, and at the contact it is out of
    # the field again. No sample shows it in the field: where the stop began decides.
    rows = [*far_away(), sample(9.8, (0.1, -0.75)), sample(10.0, (0.09, -0.46), stop=True)]
    assert classify(rows, "right") == "edge-entry/moving"


@pytest.mark.parametrize(
    ("rows", "face"),
    [
        (far_away() + contact("front"), "front"),  # front touch the field never saw
        (far_away() + contact("rear"), "rear"),
        (far_away() + entered_ahead() + contact("rear", stop=True), "rear"),
        (far_away() + contact("left"), None),  # no contact face
        ([], "left"),  # no trajectory
    ],
)
def test_a_failure_that_fits_no_class_is_other_not_dropped(rows, face):
    assert classify(rows, face) == OTHER


def test_the_classes_match_the_field_setting_and_other_comes_last():
    with_field = CLASSIFIER.classes_for(FIELD)
    without_field = CLASSIFIER.classes_for(NO_FIELD)
    assert len(with_field) == 10 + 1
    assert len(without_field) == 8 + 1
    assert with_field[-1] == without_field[-1] == OTHER
    assert len(set(with_field)) == len(with_field)
    assert isinstance(CLASSIFIER, FailureClassifier)


def test_classify_failures_keeps_every_episode():
    trajectories = {0: far_away() + contact("left"), 1: far_away() + contact("front"), 2: []}
    summaries = {
        0: EpisodeSummary("failure", contact_face="left"),
        1: EpisodeSummary("failure", contact_face="front"),
        2: EpisodeSummary("failure"),
    }
    classes = classify_failures(trajectories, summaries, FIELD)
    assert classes == {0: "side-left/no-stop", 1: OTHER, 2: OTHER}
    assert set(classes.values()) <= set(CLASSIFIER.classes_for(FIELD))


# ------------------------------------------------------------------ end to end
# Scripted humans against the real NMPC in the crossing: the robot drives east along the main
# aisle (y = 10 m) at 1 m/s; the human starts south of it (meets the robot's right) or, in
# FROM_THE_NORTH, north of it (meets its left).
NMPC = NMPCController()  # built once: construction is the expensive part
CROSSING = load_scenario("crossing")
FROM_THE_NORTH = dataclasses.replace(CROSSING, human_start=Pose(10.0, 15.0, -math.pi / 2))
ROUTE_Y = 10.0
SIDES = {"left": 1.0, "right": -1.0}
"""Which way from the route (in y) the human waits for each side of the robot."""


def classify_episode(field, policy, side="right"):
    """Play one episode in the crossing; returns the failure's class and the sim."""
    sim = Simulation.build(
        FROM_THE_NORTH if side == "left" else CROSSING, field, controller=NMPC, decision_period=0.2
    )
    result = run(sim, policy)
    assert result.outcome == "failure"
    label = CLASSIFIER.classify(sim.trajectory(), result.summary, sim.field)
    assert label in CLASSIFIER.classes_for(sim.field)
    return label, sim


def beside_route(side, x, offset):
    """The point ``offset`` m from the route on the robot's ``side``, at ``x``."""
    return x, ROUTE_Y + SIDES[side] * offset


def towards_route(side):
    """The heading from ``side`` straight across the route."""
    return -SIDES[side] * math.pi / 2


def robot_past(x):
    """Trigger: the robot's centre has passed ``x``."""
    return lambda sim: sim.robot.x > x


def charge(sim):
    """Run at the robot's centre."""
    robot = sim.robot
    return steer_towards(sim, (robot.x, robot.y), 1.5)


def side_attack(side) -> Policy:
    """Wait 1.2 m beside the route and run at the robot's centre as it comes abreast."""
    return lie_in_wait(beside_route(side, 10.0, 1.2), towards_route(side), robot_past(9.55), charge)


def graze_the_field(side) -> Policy:
    """Wait 1.2 m beside the route; when the robot is 1.5 m short, walk at 1.1 m/s diagonally
    back across its path (45 degrees against its direction). The human grazes the field's corner
    (stop), walks on past the front corner and along the side, out of the field: the released
    robot drives off into him."""
    heading = math.atan2(-SIDES[side] * math.sin(math.pi / 4), -math.cos(math.pi / 4))
    return lie_in_wait(
        beside_route(side, 9.95, 1.2),
        heading,
        robot_past(9.95 - 1.5),
        lambda sim: keep_heading(sim, heading, 1.1),
    )


def cut_in_behind_the_front_corner() -> Policy:
    """Wait 1 m right of the route; as the robot's centre passes, run at 1.5 m/s forward and in
    at 40 degrees to its heading, a little faster along it than the robot: the human steps over
    the field's straight edge just behind the front corner and into the side."""
    heading = math.radians(40)
    return lie_in_wait(
        (9.728, ROUTE_Y - 1.0),
        heading,
        robot_past(9.728),
        lambda sim: keep_heading(sim, heading, 1.5),
    )


def step_into_the_path(side, x, offset) -> Policy:
    """Wait 1.4 m beside the route at ``x``; when the robot's centre passes 8 m, walk straight
    to ``offset`` m from the route and stop there."""
    target = beside_route(side, x, offset)
    return lie_in_wait(
        beside_route(side, x, 1.4),
        towards_route(side),
        robot_past(8.0),
        lambda sim: walk_to(sim, target),
    )


def chase_the_rear() -> Policy:
    """Wait 0.8 m right of the route; once the robot has passed, run at its centre: the human
    reaches its rear corner slower along its heading than the robot drives."""
    return lie_in_wait(beside_route("right", 10.0, 0.8), math.pi / 2, robot_past(10.15), charge)


@pytest.mark.parametrize("side", list(SIDES))
def test_a_side_attack_past_the_field_is_a_side_no_stop_failure(side):
    label, sim = classify_episode("1.25m", side_attack(side), side)
    assert label == f"side-{side}/no-stop"
    assert not any(row.emergency_stop for row in sim.trajectory())


@pytest.mark.parametrize("side", list(SIDES))
def test_a_side_attack_without_a_field_is_a_side_failure_of_a_moving_human(side):
    label, _ = classify_episode("none", side_attack(side), side)
    assert label == f"{side}/moving"


def test_a_human_charging_head_on_meets_the_swerving_robots_side_unseen_by_the_field():
    sim = Simulation.build("head-on", "1.25m", controller=NMPC, decision_period=0.2)
    result = run(sim, charge)
    assert result.outcome == "failure"
    label = CLASSIFIER.classify(sim.trajectory(), result.summary, sim.field)
    assert label in {"side-left/no-stop", "side-right/no-stop"}


@pytest.mark.parametrize("side", list(SIDES))
def test_a_human_grazing_the_field_then_beside_the_released_robot_is_restarted(side):
    label, sim = classify_episode("1.25m", graze_the_field(side), side)
    assert label == f"side-{side}/restarted"
    rows = sim.trajectory()
    stop = next(index for index, row in enumerate(rows) if row.emergency_stop)
    assert any(row.robot_speed == 0.0 for row in rows[stop:])  # the stop held it still
    assert not rows[-1].emergency_stop
    assert rows[-1].robot_speed >= 0.05  # driving again at contact


def test_a_human_cutting_in_over_the_fields_straight_edge_is_hit_while_the_robot_brakes():
    label, sim = classify_episode("1.25m", cut_in_behind_the_front_corner())
    assert label == "edge-entry/moving"
    last = sim.trajectory()[-1]
    assert last.emergency_stop
    assert last.robot_speed >= 0.05  # the stop came too late to bring it to a standstill


@pytest.mark.parametrize(
    ("x", "offset", "expected"),
    [
        (9.15, 0.0, "front/moving"),  # too late: still walking when the robot arrives
        (9.95, 0.0, "front/standing"),  # on the route, too close for the robot to stop
    ],
)
def test_a_human_stepping_onto_the_route_is_hit_by_the_front(x, offset, expected):
    label, _ = classify_episode("none", step_into_the_path("right", x, offset))
    assert label == expected


@pytest.mark.parametrize("side", list(SIDES))
def test_a_human_standing_off_centre_in_the_path_is_hit_by_the_swerving_robots_side(side):
    label, _ = classify_episode("none", step_into_the_path(side, 10.0, 0.35), side)
    assert label == f"{side}/standing"


def test_a_human_chasing_the_robot_slower_than_it_drives_touches_its_rear_unsafely():
    label, sim = classify_episode("none", chase_the_rear())
    assert label == "rear/moving"
    assert sim.trajectory()[-1].robot_speed >= 0.05


def test_the_same_chase_with_a_field_fits_no_class_and_is_kept_as_other():
    label, sim = classify_episode("1.25m", chase_the_rear())
    assert label == OTHER
    assert not any(row.emergency_stop for row in sim.trajectory())  # the field never saw it


# ------------------------------------------------------------------ unreachable classes
def braking_travel(speed, robot=RobotParams(), physics_step=0.05, standstill=0.05):
    """From the physics step in which the human enters the field on: how many steps the robot
    still counts as moving at their end, and how far it drives meanwhile (m)."""
    steps, travelled = 1, speed * physics_step  # the entry step: the stop applies from the next
    while True:
        motion = step_robot(
            RobotState(travelled, 0.0, 0.0, speed, 0.0),
            speed,
            0.0,
            physics_step,
            robot,
            emergency_stop=True,
        )
        if motion.speed < standstill:
            return steps, travelled
        travelled, speed, steps = motion.x, motion.speed, steps + 1


@pytest.mark.parametrize("field", [1.25, 2.0])
def test_no_human_reaches_the_front_face_while_the_robot_brakes(field):
    # The numbers behind "field/braking/* is unreachable" (docs/failure-classes.md): the
    # front-face contact farthest from the field's centre (human centre at the front corner's
    # 45-degree point) still lies further inside the field than human and robot can close.
    robot, human = RobotParams(), HumanParams()
    steps, travelled = braking_travel(1.0, robot)
    closing = travelled + steps * human.max_speed * 0.05
    diagonal = human.radius / math.sqrt(2)
    farthest_front_contact = math.hypot(diagonal, robot.width / 2 + diagonal)
    assert (steps, closing) == (3, pytest.approx(0.3375))
    assert field / 2 + human.radius - farthest_front_contact > closing


# ------------------------------------------------------------------ the field's response time
def with_response_time(seconds):
    """The crossing with a 1.25 m field whose brake engages ``seconds`` after a violation."""
    fields = {"slow": {"diameter": 1.25, "response_time": seconds}}
    return Simulation.build(
        dataclasses.replace(CROSSING, fields=fields), "slow", decision_period=0.2, controller=NMPC
    )


@pytest.mark.parametrize(
    ("seconds", "trigger", "expected"),
    [
        (0.0, 8.0, None),  # the study's instant brake: the robot stands before the contact
        (0.3, 8.0, "field/braking/moving"),  # a late brake: the braking front hits the human
        (0.15, 8.05, "side-right/braking"),
    ],
)
def test_a_slower_safety_function_makes_braking_classes_reachable(seconds, trigger, expected):
    # Wait south of the route and step onto it at x = 9.15 m once the robot has passed trigger.
    policy = lie_in_wait(
        (9.15, 8.6), math.pi / 2, robot_past(trigger), lambda sim: walk_to(sim, (9.15, ROUTE_Y))
    )
    sim = with_response_time(seconds)
    result = run(sim, policy)
    if expected is None:
        assert result.outcome != "failure"
    else:
        assert result.outcome == "failure"
        assert CLASSIFIER.classify(result.trajectory, result.summary, sim.field) == expected
