"""The laser-scanner safety layer and the shapes of its protective field (SPEC 3).

A field shape is a half-disc ahead of the robot whose straight edge lies on the robot's front
face, centred on its long axis, so the robot's sides are not covered (the study's
configuration); it may add bands of ``side_margin`` metres along both sides, from the rear to the
front face. A human disc overlapping the field triggers an emergency stop that overrides the
controller after the field's ``response_time``; the stop holds until the robot stands still and
the field is free.

The built-in field settings are ``none``, ``1.25m`` and ``2m``; a scenario file may define
more (``[fields.NAME]`` with ``diameter``, ``side_margin`` and ``response_time``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

from hazardhunt.errors import InputError
from hazardhunt.sut.protocols import FloatArray, SafetyStatus
from hazardhunt.textfiles import shown_value
from hazardhunt.world.bodies import RobotParams, RobotState
from hazardhunt.world.geometry import (
    point_half_disc_distance,
    point_rectangle_clearance,
    to_body_frame,
)
from hazardhunt.world.scenario import Scenario


class FieldShapeError(InputError):
    """A field shape's value out of its range; ``key`` names it."""

    def __init__(self, key: str, problem: str) -> None:
        super().__init__(f"{key} {problem}")
        self.key = key


@dataclass(frozen=True)
class FieldShape:
    """A protective field: a half-disc ahead of the robot, bands along its sides, and the time
    the safety function takes to brake once the field is violated."""

    diameter: float | None = None
    """Diameter of the half-disc ahead of the front face, in m (None: no front field)."""
    side_margin: float = 0.0
    """Width of the bands along both sides, in m (0: the sides are not covered)."""
    response_time: float = 0.0
    """Time from the human entering the field to the brake engaging, in s: the T of ISO
    13855's minimum distance (the scanner's response time plus the drive's reaction). 0, as
    the study, brakes in the physics step the field is violated."""

    def __post_init__(self) -> None:
        for key, value in vars(self).items():
            # A plug-in's parameters come as written: true is no diameter of 1 m.
            if value is not None and (
                isinstance(value, bool) or not isinstance(value, int | float)
            ):
                raise FieldShapeError(key, f"must be a number, not {shown_value(value)}")
        diameter, side_margin, response_time = self.diameter, self.side_margin, self.response_time
        if diameter is not None and not (math.isfinite(diameter) and diameter > 0):
            raise FieldShapeError("diameter", f"must be a positive number of m, not {diameter!r}")
        if not (math.isfinite(side_margin) and side_margin >= 0):
            raise FieldShapeError("side_margin", f"must be >= 0 m, not {side_margin!r}")
        if not (math.isfinite(response_time) and response_time >= 0):
            raise FieldShapeError("response_time", f"must be >= 0 s, not {response_time!r}")

    @property
    def covers_anything(self) -> bool:
        """Whether the field covers any ground (the setting ``none`` does not)."""
        return self.diameter is not None or self.side_margin > 0.0


FIELD_SETTINGS: dict[str, FieldShape] = {
    "none": FieldShape(None),
    "1.25m": FieldShape(1.25),
    "2m": FieldShape(2.0),
}
"""The built-in field settings (the study's): no field, and half-discs of 1.25 m and 2 m."""


def field_shape(scenario: Scenario, setting: str) -> FieldShape:
    """The shape of a field setting: a built-in one, or one the scenario defines.

    Raises:
        ValueError: The setting is unknown (naming the settings there are), or the scenario's
            definition of it is wrong (naming the file and the key).
    """
    shapes = scenario_field_shapes(scenario)
    if setting in shapes:
        return shapes[setting]
    raise ValueError(f"unknown field {setting!r}: use one of {', '.join(shapes)}")


def scenario_field_shapes(scenario: Scenario) -> dict[str, FieldShape]:
    """Every field setting of ``scenario``: the built-in ones and those it defines.

    Raises:
        ValueError: A definition is wrong or redefines a built-in setting, naming the file and
            the key.
    """
    shapes = dict(FIELD_SETTINGS)
    for name, values in scenario.fields.items():
        where = f"{scenario.source}: fields.{name}"
        if name in FIELD_SETTINGS:
            raise ValueError(
                f"{where}: {name!r} is a built-in field setting and cannot be redefined"
            )
        shapes[name] = _shape_from_table(where, values)
    return shapes


