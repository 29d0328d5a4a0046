"""The laser-scanner safety layer: a half-disc protective field ahead of the robot (SPEC 3).

The field's straight edge lies on the robot's front face, centred on its long axis, so the
robot's sides are not covered. A human disc overlapping the field triggers an emergency stop that
overrides the controller; the stop holds until the robot stands still and the field is free.
"""

from __future__ import annotations

from dataclasses import dataclass

from hazardhunt.sut.protocols import FloatArray, RobotState, SafetyStatus
from hazardhunt.world.bodies import RobotParams
from hazardhunt.world.geometry import point_half_disc_distance, to_body_frame

FIELD_SETTINGS: dict[str, float | None] = {"none": None, "1.25m": 1.25, "2m": 2.0}
"""The named field settings and their protective-field diameters, in m (None: no field)."""


_STATUSES = {
    (stop, in_field): SafetyStatus(emergency_stop=stop, human_in_field=in_field)
    for stop in (False, True)
    for in_field in (False, True)
}
"""The four possible verdicts, built once: the layer answers at every physics step."""


def field_diameter(setting: str) -> float | None:
    """The protective-field diameter of a named setting, in m.

    Raises:
        ValueError: For a setting that is not one of ``FIELD_SETTINGS``.
    """
    if setting not in FIELD_SETTINGS:
        raise ValueError(f"unknown field setting {setting!r}; choose one of {list(FIELD_SETTINGS)}")
    return FIELD_SETTINGS[setting]


@dataclass
class LaserSafetyLayer:
    """Emergency stop on a half-disc protective field of ``diameter`` metres (None: no field)."""

    diameter: float | None
    robot: RobotParams = RobotParams()
    standstill_speed: float = 1e-9
    """Speed below which the robot counts as standing still for the restart rule, in m/s."""
    _stopping: bool = False

    def reset(self) -> None:
        """Release any stop."""
        self._stopping = False

    def human_in_field(self, robot: RobotState, human_position: FloatArray, radius: float) -> bool:
        """Whether the human disc overlaps the protective field."""
        if self.diameter is None:
            return False
        forward, left = to_body_frame(human_position, robot.x, robot.y, robot.heading)
        distance = point_half_disc_distance(
            forward - self.robot.length / 2, left, self.diameter / 2
        )
        return distance < radius

    def update(self, robot: RobotState, human_position: FloatArray, radius: float) -> SafetyStatus:
        """Check the field at one physics step and decide whether the stop holds."""
        in_field = self.human_in_field(robot, human_position, radius)
        if in_field:
            self._stopping = True
        elif self._stopping and robot.speed <= self.standstill_speed:
            self._stopping = False
        return _STATUSES[self._stopping, in_field]
