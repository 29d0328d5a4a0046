"""Prediction of the human's future positions from its last tracked positions (SPEC 3).

The NMPC calls this once per control period (every 0.2 s), so it is plain numpy with no Python
loop over the horizon.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def predict_constant_acceleration(
    recent_positions: FloatArray,
    recent_times: FloatArray,
    horizon: int,
    step: float,
    max_speed: float = 1.5,
) -> FloatArray:
    """Extrapolate the human's last tracked positions with constant acceleration.

    A quadratic through the last three positions gives the velocity and the acceleration at the
    latest tracking instant; with two positions the velocity is their difference quotient and
    the acceleration zero; with one position the human stands still. The velocity is capped to
    ``max_speed`` at every predicted instant and the positions are integrated from the capped
    velocities (trapezoidal rule, exact for constant acceleration below the cap), so no predicted
    step is longer than ``max_speed * step``.

    Args:
        recent_positions: Shape (k, 2), k >= 1: tracked positions (x, y), oldest first, in m.
        recent_times: Shape (k,): their tracking instants, strictly increasing, in s.
        horizon: Number of predicted instants.
        step: Time between two predicted instants, in s.
        max_speed: Largest predicted speed, in m/s.

    Returns:
        Shape (horizon, 2): the predicted positions at ``t + step, ..., t + horizon * step``,
        where t is the latest tracking instant, in m.
    """
    positions = np.asarray(recent_positions, dtype=np.float64).reshape(-1, 2)[-3:]
    times = np.asarray(recent_times, dtype=np.float64).reshape(-1)[-3:]
    if len(positions) == 0 or len(positions) != len(times):
        raise ValueError("recent_positions and recent_times must hold the same k >= 1 instants")
    velocity, acceleration = _velocity_and_acceleration(positions, times)
    if horizon <= 0:
        return np.zeros((0, 2))
    elapsed = step * np.arange(horizon + 1, dtype=np.float64)
    uncapped = velocity + elapsed[:, None] * acceleration
    speed = np.hypot(uncapped[:, 0], uncapped[:, 1])
    capped = uncapped * np.minimum(1.0, max_speed / np.maximum(speed, 1e-12))[:, None]
    displacements = 0.5 * step * (capped[:-1] + capped[1:])
    predicted: FloatArray = positions[-1] + np.cumsum(displacements, axis=0)
    return predicted


def _velocity_and_acceleration(
    positions: FloatArray, times: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Velocity (m/s) and acceleration (m/s^2) at the latest instant from up to three points."""
    intervals = np.diff(times)
    # A repeated or reordered tracking instant carries no motion information: use the longest
    # trailing run of increasing instants.
    usable = len(times)
    for index in range(len(intervals) - 1, -1, -1):
        if not intervals[index] > 0.0:
            usable = len(intervals) - index
            break
    positions, times = positions[-usable:], times[-usable:]
    zero = np.zeros(2)
    if len(positions) == 1:
        return zero, zero
    quotients = np.diff(positions, axis=0) / np.diff(times)[:, None]
    if len(positions) == 2:
        return quotients[-1], zero
    # Divided differences of the interpolating quadratic: exact for constant acceleration.
    acceleration = 2.0 * (quotients[1] - quotients[0]) / (times[2] - times[0])
    velocity = quotients[1] + 0.5 * acceleration * (times[2] - times[1])
    return velocity, acceleration
