"""Site maps as ROS writes them: a map_server YAML file naming a PGM, PNG or BMP image.

The image is read the way ROS 2's ``nav2_map_server`` reads it into a ``nav_msgs/OccupancyGrid``:
a pixel's shade is the mean of its colour channels on a scale from 0 (black) to 1 (white); its
occupancy is ``1 - shade`` (``shade`` with ``negate: 1``); ``mode`` then says what a cell holds:

- ``trinary`` (the default): occupied (100) above ``occupied_thresh``, free (0) below
  ``free_thresh``, unknown (-1) in between; an image with transparency has its alpha averaged in
  with the colours;
- ``scale``: like ``trinary``, but in between the occupancy scaled from 0 to 100, and any
  transparent pixel unknown;
- ``raw``: the shade times 255 rounded is the cell's value, unknown above 100.

The image's top row is the map's northmost row. hazardhunt places the map's lower-left corner
at the floor's (0, 0) and its axes along the floor's: ``origin`` (the map frame's pose of that
corner, as ``[x, y, yaw]``) is kept with the grid, for whoever speaks to the robot in the map's
frame, and moves nothing on the floor.

Occupied and unknown cells are obstacles, for the human, the robot, the scanner and the route:
nobody walks where the map does not say the floor is free. Cells in between (1 to 99, only in
``scale`` and ``raw`` mode) are floor.
"""

from __future__ import annotations

import base64
import math
import zlib
from dataclasses import dataclass
from decimal import Decimal
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import shapely
import yaml
from numpy.typing import NDArray
from PIL import Image, UnidentifiedImageError
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    Strict,
    ValidationError,
    ValidationInfo,
    field_validator,
)
from shapely.geometry import Polygon

from hazardhunt.errors import InputError
from hazardhunt.textfiles import format_validation_error
from hazardhunt.world.floor import FloorMap, Obstacle
from hazardhunt.world.geometry import FloatArray

OCCUPIED = 100
"""A cell's value where the map is occupied (``nav_msgs/OccupancyGrid``)."""

FREE = 0
"""A cell's value where the map is free."""

UNKNOWN = -1
"""A cell's value where the map does not know."""

MAP_SUFFIXES = (".yaml", ".yml")
"""File names a scenario's ``map`` reads as a ROS map."""

IMAGE_FORMATS = {"PPM": "PGM", "PNG": "PNG", "BMP": "BMP"}
"""The image formats a map may be in (Pillow's name: the name a user knows)."""


class MapFileError(InputError):
    """A ROS map that cannot be used; the message names the file and the field."""


@dataclass(frozen=True)
class OccupancyGrid:
    """A map as ``nav_msgs/OccupancyGrid`` holds it."""

    resolution: float
    """Side of a cell, in m."""
    origin: tuple[float, float, float]
    """The map frame's pose (x in m, y in m, yaw in rad) of the lower-left corner of cell (0, 0),
    which lies at the floor's (0, 0)."""
    cells: NDArray[np.int8]
    """Shape (rows, columns): row 0 is the southmost (the image's bottom row); each value
    ``FREE``, ``OCCUPIED``, ``UNKNOWN`` or in between."""

    @property
    def columns(self) -> int:
        """Cells east."""
        return int(self.cells.shape[1])

    @property
    def rows(self) -> int:
        """Cells north."""
        return int(self.cells.shape[0])

    def edge(self, index: int) -> float:
        """The floor coordinate of the boundary ``index`` cells from the corner, in m: the
        decimal the resolution names times ``index``, so that 15 cells of 0.1 m end at 1.5."""
        return float(Decimal(repr(self.resolution)) * index)

    @property
    def width(self) -> float:
        """Extent east, in m."""
        return self.edge(self.columns)

    @property
    def height(self) -> float:
        """Extent north, in m."""
        return self.edge(self.rows)

    def blocked(self) -> NDArray[np.bool_]:
        """Shape (rows, columns): the cells that are obstacles (occupied or unknown)."""
        blocked: NDArray[np.bool_] = (self.cells == OCCUPIED) | (self.cells == UNKNOWN)
        return blocked


