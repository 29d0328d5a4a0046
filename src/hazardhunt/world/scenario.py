"""Scenarios as data: a floor map file and a scenario file (TOML), validated on load.

A scenario names its map (a path relative to the scenario file: a TOML file of polygons or a
ROS map_server YAML file, :mod:`hazardhunt.world.rosmap`; or an inline ``[map]`` table), the
robot's start pose, waypoints and goal, and the human's start pose. Every error names the file,
the field and what is wrong.
"""

from __future__ import annotations

import math
import re
import sys
from dataclasses import dataclass
from dataclasses import field as dataclass_field
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    Strict,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)
from shapely.geometry import Polygon
from shapely.validation import explain_validity

from hazardhunt.errors import InputError
from hazardhunt.textfiles import format_validation_error, loads_toml, read_input_text
from hazardhunt.world.bodies import HumanParams
from hazardhunt.world.floor import FloorMap, Obstacle
from hazardhunt.world.geometry import FloatArray
from hazardhunt.world.rosmap import (
    MAP_SUFFIXES,
    MapFileError,
    OccupancyGrid,
    decode_cells,
    encode_cells,
    grid_floor,
    load_ros_map,
)

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

BUILTIN_SCENARIOS = ("crossing", "head-on", "overtaking")


class ScenarioError(InputError):
    """A scenario or map file that cannot be used; the message names the file and the field."""


@dataclass(frozen=True)
class Pose:
    """A position and heading on the floor."""

    x: float
    """m"""
    y: float
    """m"""
    heading: float
    """rad, counter-clockwise from east"""

    @property
    def position(self) -> FloatArray:
        """(x, y) as an array, in m."""
        return np.array([self.x, self.y])


@dataclass(frozen=True)
class Scenario:
    """An initial state on a floor: where the robot starts and must go, where the human starts."""

    name: str
    floor: FloorMap
    robot_start: Pose
    waypoints: FloatArray
    """Shape (K, 2): points the robot's route passes through, in order, in m."""
    goal: FloatArray
    """Shape (2,): the robot's goal, in m."""
    human_start: Pose
    description: str = ""
    source: str = ""
    """The file the scenario was loaded from."""
    fields: dict[str, dict[str, Any]] = dataclass_field(default_factory=dict)
    """Field settings the scenario defines besides the built-in ones, by name: each its
    ``[fields.NAME]`` table, which :func:`hazardhunt.sut.safety_layer.field_shape` reads."""


class _Strict(BaseModel):
    # Every number of a scenario or map file is finite.
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


Number = Annotated[float, Strict()]
"""An int or a float: a file's ``true`` or ``"10"`` is refused, not read as 1 or 10."""


class _PointSpec(_Strict):
    x: Number
    y: Number


class _PoseSpec(_PointSpec):
    heading_deg: Number = 0.0


Vertex = tuple[Number, Number]


_GEOS_PROBLEM = re.compile(r"[^\[]+\[(?P<x>\S+) (?P<y>\S+)\]")
"""GEOS's reason for an invalid polygon, such as ``Self-intersection[1 1]``."""


def _check_polygon(polygon: list[Vertex]) -> list[Vertex]:
    shape = Polygon(polygon)
    if shape.area < 1e-9:
        raise ValueError("polygon has no area")
    if not shape.is_valid:
        reason = explain_validity(shape)
        found = _GEOS_PROBLEM.fullmatch(reason)
        where = f"near ({float(found['x']):g}, {float(found['y']):g})" if found else f"({reason})"
        raise ValueError(f"polygon edges cross or touch each other {where}")
    return polygon


PolygonSpec = Annotated[list[Vertex], Field(min_length=3)]


class _ObstacleSpec(_Strict):
    name: str
    kind: Literal["wall", "shelf"] = "shelf"
    polygon: PolygonSpec

    _polygon_ok = field_validator("polygon")(_check_polygon)


class _BlindZoneSpec(_Strict):
    name: str = ""
    polygon: PolygonSpec

    _polygon_ok = field_validator("polygon")(_check_polygon)


class _OccupancySpec(_Strict):
    """A site map's grid inlined (what a run records of a scenario on a ROS map)."""

    resolution: Number = Field(gt=0)
    origin: tuple[Number, Number, Number]
    columns: Annotated[int, Strict(), Field(ge=1)]
    rows: Annotated[int, Strict(), Field(ge=1)]
    cells: str

    @field_validator("cells")
    @classmethod
    def _cells_fit(cls, value: str, info: ValidationInfo) -> str:
        columns, rows = info.data.get("columns"), info.data.get("rows")
        if columns is not None and rows is not None:
            decode_cells(value, columns, rows)
        return value

    @property
    def grid(self) -> OccupancyGrid:
        """The grid the table holds."""
        cells = decode_cells(self.cells, self.columns, self.rows)
        return OccupancyGrid(self.resolution, self.origin, cells)


