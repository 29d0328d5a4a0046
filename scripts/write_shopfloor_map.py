"""Write the built-in shop floor as a ROS map: ``shopfloor.yaml`` and ``shopfloor.pgm``.

The polygons of ``src/hazardhunt/scenarios/shopfloor.toml`` rasterised at 0.1 m per cell (every
wall and shelf edge lies on a cell boundary, so the map holds the same obstacles), written as
map_server's ``map_saver`` writes a map, beside the polygons (``scenarios/`` is the package's
folder). ``tests/world/test_rosmap.py`` checks that the files are what this script
writes and that the crossing scenario plays the same episodes on either floor.

    python scripts/write_shopfloor_map.py
"""

from __future__ import annotations

import argparse
from pathlib import Path

from hazardhunt.world.rosmap import rasterise, write_ros_map
from hazardhunt.world.scenario import load_scenario

RESOLUTION = 0.1
"""Side of a cell of the shop floor's map, in m."""

SCENARIOS = Path(__file__).resolve().parent.parent / "src" / "hazardhunt" / "scenarios"
"""Where the built-in scenario files are."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.parse_args()
    grid = rasterise(load_scenario("crossing").floor, RESOLUTION)
    image = write_ros_map(grid, SCENARIOS / "shopfloor.yaml")
    print(f"wrote {SCENARIOS / 'shopfloor.yaml'} and {image.name}")


if __name__ == "__main__":
    main()