class _MapYaml(BaseModel):
    # map_server reads the keys below and ignores any other.
    model_config = ConfigDict(extra="ignore", frozen=True, allow_inf_nan=False)

    image: Annotated[str, Field(min_length=1)]
    resolution: Annotated[float, Strict(), Field(gt=0)]
    origin: tuple[
        Annotated[float, Strict()], Annotated[float, Strict()], Annotated[float, Strict()]
    ]
    """The map frame's (x, y, yaw) of the image's lower-left corner."""
    negate: Literal[0, 1]
    occupied_thresh: Annotated[float, Strict(), Field(ge=0, le=1)]
    free_thresh: Annotated[float, Strict(), Field(ge=0, le=1)]
    mode: Literal["trinary", "scale", "raw"] = "trinary"

    @field_validator("negate", mode="before")
    @classmethod
    def _negate_as_number(cls, value: Any) -> Any:
        # map_server takes 0 and 1 or false and true.
        return int(value) if isinstance(value, bool) else value

    @field_validator("origin", mode="before")
    @classmethod
    def _three_numbers(cls, value: Any) -> Any:
        if isinstance(value, list) and len(value) != 3:
            raise ValueError(f"must be [x, y, yaw], not {len(value)} numbers")
        return value

    @field_validator("free_thresh")
    @classmethod
    def _below_occupied(cls, value: float, info: ValidationInfo) -> float:
        occupied = info.data.get("occupied_thresh")
        if occupied is not None and value >= occupied:
            raise ValueError(f"must be less than occupied_thresh ({occupied:g}), not {value:g}")
        return value


def load_ros_map(path: Path) -> OccupancyGrid:
    """Read a map_server YAML file and its image into an occupancy grid.

    Raises:
        MapFileError: The YAML file or its image cannot be read, or a field is missing or out
            of range; the message names the file and the field.
    """
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as error:
        raise MapFileError(f"{path}: cannot be read: {error.strerror}") from None
    except UnicodeDecodeError as error:
        raise MapFileError(f"{path}: not a text file: {error.reason}") from None
    except yaml.YAMLError as error:
        where = getattr(error, "problem_mark", None)
        at = f" (line {where.line + 1})" if where is not None else ""
        problem = getattr(error, "problem", None) or "cannot be parsed"
        raise MapFileError(f"{path}: not valid YAML{at}: {problem}") from None
    if not isinstance(data, dict):
        raise MapFileError(f"{path}: not a map_server map (a table of image, resolution, ...)")
    try:
        spec = _MapYaml.model_validate(data)
    except ValidationError as error:
        raise MapFileError(f"{path}: {format_validation_error(error, _MapYaml)}") from None
    shade, alpha = _read_image(path, spec.image)
    cells = _occupancy(shade, alpha, spec)
    return OccupancyGrid(spec.resolution, spec.origin, np.ascontiguousarray(np.flipud(cells)))


def _read_image(path: Path, name: str) -> tuple[FloatArray, FloatArray | None]:
    """The image's shade per pixel, the mean of its colour channels from 0 (black) to 1
    (white), and its opacity from 0 to 1 where it has transparency; top row first."""
    image_path = path.parent / name
    where = f"{path}: image: {name!r}"
    try:
        with Image.open(image_path) as image:
            image.load()
            kind = image.format
            pixels = _shade(image) if kind in IMAGE_FORMATS else None
    except FileNotFoundError:
        raise MapFileError(f"{where}: no such image file") from None
    except UnidentifiedImageError:
        raise MapFileError(f"{where} is not an image (PGM, PNG or BMP)") from None
    except (OSError, SyntaxError, ValueError) as error:
        # Pillow raises these for a truncated file or a broken header.
        raise MapFileError(f"{where} cannot be read: {error}") from None
    if pixels is None:
        known = ", ".join(sorted(set(IMAGE_FORMATS.values())))
        raise MapFileError(f"{where} is a {kind} image, not one of {known}")
    return pixels