def _shape_from_table(where: str, values: Mapping[str, Any]) -> FieldShape:
    known = [field.name for field in fields(FieldShape)]
    for key, value in values.items():
        if key not in known:
            raise ValueError(f"{where}.{key}: unknown key (a field has {', '.join(known)})")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"{where}.{key}: must be a number, not {value!r}")
    try:
        return FieldShape(**{key: float(value) for key, value in values.items()})
    except FieldShapeError as error:
        raise ValueError(f"{where}.{error.key}: {error}") from None


_STATUSES = {
    (stop, in_field): SafetyStatus(emergency_stop=stop, human_in_field=in_field)
    for stop in (False, True)
    for in_field in (False, True)
}
"""The four possible verdicts, built once: the layer answers at every physics step."""


class LaserSafetyLayer:
    """Emergency stop on a protective field (see :class:`FieldShape`)."""

    def __init__(
        self,
        diameter: float | None = None,
        side_margin: float = 0.0,
        response_time: float = 0.0,
        robot: RobotParams = RobotParams(),
        standstill_speed: float = 1e-9,
    ) -> None:
        """Args:
        diameter: Of the half-disc ahead of the front face, in m (None: none).
        side_margin: Width of the bands along both sides, in m (0: none).
        response_time: From a violation of the field to the brake, in s.
        robot: The robot's dimensions.
        standstill_speed: Speed below which the robot counts as standing still for the
            restart rule, in m/s.

        Raises:
            ValueError: A negative or non-finite size or speed.
        """
        self.field = FieldShape(diameter, side_margin, response_time)
        if isinstance(standstill_speed, bool) or not isinstance(standstill_speed, int | float):
            raise FieldShapeError(
                "standstill_speed", f"must be a number, not {shown_value(standstill_speed)}"
            )
        if not (math.isfinite(standstill_speed) and standstill_speed >= 0):
            raise FieldShapeError("standstill_speed", f"must be >= 0 m/s, not {standstill_speed!r}")
        self.robot = robot
        self.standstill_speed = standstill_speed
        self._emergency_stop = False
        self._violated_at: float | None = None

    @classmethod
    def for_field(cls, shape: FieldShape, robot: RobotParams = RobotParams()) -> LaserSafetyLayer:
        """The layer that guards ``shape``."""
        return cls(shape.diameter, shape.side_margin, shape.response_time, robot)

    def reset(self) -> None:
        """Release any stop."""
        self._emergency_stop = False
        self._violated_at = None

    def human_in_field(self, robot: RobotState, human_position: FloatArray, radius: float) -> bool:
        """Whether the human disc overlaps the protective field."""
        shape = self.field
        if not shape.covers_anything:
            return False
        forward, left = to_body_frame(human_position, robot.x, robot.y, robot.heading)
        if shape.diameter is not None:
            distance = point_half_disc_distance(
                forward - self.robot.length / 2, left, shape.diameter / 2
            )
            if distance < radius:
                return True
        if shape.side_margin > 0.0:
            # The band along the nearer side: the robot's length by side_margin, beside it.
            band_centre = self.robot.width / 2 + shape.side_margin / 2
            distance = point_rectangle_clearance(
                forward, abs(left) - band_centre, self.robot.length, shape.side_margin
            )
            return distance < radius
        return False

    def update(
        self, time: float, robot: RobotState, human_position: FloatArray, radius: float
    ) -> SafetyStatus:
        """Check the field at one physics step and decide whether the stop holds.

        A violation brakes the robot ``response_time`` after it began, even if the human has
        left the field meanwhile (the scanner's outputs have switched); the stop then holds
        until the robot stands and the field is free.
        """
        in_field = self.human_in_field(robot, human_position, radius)
        if in_field and self._violated_at is None and not self._emergency_stop:
            self._violated_at = time
        if self._violated_at is not None and (
            time - self._violated_at >= self.field.response_time - 1e-9
        ):
            self._emergency_stop = True
            self._violated_at = None
        elif self._emergency_stop and not in_field and robot.speed <= self.standstill_speed:
            self._emergency_stop = False
        return _STATUSES[self._emergency_stop, in_field]
