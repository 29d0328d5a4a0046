"""The laser-scanner safety layer: a half-disc protective field ahead of the robot (SPEC 3).

The field's straight edge lies on the robot's front face, centred on its long axis, so the
robot's sides are not covered (the study's configuration). A field shape may add bands of
``side_margin`` metres along both sides, from the rear to the front face. A human disc
overlapping the field triggers an emergency stop that overrides the controller; the stop holds
until the robot stands still and the field is free.
"""

from __future__ import annotations

from dataclasses import dataclass

from hazardhunt.sut.protocols import FloatArray, RobotState, SafetyStatus
from hazardhunt.world.bodies import RobotParams
from hazardhunt.world.geometry import (
    point_half_disc_distance,
    point_rectangle_clearance,
    to_body_frame,
)

FIELD_SETTINGS: dict[str, float | None] = {"none": None, "1.25m": 1.25, "2m": 2.0}
"""The named field settings and their protective-field diameters, in m (None: no field)."""


_STATUSES = {
    (stop, in_field): SafetyStatus(emergency_stop=stop, human_in_field=in_field)
    for stop in (False, True)
    for in_field in (False, True)
}
"""The four possible verdicts, built once: the layer answers at every physics step."""


@dataclass
class LaserSafetyLayer:
    """Emergency stop on a half-disc protective field of ``diameter`` metres (None: no field),
    and on bands of ``side_margin`` metres along the robot's sides (0: none)."""

    diameter: float | None
    robot: RobotParams = RobotParams()
    standstill_speed: float = 1e-9
    """Speed below which the robot counts as standing still for the restart rule, in m/s."""
    side_margin: float = 0.0
    """Width of the bands the field also covers along both sides of the robot, in m."""
    _stopping: bool = False

    def __post_init__(self) -> None:
        if self.diameter is not None and not self.diameter > 0:
            raise ValueError(f"diameter must be positive or None, not {self.diameter!r}")
        if not self.side_margin >= 0:
            raise ValueError(f"side_margin must be >= 0, not {self.side_margin!r}")

    def reset(self) -> None:
        """Release any stop."""
        self._stopping = False

    def human_in_field(self, robot: RobotState, human_position: FloatArray, radius: float) -> bool:
        """Whether the human disc overlaps the protective field."""
        if self.diameter is None and self.side_margin == 0.0:
            return False
        forward, left = to_body_frame(human_position, robot.x, robot.y, robot.heading)
        if self.diameter is not None:
            distance = point_half_disc_distance(
                forward - self.robot.length / 2, left, self.diameter / 2
            )
            if distance < radius:
                return True
        if self.side_margin > 0.0:
            # The band along the nearer side: the robot's length by side_margin, beside it.
            band_centre = self.robot.width / 2 + self.side_margin / 2
            distance = point_rectangle_clearance(
                forward, abs(left) - band_centre, self.robot.length, self.side_margin
            )
            return distance < radius
        return False

    def update(self, robot: RobotState, human_position: FloatArray, radius: float) -> SafetyStatus:
        """Check the field at one physics step and decide whether the stop holds."""
        in_field = self.human_in_field(robot, human_position, radius)
        if in_field:
            self._stopping = True
        elif self._stopping and robot.speed <= self.standstill_speed:
            self._stopping = False
        return _STATUSES[self._stopping, in_field]
