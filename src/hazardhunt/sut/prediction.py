"""Prediction of the human's future positions from its last tracked positions (SPEC 3).

The NMPC calls this once per control period (every 0.2 s) for a horizon of about twenty
instants: too few for numpy to pay off, so the arithmetic runs on Python floats.
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
    positions = np.asarray(recent_positions, dtype=np.float64).reshape(-1, 2)[-3:].tolist()
    times = np.asarray(recent_times, dtype=np.float64).reshape(-1)[-3:].tolist()
    if len(positions) == 0 or len(positions) != len(times):
        raise ValueError("recent_positions and recent_times must hold the same k >= 1 instants")
    (velocity_x, velocity_y), (acceleration_x, acceleration_y) = _velocity_and_acceleration(
        positions, times
    )
    if horizon <= 0:
        return np.zeros((0, 2))
    elapsed = [step * index for index in range(horizon + 1)]
    uncapped_x = [velocity_x + e * acceleration_x for e in elapsed]
    uncapped_y = [velocity_y + e * acceleration_y for e in elapsed]
    capped = list(zip(uncapped_x, uncapped_y, strict=True))
    # Below 99 % of the squared cap no rounding brings the speed up to the cap.
    below_cap = 0.99 * max_speed * max_speed if max_speed >= 1e-6 else -1.0
    if not all(vx * vx + vy * vy <= below_cap for vx, vy in capped):
        speeds = np.hypot(uncapped_x, uncapped_y).tolist()
        for index, speed in enumerate(speeds):
            # min(1, max_speed / max(speed, 1e-12)), passing NaN on.
            ratio = max_speed / (1e-12 if speed < 1e-12 else speed)
            factor = 1.0 if ratio >= 1.0 else ratio
            capped[index] = (uncapped_x[index] * factor, uncapped_y[index] * factor)
    # Trapezoidal rule: each step moves by the mean of its two capped velocities.
    half_step = 0.5 * step
    x, y = positions[-1]
    predicted: list[float] = []
    shift_x = shift_y = 0.0
    for index in range(horizon):
        (start_x, start_y), (end_x, end_y) = capped[index], capped[index + 1]
        step_x, step_y = half_step * (start_x + end_x), half_step * (start_y + end_y)
        if index == 0:
            shift_x, shift_y = step_x, step_y
        else:
            shift_x, shift_y = shift_x + step_x, shift_y + step_y
        predicted += (x + shift_x, y + shift_y)
    return np.array(predicted).reshape(-1, 2)


def _velocity_and_acceleration(
    positions: list[list[float]], times: list[float]
) -> tuple[tuple[float, float], tuple[float, float]]:
    """Velocity (m/s) and acceleration (m/s^2) at the latest instant from up to three points."""
    # A repeated or reordered tracking instant carries no motion information: use the longest
    # trailing run of increasing instants.
    usable = len(times)
    for index in range(len(times) - 2, -1, -1):
        if not times[index + 1] - times[index] > 0.0:
            usable = len(times) - 1 - index
            break
    positions, times = positions[-usable:], times[-usable:]
    if len(positions) == 1:
        return (0.0, 0.0), (0.0, 0.0)
    quotients = [
        ((x1 - x0) / (t1 - t0), (y1 - y0) / (t1 - t0))
        for (x0, y0), (x1, y1), t0, t1 in zip(
            positions[:-1], positions[1:], times[:-1], times[1:], strict=False
        )
    ]
    if len(positions) == 2:
        return quotients[-1], (0.0, 0.0)
    # Divided differences of the interpolating quadratic: exact for constant acceleration.
    (first_x, first_y), (second_x, second_y) = quotients
    span, last = times[2] - times[0], times[2] - times[1]
    acceleration_x = 2.0 * (second_x - first_x) / span
    acceleration_y = 2.0 * (second_y - first_y) / span
    velocity = (second_x + 0.5 * acceleration_x * last, second_y + 0.5 * acceleration_y * last)
    return velocity, (acceleration_x, acceleration_y)
