"""The human prediction the NMPC plans against: constant acceleration, speed-capped."""

from __future__ import annotations

import numpy as np
import pytest

from hazardhunt.sut.prediction import predict_constant_acceleration

STEP = 0.2
HORIZON = 20


def test_constant_velocity_extrapolates_exactly() -> None:
    times = np.array([0.6, 0.8, 1.0])
    velocity = np.array([0.8, -0.5])
    positions = np.array([1.0, 2.0]) + times[:, None] * velocity

    predicted = predict_constant_acceleration(positions, times, HORIZON, STEP)

    ahead = STEP * np.arange(1, HORIZON + 1)
    np.testing.assert_allclose(predicted, positions[-1] + ahead[:, None] * velocity, atol=1e-12)


def test_two_positions_extrapolate_with_constant_velocity() -> None:
    positions = np.array([[0.0, 0.0], [0.2, 0.1]])

    predicted = predict_constant_acceleration(positions, np.array([0.0, 0.2]), 3, STEP)

    np.testing.assert_allclose(predicted, [[0.4, 0.2], [0.6, 0.3], [0.8, 0.4]], atol=1e-12)


def test_constant_acceleration_extrapolates_exactly() -> None:
    acceleration = np.array([0.1, 0.05])
    start_velocity = np.array([0.2, -0.1])

    def position(t: np.ndarray) -> np.ndarray:
        return (
            np.array([3.0, 4.0])
            + t[:, None] * start_velocity
            + 0.5 * t[:, None] ** 2 * (acceleration)
        )

    # Uneven tracking instants: the quadratic fit must not assume a fixed period.
    times = np.array([0.0, 0.15, 0.4])
    predicted = predict_constant_acceleration(position(times), times, 5, STEP, max_speed=10.0)

    np.testing.assert_allclose(predicted, position(0.4 + STEP * np.arange(1, 6)), atol=1e-12)


def test_predicted_speed_never_exceeds_the_cap() -> None:
    # A human speeding up at 4 m/s^2 from 1.7 m/s: uncapped, the prediction would reach 17.7 m/s.
    times = np.array([0.0, 0.2, 0.4])
    positions = np.array([[0.0, 0.0], [0.1, 0.0], [0.36, 0.0]])

    predicted = predict_constant_acceleration(positions, times, HORIZON, STEP, max_speed=1.5)

    path = np.vstack([positions[-1], predicted])
    step_lengths = np.hypot(*np.diff(path, axis=0).T)
    assert np.all(step_lengths <= 1.5 * STEP + 1e-12)
    assert step_lengths[-1] == pytest.approx(1.5 * STEP)
    assert np.all(np.diff(predicted[:, 0]) > 0.0), "the human keeps walking the same way"


def test_a_fast_tracked_human_is_slowed_to_the_cap_at_once() -> None:
    times = np.array([0.0, 0.2])
    positions = np.array([[0.0, 0.0], [0.0, 1.0]])  # 5 m/s between two tracking instants

    predicted = predict_constant_acceleration(positions, times, 4, STEP, max_speed=1.5)

    np.testing.assert_allclose(predicted[:, 1], 1.0 + 1.5 * STEP * np.arange(1, 5), atol=1e-12)


def test_a_single_position_stands_still() -> None:
    predicted = predict_constant_acceleration(
        np.array([[4.0, 5.0]]), np.array([3.0]), HORIZON, STEP
    )

    assert predicted.shape == (HORIZON, 2)
    np.testing.assert_array_equal(predicted, np.tile([4.0, 5.0], (HORIZON, 1)))


def test_repeated_tracking_instant_does_not_produce_nan() -> None:
    positions = np.array([[0.0, 0.0], [0.2, 0.0], [0.2, 0.0]])
    times = np.array([0.0, 0.2, 0.2])

    predicted = predict_constant_acceleration(positions, times, 3, STEP)

    np.testing.assert_array_equal(predicted, np.tile([0.2, 0.0], (3, 1)))