class _MapSpec(_Strict):
    name: str
    width: Number = Field(gt=0)
    height: Number = Field(gt=0)
    obstacles: list[_ObstacleSpec] = []
    blind_zones: list[_BlindZoneSpec] = []
    occupancy: _OccupancySpec | None = None

    @model_validator(mode="after")
    def _grid_alone(self) -> _MapSpec:
        if self.occupancy is None:
            return self
        grid = self.occupancy.grid
        if self.obstacles:
            raise ValueError("obstacles: must be empty beside an occupancy grid (its cells are)")
        if (self.width, self.height) != (grid.width, grid.height):
            raise ValueError(
                f"width, height: must be the grid's {grid.width:g} m x {grid.height:g} m, "
                f"not {self.width:g} m x {self.height:g} m"
            )
        return self


class _RobotSpec(_Strict):
    start: _PoseSpec
    waypoints: list[_PointSpec] = []
    goal: _PointSpec


class _HumanSpec(_Strict):
    start: _PoseSpec


class _ScenarioSpec(_Strict):
    name: str
    description: str = ""
    map: str | dict[str, Any]
    """A map file's name, or the map's table (validated by :func:`_map_table`, so that an
    error names its key as ``map.KEY``)."""
    robot: _RobotSpec
    human: _HumanSpec
    fields: dict[str, dict[str, Any]] = {}


