"""Draw ``warehouse.png``, a site map as a SLAM run leaves one: walls with ragged edges, racks,
round pillars, a wall at an angle, specks of noise, unknown space outside the building and in a
corner nobody mapped. 30 m x 20 m at 0.05 m per cell; seeded, so it draws the same map each time.

    python examples/site_map/draw_warehouse.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

RESOLUTION = 0.05
"""Side of a cell, in m."""

FREE, OCCUPIED, UNKNOWN = 254, 0, 205
"""The shades map_saver writes."""


def draw(seed: int = 7) -> np.ndarray:
    """The map's shades, top row first."""
    rng = np.random.default_rng(seed)
    columns, rows = 600, 400
    x = (np.arange(columns) + 0.5) * RESOLUTION
    y = (np.arange(rows)[::-1] + 0.5) * RESOLUTION  # the image's top row is the north
    xs, ys = np.meshgrid(x, y)
    shades = np.full((rows, columns), UNKNOWN, dtype=np.uint8)
    inside = (xs > 0.5) & (xs < 29.5) & (ys > 0.5) & (ys < 19.5)
    shades[inside] = FREE
    wall = inside & ~((xs > 0.7) & (xs < 29.3) & (ys > 0.7) & (ys < 19.3))
    # Racks: two rows west and east of the cross aisle.
    racks = np.zeros_like(inside)
    for x0 in (3.0, 9.0, 17.0, 23.0):
        for y0, y1 in ((2.0, 6.5), (13.5, 18.0)):
            racks |= (xs > x0) & (xs < x0 + 4.0) & (ys > y0) & (ys < y1)
    pillars = np.zeros_like(inside)
    for px in (7.5, 15.0, 22.5):
        for py in (8.0, 12.0):
            pillars |= np.hypot(xs - px, ys - py) < 0.2
    # A wall at 30 degrees closing off the north-east corner.
    along = (xs - 25.0) * np.sin(np.radians(30)) + (ys - 19.3) * np.cos(np.radians(30))
    angled = (np.abs(along) < 0.1) & (xs > 25.0) & inside
    occupied = wall | racks | pillars | angled
    # Ragged edges: a free cell beside an occupied one reads as occupied now and then.
    beside = np.zeros_like(occupied)
    beside[1:, :] |= occupied[:-1, :]
    beside[:-1, :] |= occupied[1:, :]
    beside[:, 1:] |= occupied[:, :-1]
    beside[:, :-1] |= occupied[:, 1:]
    ragged = beside & ~occupied & inside & (rng.random(occupied.shape) < 0.3)
    specks = inside & (rng.random(occupied.shape) < 0.0005)
    shades[occupied | ragged | specks] = OCCUPIED
    # Behind the angled wall nobody drove: unknown.
    shades[inside & (along > 0.1) & (xs > 25.0)] = UNKNOWN
    return shades


def main() -> None:
    path = Path(__file__).with_name("warehouse.png")
    Image.fromarray(draw()).save(path)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
