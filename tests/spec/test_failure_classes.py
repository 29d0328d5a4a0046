"""Failure classes (SPEC 6): hand-built trajectories for every class, and scripted humans."""

import pytest

from hazardhunt.env.agv import AGVEnv
from hazardhunt.spec.failure_classes import (
    OTHER,
    FailureClassifier,
    MechanismClassifier,
    classify_failures,
)
from hazardhunt.sut.nmpc import NMPCController
from tests.env.test_scripted_humans import side_attack
from tests.scripted import run, steer_towards

CLASSIFIER = MechanismClassifier()
FIELD = 1.25


def sample(time, human, *, robot_speed=1.0, stop=False, in_field=False):
    """One trajectory row; the robot stands at the origin facing +x, so world = robot frame."""
    return {
        "time": time,
        "human_x": human[0],
        "human_y": human[1],
        "human_heading": 0.0,
        "robot_x": 0.0,
        "robot_y": 0.0,
        "robot_heading": 0.0,
        "robot_speed": robot_speed,
        "emergency_stop": stop,
        "human_in_field": in_field,
        "clearance": 0.0,
    }


def contact(face, *, moving=True, **kwargs):
    """The last two rows before a contact on ``face``, the human moving 0.2 m in 0.2 s or not."""
    at = {"front": (0.55, 0.0), "rear": (-0.55, 0.0), "left": (0.0, 0.5), "right": (0.0, -0.5)}
    x, y = at[face]
    before = (x + 0.2, y) if moving else (x, y)
    return [sample(9.8, before, **kwargs), sample(10.0, (x, y), **kwargs)]


def classify(rows, face, field=FIELD):
    return CLASSIFIER.classify(rows, {"outcome": "failure", "contact_face": face}, field)


def far_away(count=5, **kwargs):
    return [sample(0.2 * i, (5.0, 5.0), **kwargs) for i in range(count)]


@pytest.mark.parametrize("face", ["front", "left", "right", "rear"])
@pytest.mark.parametrize("moving", [True, False])
def test_without_a_field_the_class_is_the_face_and_the_humans_motion(face, moving):
    rows = far_away() + contact(face, moving=moving)
    motion = "moving" if moving else "standing"
    assert classify(rows, face, field=None) == f"{face}/{motion}"


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
    rows[-1]["emergency_stop"] = True
    assert classify(rows, "left") == "edge-entry/moving"


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
    without_field = CLASSIFIER.classes_for(None)
    assert len(with_field) == 10 + 1
    assert len(without_field) == 8 + 1
    assert with_field[-1] == without_field[-1] == OTHER
    assert len(set(with_field)) == len(with_field)
    assert isinstance(CLASSIFIER, FailureClassifier)


def test_classify_failures_keeps_every_episode():
    trajectories = {0: far_away() + contact("left"), 1: far_away() + contact("front"), 2: []}
    summaries = {
        0: {"contact_face": "left"},
        1: {"contact_face": "front"},
        2: {"contact_face": None},
    }
    classes = classify_failures(trajectories, summaries, FIELD)
    assert classes == {0: "side-left/no-stop", 1: OTHER, 2: OTHER}
    assert set(classes.values()) <= set(CLASSIFIER.classes_for(FIELD))


# ------------------------------------------------------------------ end to end
NMPC = NMPCController()  # built once: construction is the expensive part


def classify_episode(field, policy, scenario="crossing"):
    env = AGVEnv(scenario, field, controller=NMPC, decision_period=0.2)
    info, _ = run(env, policy)
    assert info["outcome"] == "failure"
    label = CLASSIFIER.classify(env.trajectory(), info["summary"], env.field_diameter)
    assert label in CLASSIFIER.classes_for(env.field_diameter)
    return label


def test_a_side_attack_past_the_field_is_a_side_no_stop_failure():
    assert classify_episode("1.25m", side_attack) == "side-right/no-stop"


def test_a_side_attack_without_a_field_is_a_side_failure_of_a_moving_human():
    assert classify_episode("none", side_attack) == "right/moving"


def test_a_human_charging_head_on_meets_the_swerving_robots_side_unseen_by_the_field():
    def charge(env):
        robot = env.robot_state
        return steer_towards(env, (robot.x, robot.y), 1.5)

    label = classify_episode("1.25m", charge, scenario="head-on")
    assert label in {"side-left/no-stop", "side-right/no-stop"}