def builtin_scenario_path(name: str) -> Path:
    """Path of a built-in scenario file."""
    return Path(str(resources.files("hazardhunt") / "scenarios" / f"{name}.toml"))


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load a built-in scenario by name (``crossing``, ``head-on``, ``overtaking``) or a file.

    Raises:
        ScenarioError: The file is missing, is not valid TOML, or a field is wrong.
    """
    if str(name_or_path) in BUILTIN_SCENARIOS:
        path = builtin_scenario_path(str(name_or_path))
    else:
        path = Path(name_or_path)
        if not path.exists():
            raise ScenarioError(
                f"{path}: no such scenario file (built-in scenarios: "
                f"{', '.join(BUILTIN_SCENARIOS)})"
            )
    spec = _parse(path, _ScenarioSpec)
    if isinstance(spec.map, str):
        map_path = (path.parent / spec.map).resolve()
        if not map_path.exists():
            raise ScenarioError(f"{path}: map: no such map file {spec.map!r}")
        if map_path.suffix.lower() in MAP_SUFFIXES:
            floor = grid_floor(map_path.stem, _ros_map(map_path))
        else:
            floor = _build_floor(_parse(map_path, _MapSpec))
    else:
        floor = _build_floor(_map_table(spec.map, path))
    return _build_scenario(spec, floor, path)


def scenario_from_data(data: dict[str, Any], source: str) -> Scenario:
    """A scenario from the contents of a scenario file whose ``map`` is an inline table (as
    regression cases store it); errors name ``source``.

    Raises:
        ScenarioError: A field is wrong.
    """
    try:
        spec = _ScenarioSpec.model_validate(data)
    except ValidationError as error:
        raise ScenarioError(f"{source}: {format_validation_error(error, _ScenarioSpec)}") from error
    if isinstance(spec.map, str):
        raise ScenarioError(f"{source}: map: must be an inline table here, not a file name")
    return _build_scenario(spec, _build_floor(_map_table(spec.map, source)), Path(source))


def _map_table(table: dict[str, Any], source: str | Path) -> _MapSpec:
    try:
        return _MapSpec.model_validate(table)
    except ValidationError as error:
        raise ScenarioError(f"{source}: map.{format_validation_error(error, _MapSpec)}") from None


def _build_scenario(spec: _ScenarioSpec, floor: FloorMap, path: Path) -> Scenario:
    scenario = Scenario(
        name=spec.name,
        description=spec.description,
        floor=floor,
        robot_start=_pose(spec.robot.start),
        waypoints=np.array([[p.x, p.y] for p in spec.robot.waypoints]).reshape(-1, 2),
        goal=np.array([spec.robot.goal.x, spec.robot.goal.y]),
        human_start=_pose(spec.human.start),
        source=str(path),
        fields={name: dict(table) for name, table in spec.fields.items()},
    )
    _check_placement(scenario, path)
    return scenario


def _parse(path: Path, model: type[_Strict]) -> Any:
    try:
        data = loads_toml(read_input_text(path))
    except tomllib.TOMLDecodeError as error:
        raise ScenarioError(f"{path}: not valid TOML: {error}") from error
    except OSError as error:
        raise ScenarioError(f"{path}: cannot be read: {error.strerror}") from error
    except UnicodeDecodeError as error:
        raise ScenarioError(f"{path}: not a text file: {error.reason}") from None
    try:
        return model.model_validate(data)
    except ValidationError as error:
        raise ScenarioError(f"{path}: {format_validation_error(error, model)}") from error


def _ros_map(path: Path) -> OccupancyGrid:
    try:
        return load_ros_map(path)
    except MapFileError as error:
        raise ScenarioError(str(error)) from None


def _pose(spec: _PoseSpec) -> Pose:
    return Pose(spec.x, spec.y, math.radians(spec.heading_deg))


def _build_floor(spec: _MapSpec) -> FloorMap:
    def counter_clockwise(polygon: list[Vertex]) -> FloatArray:
        vertices = np.asarray(polygon, dtype=np.float64)
        return vertices if Polygon(polygon).exterior.is_ccw else vertices[::-1].copy()

    blind_zones = tuple(counter_clockwise(zone.polygon) for zone in spec.blind_zones)
    if spec.occupancy is not None:
        return grid_floor(spec.name, spec.occupancy.grid, blind_zones)
    return FloorMap(
        name=spec.name,
        width=spec.width,
        height=spec.height,
        obstacles=tuple(
            Obstacle(o.name, counter_clockwise(o.polygon), o.kind) for o in spec.obstacles
        ),
        blind_zones=blind_zones,
    )


def _check_placement(scenario: Scenario, path: Path) -> None:
    floor = scenario.floor
    points = {
        "robot.start": scenario.robot_start.position,
        "robot.goal": scenario.goal,
        "human.start": scenario.human_start.position,
        **{f"robot.waypoints.{i}": p for i, p in enumerate(scenario.waypoints)},
    }
    for field, point in points.items():
        if not floor.on_floor(point):
            raise ScenarioError(
                f"{path}: {field}: ({point[0]:g}, {point[1]:g}) lies off the "
                f"{floor.width:g} m x {floor.height:g} m floor{_frame_hint(floor)}"
            )
        if floor.inside_obstacle(point):
            raise ScenarioError(
                f"{path}: {field}: ({point[0]:g}, {point[1]:g}) lies inside an obstacle"
                f"{_frame_hint(floor)}"
            )
    _check_human_body(floor, scenario.human_start.position, path)


def _frame_hint(floor: FloorMap) -> str:
    # A position copied from the map's own frame (RViz) lies elsewhere on the floor.
    grid = floor.occupancy
    if grid is None or grid.origin[:2] == (0.0, 0.0):
        return ""
    x, y, _ = grid.origin
    return (
        f" (positions are measured from the map's lower-left corner, at ({x:g}, {y:g}) in "
        "the map's frame)"
    )


def _check_human_body(floor: FloorMap, point: FloatArray, path: Path) -> None:
    # A human whose disc starts on a wall or a shelf can never move: every episode would be
    # played without one.
    radius = HumanParams().radius
    x, y = float(point[0]), float(point[1])
    where = f"{path}: human.start: ({x:g}, {y:g})"
    body = f"the human is a disc of radius {radius:g} m"
    if not (radius <= x <= floor.width - radius and radius <= y <= floor.height - radius):
        raise ScenarioError(f"{where} lies too near the edge of the floor ({body})")
    if floor.disc_blocked_at(x, y, radius):
        raise ScenarioError(f"{where} overlaps an obstacle ({body})")


def scenario_data(name_or_path: str | Path) -> dict[str, Any]:
    """The contents of a built-in scenario or a scenario file, with a map file it names
    inlined as the ``map`` table: everything needed to rebuild it elsewhere (a ROS map as its
    grid of cells, which holds what its image and thresholds say).

    Raises:
        ScenarioError: The scenario does not load.
    """
    scenario = load_scenario(name_or_path)  # reports any problem with the files first
    path = Path(scenario.source)
    data: dict[str, Any] = loads_toml(path.read_text(encoding="utf-8"))
    if isinstance(data.get("map"), str):
        map_path = path.parent / data["map"]
        grid = scenario.floor.occupancy
        if grid is not None and map_path.suffix.lower() in MAP_SUFFIXES:
            data["map"] = _grid_data(scenario.floor.name, grid)
        else:
            data["map"] = loads_toml(map_path.read_text(encoding="utf-8"))
    return data


def _grid_data(name: str, grid: OccupancyGrid) -> dict[str, Any]:
    return {
        "name": name,
        "width": grid.width,
        "height": grid.height,
        "occupancy": {
            "resolution": grid.resolution,
            "origin": list(grid.origin),
            "columns": grid.columns,
            "rows": grid.rows,
            "cells": encode_cells(grid.cells),
        },
    }
