"""Failure classes (SPEC 6): which mechanism led to an unsafe contact.

A failure's class is read from the episode's trajectory (sampled every 0.2 s, see
:class:`~hazardhunt.spec.episode.TrajectorySample`) and its summary, at and before the contact.
The features are the robot face that was touched, the safety layer's history, and whether the
human was moving at contact (faster than ``moving_speed``, from the last two samples).

With a protective field (a half-disc, side bands or both; 10 classes; the study counted 9, with
both sides of fewer mechanisms):

- ``side-left/no-stop``, ``side-right/no-stop``: the field never triggered; the human walked
  into the uncovered side.
- ``side-left/restarted``, ``side-right/restarted``: a stop happened, was released, the robot
  drove again and then touched the human on its side.
- ``side-left/braking``, ``side-right/braking``: the stop holds at contact (the robot had not
  yet come to a standstill) and the touch is on a side: the human left the field sideways.
- ``field/braking/moving``, ``field/braking/standing``: the stop holds at contact on the front
  face, the human entered the field over its arc (from ahead).
- ``edge-entry/moving``, ``edge-entry/standing``: the stop holds at contact and the human last
  entered the field over its straight edge, i.e. from beside the robot (its forward coordinate
  in the robot's frame at most half the robot's length + ``edge_tolerance``).

Without a field (8 classes):

- ``front|left|right|rear`` ``/moving|standing``: the face touched and the human's motion.

Anything else is ``other`` and kept, never dropped: a contact without a face, a front or rear
touch the field never saw (the field covers the whole front face, so a front touch it never saw
would need the human to cross 0.41 m of field within one physics step; a rear one happens when a
human catches the rear corner slower than the robot drives), a rear touch while braking, or a
contact after a released stop without the robot driving again.

Reachability with the built-in NMPC (1 m/s cruise, 1.25 m field), shown by the scripted humans of
``tests/spec/test_failure_classes.py``: ``side-*/no-stop`` and ``left|right/moving`` (run at the
robot's side as it comes abreast), ``side-*/restarted`` (graze the field's corner diagonally, walk
on beside the stopped robot, which drives off into the human), ``edge-entry/moving`` (cut in at
40 degrees just behind the front corner, over the field's straight edge), ``front/moving`` and
``front/standing`` (step onto the route too late / in time to stand), ``left|right/standing``
(stand 0.35 m off the route's centre line; the swerving robot's side hits), ``rear/moving`` (chase
the rear corner slower than the robot) and ``other`` (the same chase with a field).

Not reached, with the reason (docs/failure-classes.md has the arithmetic):

- ``field/braking/*``: unreachable. After the field triggers, the robot still counts as moving for
  at most 3 physics steps (7.5 m/s^2 from 1 m/s), in which human (1.5 m/s) and robot close at most
  0.34 m; every front-face contact lies at least 0.41 m (2 m field: 0.79 m) inside the field's
  trigger boundary.
- ``side-*/braking``: unreachable. A side contact ahead of the front face (a corner hit from ahead)
  lies 0.38 m inside the boundary; from beside, the human would have to gain 0.3 m forward on the
  robot. So every contact while braking is on a side with the human level with the front part of
  the robot (at most 0.23 m ahead of its centre in a sweep over all straight and turning paths, at
  up to 1.2 m/s): it counts as ``edge-entry``.
- ``edge-entry/standing``: not reached. The braking robot drives at most 0.07 m more, too little
  to close on a standing human beside it; the sweep found such a hit only with the robot turning
  towards the human at full yaw rate as the field triggers and the human stopping dead at the very
  next decision.
- ``rear/standing``: not reached. The rear face moves backwards onto a standing human only while
  the robot turns almost on the spot (speed below 0.5 rad/s x 0.25 m = 0.125 m/s, and at least
  0.05 m/s to be a failure); the built-in routes are straight, and no scripted or searched human
  has made the NMPC turn like that next to them.

These classes are kept for other controllers, fields and scenarios.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, cast, runtime_checkable

import numpy as np

from hazardhunt.spec.episode import EpisodeSummary, TrajectorySample
from hazardhunt.sut.compat import mismatch, parameter_names, takes, warn_earlier
from hazardhunt.sut.safety_layer import FieldShape
from hazardhunt.world.bodies import RobotParams
from hazardhunt.world.geometry import to_body_frame

OTHER = "other"
"""The class of a failure that fits no other class."""

SIDES = ("left", "right")
FACES = ("front", "left", "right", "rear")
MOTIONS = ("moving", "standing")


@runtime_checkable
class FailureClassifier(Protocol):
    """Names the mechanism of a failure episode; the plug-in point for other taxonomies."""

    @property
    def name(self) -> str:
        """Short name of the taxonomy, recorded with the classes."""
        ...

    def classes_for(self, field: FieldShape) -> tuple[str, ...]:
        """Every class ``classify`` can return under this protective field, ``other`` last."""
        ...

    def classify(
        self, trajectory: Sequence[TrajectorySample], summary: EpisodeSummary, field: FieldShape
    ) -> str:
        """The class of one failure, from its trajectory, its summary and the field."""
        ...


@dataclass(frozen=True)
class MechanismClassifier:
    """The default taxonomy (SPEC 6): contact face x safety-layer history x human motion."""

    name: str = "mechanism"
    robot: RobotParams = RobotParams()
    """The robot's dimensions, for the straight-edge test."""
    moving_speed: float = 0.1
    """Above this speed at contact the human counts as moving, in m/s."""
    standstill_speed: float = 0.05
    """From this speed on the robot counts as driving (below it, standing: SPEC 4), in m/s."""
    edge_tolerance: float = 0.05
    """Allowance beyond the front face for an entry over the straight edge, in m."""

    def classes_for(self, field: FieldShape) -> tuple[str, ...]:
        if not field.covers_anything:
            return (*(f"{face}/{motion}" for face in FACES for motion in MOTIONS), OTHER)
        return (
            *(f"side-{side}/no-stop" for side in SIDES),
            *(f"side-{side}/restarted" for side in SIDES),
            *(f"side-{side}/braking" for side in SIDES),
            *(f"field/braking/{motion}" for motion in MOTIONS),
            *(f"edge-entry/{motion}" for motion in MOTIONS),
            OTHER,
        )

    def classify(
        self, trajectory: Sequence[TrajectorySample], summary: EpisodeSummary, field: FieldShape
    ) -> str:
        face = summary.contact_face
        if face not in FACES or not trajectory:
            return OTHER
        motion = "moving" if human_speed_at_end(trajectory) > self.moving_speed else "standing"
        if not field.covers_anything:
            return f"{face}/{motion}"
        if not any(row.emergency_stop for row in trajectory):
            return f"side-{face}/no-stop" if face in SIDES else OTHER
        if trajectory[-1].emergency_stop:
            if self._entered_over_edge(trajectory):
                return f"edge-entry/{motion}"
            if face == "front":
                return f"field/braking/{motion}"
            return f"side-{face}/braking" if face in SIDES else OTHER
        if face in SIDES and self._drove_after_release(trajectory):
            return f"side-{face}/restarted"
        return OTHER

    def _entered_over_edge(self, trajectory: Sequence[TrajectorySample]) -> bool:
        """Whether the human's last entry into the field came from beside the robot.

        A human who grazes the field between two samples and is out of it again at the next
        one (beside the robot, at the contact) shows in no sample: then the first sample of
        the stop that holds at the contact stands for the entry.
        """
        entry = last_field_entry(trajectory)
        if entry is None:
            entry = final_stop_onset(trajectory)
        row = trajectory[entry]
        forward, _ = to_body_frame(
            np.array([row.human_x, row.human_y]), row.robot_x, row.robot_y, row.robot_heading
        )
        return forward <= self.robot.length / 2 + self.edge_tolerance

    def _drove_after_release(self, trajectory: Sequence[TrajectorySample]) -> bool:
        """Whether the robot drove again after the last emergency stop was released."""
        last_stop = max(i for i, row in enumerate(trajectory) if row.emergency_stop)
        return any(row.robot_speed >= self.standstill_speed for row in trajectory[last_stop + 1 :])


