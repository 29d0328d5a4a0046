"""The SUT's uncertainties as the random effects of one episode: what the sensors and the brake
did in it, which the nominal simulation takes as perfect.

:class:`SutEffects` holds one episode's sampled values (a model of the uncertainties draws
them, :mod:`hazardhunt.likelihood.uncertainty`); :class:`EffectsState` applies them while the
episode plays. Per-frame tracking noise and lost frames come from a generator seeded by
``seed``, so an episode replays exactly from its values and seed.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, fields

import numpy as np

from hazardhunt.errors import InputError


@dataclass(frozen=True)
class SutEffects:
    """One episode's uncertainties; the defaults are the nominal simulation."""

    tracking_noise: float = 0.0
    """Standard deviation of the tracked position's error, per axis and frame, in m."""
    tracking_latency: float = 0.0
    """Age of the position the cameras report, in s (rounded down to physics steps)."""
    dropped_frames: float = 0.0
    """Probability that a tracking frame is lost (the controller gets no sighting)."""
    response_time: float = 0.0
    """Time from the safety layer's stop to the brake, beyond the layer's own, in s."""
    brake_deceleration: float | None = None
    """The emergency brake's deceleration in this episode, in m/s²; None: the robot's."""
    seed: int = 0
    """Seeds the per-frame noise and lost frames."""

    def __post_init__(self) -> None:
        for name in ("tracking_noise", "tracking_latency", "response_time"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise InputError(f"effects: {name} must be a number >= 0, not {value!r}")
        if not 0.0 <= self.dropped_frames <= 1.0:
            raise InputError(
                f"effects: dropped_frames must be in [0, 1], not {self.dropped_frames!r}"
            )
        brake = self.brake_deceleration
        if brake is not None and not (math.isfinite(brake) and brake > 0):
            raise InputError(f"effects: brake_deceleration must be > 0, not {brake!r}")

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """The effects a model of the uncertainties may draw (all but the seed)."""
        return tuple(f.name for f in fields(cls) if f.name != "seed")


class EffectsState:
    """The effects of the episode being played: the delayed, noisy sightings and the delayed
    brake."""

    def __init__(self, effects: SutEffects, physics_step: float) -> None:
        self.effects = effects
        self.rng = np.random.default_rng(effects.seed)
        self.delay_steps = int(effects.tracking_latency / physics_step + 1e-9)
        self.poses: deque[tuple[float, float, float]] = deque(maxlen=self.delay_steps + 1)
        self.response_steps = math.ceil(effects.response_time / physics_step - 1e-9)
        self.stop_requested_steps = 0

    def note_pose(self, pose: tuple[float, float, float]) -> None:
        """Keep the human's pose of this physics step (for the latency)."""
        self.poses.append(pose)

    def sighting(self) -> tuple[np.ndarray, float] | None:
        """What the cameras report now: the pose ``tracking_latency`` ago with noise, or None
        for a lost frame. Draws the same numbers at every call, lost or not."""
        noise = self.rng.normal(0.0, 1.0, 2) * self.effects.tracking_noise
        lost = self.rng.random() < self.effects.dropped_frames
        x, y, heading = self.poses[0]
        return None if lost else (np.array([x + noise[0], y + noise[1]]), heading)

    def brake_engaged(self, requested: bool) -> bool:
        """Whether the brake acts at this physics step, given whether the safety layer asks for
        a stop: only after it has asked ``response_time`` without a break."""
        self.stop_requested_steps = self.stop_requested_steps + 1 if requested else 0
        return requested and self.stop_requested_steps > self.response_steps