def _shade(image: Image.Image) -> tuple[FloatArray, FloatArray | None]:
    if image.mode in ("I", "I;16", "I;16B", "I;16L"):
        return np.asarray(image, dtype=np.float64) / 65535.0, None
    if image.mode == "F":
        raise ValueError("floating-point pixels are not a map")
    has_alpha = image.mode in ("RGBA", "LA", "PA") or "transparency" in image.info
    converted = image.convert("RGBA" if has_alpha else "RGB")
    pixels = np.asarray(converted, dtype=np.float64)
    shade = pixels[..., :3].sum(axis=-1) / 3.0 / 255.0
    return shade, (pixels[..., 3] / 255.0 if has_alpha else None)


def _occupancy(shade: FloatArray, alpha: FloatArray | None, spec: _MapYaml) -> NDArray[np.int8]:
    """The cells of map_server's ``mode`` from the image's shades (top row first)."""
    if spec.mode == "raw":
        value = np.round(shade * 255.0)
        return np.where(value <= OCCUPIED, value, UNKNOWN).astype(np.int8)
    if spec.mode == "trinary" and alpha is not None:
        # map_server averages the opacity in with the three colours.
        shade = (3.0 * shade + alpha) / 4.0
    occupancy = shade if spec.negate else 1.0 - shade
    occupied, free = spec.occupied_thresh, spec.free_thresh
    if spec.mode == "trinary":
        between = np.full(shade.shape, UNKNOWN, dtype=np.float64)
    else:
        between = np.rint((occupancy - free) / (occupied - free) * 100.0)
    cells = np.where(occupancy > occupied, OCCUPIED, np.where(occupancy < free, FREE, between))
    if spec.mode == "scale" and alpha is not None:
        cells = np.where(alpha < 1.0, UNKNOWN, cells)
    return cells.astype(np.int8)


def cell_rectangles(blocked: NDArray[np.bool_]) -> list[tuple[int, int, int, int]]:
    """Rectangles of cells that together cover the ``True`` cells, each once: the runs of a
    row, each grown north over the rows that have the same run. As (first column, first row,
    end column, end row), ends excluded, in the order they close (south first)."""
    rows = blocked.shape[0]
    rectangles: list[tuple[int, int, int, int]] = []
    open_runs: dict[tuple[int, int], int] = {}
    for row in range(rows + 1):
        runs = set(_runs(blocked[row])) if row < rows else set()
        for run in sorted(open_runs.keys() - runs):
            start_row = open_runs.pop(run)
            rectangles.append((run[0], start_row, run[1], row))
        for run in runs - open_runs.keys():
            open_runs[run] = row
    return rectangles


def _runs(line: NDArray[np.bool_]) -> list[tuple[int, int]]:
    padded = np.concatenate([[False], line, [False]]).astype(np.int8)
    changes = np.flatnonzero(np.diff(padded))
    return list(zip(changes[0::2].tolist(), changes[1::2].tolist(), strict=True))


def grid_floor(
    name: str, grid: OccupancyGrid, blind_zones: tuple[FloatArray, ...] = ()
) -> FloorMap:
    """The floor of a map: as wide and high as its cells, its blocked cells merged into
    rectangular obstacles (:func:`cell_rectangles`), the grid kept with it."""
    obstacles = tuple(
        Obstacle(
            f"map cells {index}",
            np.array(
                [
                    [grid.edge(x0), grid.edge(y0)],
                    [grid.edge(x1), grid.edge(y0)],
                    [grid.edge(x1), grid.edge(y1)],
                    [grid.edge(x0), grid.edge(y1)],
                ]
            ),
            "wall",
        )
        for index, (x0, y0, x1, y1) in enumerate(cell_rectangles(grid.blocked()), start=1)
    )
    return FloorMap(
        name=name,
        width=grid.width,
        height=grid.height,
        obstacles=obstacles,
        blind_zones=blind_zones,
        occupancy=grid,
    )