def human_speed_at_end(trajectory: Sequence[TrajectorySample]) -> float:
    """The human's speed between the last two samples with distinct times, in m/s (0 for one)."""
    last = trajectory[-1]
    for previous in reversed(trajectory[:-1]):
        elapsed = last.time - previous.time
        if elapsed > 0:
            distance = math.hypot(last.human_x - previous.human_x, last.human_y - previous.human_y)
            return float(distance / elapsed)
    return 0.0


def last_field_entry(trajectory: Sequence[TrajectorySample]) -> int | None:
    """Index of the last sample where ``human_in_field`` turned true (None: never in it)."""
    entry = None
    was_in_field = False
    for index, row in enumerate(trajectory):
        in_field = bool(row.human_in_field)
        if in_field and not was_in_field:
            entry = index
        was_in_field = in_field
    return entry


def final_stop_onset(trajectory: Sequence[TrajectorySample]) -> int:
    """Index of the first sample of the emergency stop that holds at the last sample."""
    onset = len(trajectory) - 1
    while onset > 0 and trajectory[onset - 1].emergency_stop:
        onset -= 1
    return onset


def classify_failures(
    trajectories: Mapping[int, Sequence[TrajectorySample]],
    summaries: Mapping[int, EpisodeSummary],
    field: FieldShape,
    classifier: FailureClassifier | None = None,
) -> dict[int, str]:
    """The class of every episode of ``trajectories`` (by episode id), ``other`` included.

    Raises:
        KeyError: For an episode without a summary.
    """
    chosen: FailureClassifier = classifier if classifier is not None else MechanismClassifier()
    return {
        episode: chosen.classify(trajectory, summaries[episode], field)
        for episode, trajectory in trajectories.items()
    }


