import math

import numpy as np
import pytest

from hazardhunt.spec.outcomes import Outcome, episode_outcome
from hazardhunt.spec.rewards import decision_reward
from hazardhunt.spec.risk import risk
from hazardhunt.spec.safety import ContactVerdict, judge_contact

EAST = 0.0


def test_a_contact_with_a_moving_robot_is_unsafe():
    verdict = judge_contact(True, "left", 0.8, EAST, np.array([0.0, -1.0]))
    assert verdict is ContactVerdict.UNSAFE


def test_exception_one_robot_standing_still():
    assert judge_contact(True, "front", 0.04, EAST, np.array([-1.0, 0.0])) is (
        ContactVerdict.ROBOT_STANDING
    )
    assert judge_contact(True, "front", 0.05, EAST, np.array([-1.0, 0.0])) is ContactVerdict.UNSAFE


def test_exception_two_human_runs_into_the_rear_faster_than_the_robot():
    faster = np.array([1.5, 0.0])
    slower = np.array([0.5, 0.0])
    assert judge_contact(True, "rear", 1.0, EAST, faster) is ContactVerdict.HUMAN_FROM_BEHIND
    assert judge_contact(True, "rear", 1.0, EAST, slower) is ContactVerdict.UNSAFE
    # Same speed along the heading but hitting the side: no exception.
    assert judge_contact(True, "left", 1.0, EAST, faster) is ContactVerdict.UNSAFE


def test_no_contact_no_verdict():
    assert judge_contact(False, "front", 1.0, EAST, np.zeros(2)) is ContactVerdict.NONE


def test_risk_matches_the_papers_equation():
    assert risk(True, True, 1.5, 1.2, -0.01) == pytest.approx(200.0)
    assert risk(True, True, 0.75, 0.6, -0.01) == pytest.approx(100.0 * (1 + 0.45 / 1.8))
    assert risk(False, False, 1.0, 0.5, 2.0) == pytest.approx(math.exp(-2.0))
    assert risk(False, False, 1.0, 0.1, 2.0) == 0.0  # robot not faster than 0.1 m/s
    assert risk(False, True, 1.0, 1.0, -0.01) == 0.0  # a safe contact


def test_accumulated_and_maximum_rewards():
    risks = 0.1 + 0.5 + 0.2  # summed over the decision's physics steps
    assert decision_reward("acc", risks, 0.9, last=False) == pytest.approx(0.8)
    assert decision_reward("max", risks, 0.9, last=False) == 0.0
    assert decision_reward("max", risks, 0.9, last=True) == pytest.approx(0.9)
    with pytest.raises(ValueError, match="unknown reward"):
        decision_reward("sum", risks, 0.9, last=True)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("kwargs", "expected"),
    [
        ({"verdict": ContactVerdict.UNSAFE, "goal_reached": True}, Outcome.FAILURE),
        ({"verdict": ContactVerdict.ROBOT_STANDING}, Outcome.SAFE_CONTACT),
        ({"verdict": ContactVerdict.HUMAN_FROM_BEHIND}, Outcome.SAFE_CONTACT),
        ({"sut_error": True}, Outcome.SUT_ERROR),
        ({"goal_reached": True}, Outcome.GOAL),
        ({"emergency_stop_duration": 10.0}, Outcome.STALL),
        ({"emergency_stop_duration": 9.95}, None),
        ({"sim_time": 30.0}, Outcome.TIMEOUT),
        ({}, None),
    ],
)
def test_episode_outcomes(kwargs, expected):
    arguments = {
        "verdict": ContactVerdict.NONE,
        "goal_reached": False,
        "sim_time": 5.0,
        "emergency_stop_duration": 0.0,
        "sut_error": False,
    } | kwargs
    assert episode_outcome(**arguments) is expected