def rasterise(floor: FloorMap, resolution: float) -> OccupancyGrid:
    """The occupancy grid of a floor at ``resolution`` m per cell: a cell is occupied where its
    centre lies in an obstacle (its own grid for a floor read from a map at that resolution).

    Raises:
        ValueError: The floor's extent is no whole number of cells.
    """
    if floor.occupancy is not None and floor.occupancy.resolution == resolution:
        return floor.occupancy
    columns, rows = round(floor.width / resolution), round(floor.height / resolution)
    if not (
        math.isclose(columns * resolution, floor.width)
        and math.isclose(rows * resolution, floor.height)
    ):
        raise ValueError(
            f"a {floor.width:g} m x {floor.height:g} m floor is no whole number of "
            f"{resolution:g} m cells"
        )
    centre_x = (np.arange(columns) + 0.5) * resolution
    centre_y = (np.arange(rows) + 0.5) * resolution
    cells = np.full((rows, columns), FREE, dtype=np.int8)
    for obstacle in floor.obstacles:
        x_min, y_min = obstacle.polygon.min(axis=0)
        x_max, y_max = obstacle.polygon.max(axis=0)
        near_columns = np.flatnonzero((centre_x > x_min) & (centre_x < x_max))
        near_rows = np.flatnonzero((centre_y > y_min) & (centre_y < y_max))
        xs, ys = np.meshgrid(centre_x[near_columns], centre_y[near_rows])
        inside = shapely.contains_xy(Polygon(obstacle.polygon), xs, ys)
        block = np.ix_(near_rows, near_columns)
        cells[block] = np.where(inside, OCCUPIED, cells[block])
    return OccupancyGrid(resolution, (0.0, 0.0, 0.0), cells)


def write_ros_map(grid: OccupancyGrid, yaml_path: Path) -> Path:
    """Write a grid of free, occupied and unknown cells as map_server's ``map_saver`` does: a
    binary PGM beside ``yaml_path`` (same name) and the YAML naming it (trinary, black
    occupied, white free, grey unknown; ROS 1's free threshold of 0.196, under which the grey
    reads back as unknown, not nav2's 0.25, under which it reads back as free). Returns the
    image's path."""
    image_path = yaml_path.with_suffix(".pgm")
    shades = np.full(grid.cells.shape, 205, dtype=np.uint8)
    shades[grid.cells == FREE] = 254
    shades[grid.cells == OCCUPIED] = 0
    Image.fromarray(np.flipud(shades)).save(image_path, format="PPM")
    x, y, yaw = grid.origin
    yaml_path.write_text(
        f"image: {image_path.name}\n"
        "mode: trinary\n"
        f"resolution: {grid.resolution!r}\n"
        f"origin: [{x!r}, {y!r}, {yaw!r}]\n"
        "negate: 0\n"
        "occupied_thresh: 0.65\n"
        "free_thresh: 0.196\n",
        encoding="utf-8",
    )
    return image_path


def encode_cells(cells: NDArray[np.int8]) -> str:
    """A grid's cells as text (row 0 first, compressed, base64), for a scenario's record."""
    return base64.b64encode(zlib.compress(np.ascontiguousarray(cells).tobytes(), 9)).decode()


def decode_cells(text: str, columns: int, rows: int) -> NDArray[np.int8]:
    """The cells :func:`encode_cells` wrote.

    Raises:
        ValueError: The text is no grid of ``columns`` x ``rows`` cells.
    """
    try:
        raw = zlib.decompress(base64.b64decode(text.encode(), validate=True))
    except (ValueError, zlib.error) as error:
        raise ValueError("must be the compressed cells of the grid") from error
    if len(raw) != columns * rows:
        raise ValueError(f"holds {len(raw)} cells, not columns x rows = {columns * rows}")
    return np.frombuffer(raw, dtype=np.int8).reshape(rows, columns).copy()