class _ClassifierBefore020:
    """A classifier as before 0.2.0: ``classes_for(field_diameter)`` and
    ``classify(trajectory_rows, summary_row, field_diameter)``, the field as its front
    diameter (m, None: no field) and the records as plain rows (dicts)."""

    def __init__(self, classifier: Any) -> None:
        self.classifier = classifier

    @property
    def name(self) -> str:
        return str(self.classifier.name)

    def classes_for(self, field: FieldShape) -> tuple[str, ...]:
        return tuple(self.classifier.classes_for(field.diameter))

    def classify(
        self, trajectory: Sequence[TrajectorySample], summary: EpisodeSummary, field: FieldShape
    ) -> str:
        rows = [sample.as_row() for sample in trajectory]
        return cast(str, self.classifier.classify(rows, summary.as_row(), field.diameter))


def adapt_classifier(path: str, classifier: FailureClassifier) -> FailureClassifier:
    """``classifier`` as hazardhunt calls it: itself, or wrapped if it implements the protocol
    before 0.2.0 (its methods take a ``field_diameter``; see :mod:`hazardhunt.sut.compat`).

    Raises:
        PluginError: ``classes_for`` or ``classify`` takes parameters of no version of the
            protocol.
    """
    if not takes(classifier.classes_for, 1):
        raise mismatch(path, "classes_for", classifier.classes_for, "(field)")
    if not takes(classifier.classify, 3):
        raise mismatch(path, "classify", classifier.classify, "(trajectory, summary, field)")
    earlier = "field_diameter" in parameter_names(classifier.classes_for)
    if not earlier:
        return classifier
    warn_earlier(
        path, "failure classifier", "classes_for", "(field_diameter)", "(field: FieldShape)"
    )
    return _ClassifierBefore020(classifier)
