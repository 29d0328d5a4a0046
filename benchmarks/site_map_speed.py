"""Episodes per second on a floor read from a ROS site map against the built-in polygons.

Plays the same seeded uniform random actions with the built-in NMPC on three floors and prints
one JSON line per floor: how long loading the scenario and planning the route take, the
episodes per second after that (the best of ``--repeats`` rounds that take the floors in turn,
so that a busy machine slows all of them alike), how many obstacles the floor holds, and
whether the episodes' outcomes equal those on the built-in floor.

- ``polygons``: the built-in crossing scenario (``shopfloor.toml``, 12 polygons);
- ``shopfloor map``: the same scenario on ``shopfloor.yaml`` (the same floor as a 0.1 m map);
- ``warehouse map``: ``examples/site_map/warehouse_crossing.toml``, a 30 m x 20 m map at 0.05 m
  drawn as a SLAM run leaves one (ragged walls, pillars, specks, unknown space).

    python benchmarks/site_map_speed.py --episodes 20 --repeats 3
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from hazardhunt.sim.simulation import Simulation
from hazardhunt.world.scenario import builtin_scenario_path, load_scenario

WAREHOUSE = Path(__file__).resolve().parent.parent / "examples" / "site_map"


def crossing_on_map(directory: Path) -> Path:
    """The built-in crossing scenario with its map replaced by the shop floor's ROS map."""
    crossing = builtin_scenario_path("crossing")
    text = crossing.read_text(encoding="utf-8").replace(
        'map = "shopfloor.toml"', f'map = "{crossing.parent / "shopfloor.yaml"}"'
    )
    path = directory / "crossing-on-map.toml"
    path.write_text(text, encoding="utf-8")
    return path


def measure(simulation: Simulation, episodes: int, seed: int) -> tuple[float, list[str]]:
    """Episodes per second and outcomes of ``episodes`` random episodes."""
    rng = np.random.default_rng(seed)
    outcomes = []
    started = time.perf_counter()
    for _ in range(episodes):
        result = simulation.simulate(rng.uniform(-1.0, 1.0, (simulation.horizon, 2)), False)
        outcomes.append(str(result.outcome))
    return episodes / (time.perf_counter() - started), outcomes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as directory:
        floors = {
            "polygons": "crossing",
            "shopfloor map": str(crossing_on_map(Path(directory))),
            "warehouse map": str(WAREHOUSE / "warehouse_crossing.toml"),
        }
        rows: dict[str, dict[str, object]] = {}
        simulations = {}
        for name, scenario in floors.items():
            started = time.perf_counter()
            loaded = load_scenario(scenario)
            simulations[name] = Simulation.build(loaded, "1.25m")
            setup = time.perf_counter() - started
            rows[name] = {"obstacles": len(loaded.floor.obstacles), "setup_s": round(setup, 3)}
        speeds: dict[str, list[float]] = {name: [] for name in floors}
        outcomes: dict[str, list[str]] = {}
        for _ in range(args.repeats):
            for name, simulation in simulations.items():
                speed, outcomes[name] = measure(simulation, args.episodes, args.seed)
                speeds[name].append(speed)
        for name in floors:
            same = outcomes[name] == outcomes["polygons"] if name != "warehouse map" else None
            row = {"floor": name, **rows[name], "episodes_per_s": round(max(speeds[name]), 2)}
            print(json.dumps({**row, "same_outcomes": same}), flush=True)


if __name__ == "__main__":
    main()
