"""Record the trajectories that the speed work must leave unchanged.

Replays the recorded failures of ``tests/spec/recorded_failures.json`` and a few episodes of
seeded random actions on every built-in scenario and field setting, and stores per episode the
actions and, at every control instant, the robot's and the human's state.
``tests/sut/test_reference_trajectories.py`` checks today's code against the files:

- ``tests/sut/reference_trajectories.npz``: the NMPC with today's settings, recorded by this
  script (``python scripts/record_reference_trajectories.py``) when the warm-started solves'
  barrier decrease and bound push were tuned;
- ``tests/sut/reference_trajectories_previous_tuning.npz``: the NMPC with the warm-start
  settings before that tuning (``PREVIOUS_TUNING``), recorded with hazardhunt before its speed
  optimisations (commit d2cb541, whose ``episode`` played the same actions through the
  Gymnasium env's step loop).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from hazardhunt.sim.simulation import Simulation
from hazardhunt.sut.nmpc import NMPCController, NMPCParams

COLUMNS = ("time", "robot_x", "robot_y", "robot_heading", "robot_speed", "human_x", "human_y")
"""Trajectory columns stored, at every control instant."""
RANDOM_EPISODES = [
    (scenario, field, seed)
    for scenario in ("crossing", "head-on", "overtaking")
    for field, seed in (("none", 1), ("1.25m", 2), ("2m", 3))
]
"""Episodes of random actions: scenario, field and the seed of the actions."""
PREVIOUS_TUNING = NMPCParams(barrier_decrease_power=1.5, bound_push=1e-6)
"""The NMPC's settings before its warm-started solves were tuned."""


def episode(
    scenario: str,
    field: str,
    decision_period: float,
    actions: np.ndarray,
    controller: NMPCController | None = None,
) -> np.ndarray:
    """The trajectory of one episode driven by ``actions`` (the first ones until it ends), by
    ``controller`` or else the default NMPC."""
    simulation = Simulation.build(
        scenario, field, decision_period=decision_period, controller=controller
    )
    rows = simulation.simulate(np.asarray(actions, dtype=np.float32)).trajectory or ()
    return np.array([[getattr(row, c) for c in COLUMNS] for row in rows], dtype=np.float64)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("tests/sut/reference_trajectories.npz"))
    args = parser.parse_args()
    recorded = json.loads(Path("tests/spec/recorded_failures.json").read_text())["examples"]
    controller = NMPCController()
    arrays: dict[str, np.ndarray] = {}
    index = []
    for name, example in sorted(recorded.items()):
        key = f"recorded:{name}"
        actions = np.asarray(example["actions"], dtype=np.float32)
        setting = (example["scenario"], example["field"], example["decision_period"])
        arrays[f"{key}:actions"] = actions
        arrays[f"{key}:trajectory"] = episode(*setting, actions, controller)
        index.append([key, *setting])
    for scenario, field, seed in RANDOM_EPISODES:
        key = f"random:{scenario}:{field}:{seed}"
        actions = np.random.default_rng(seed).uniform(-1, 1, (40, 2)).astype(np.float32)
        arrays[f"{key}:actions"] = actions
        arrays[f"{key}:trajectory"] = episode(scenario, field, 2.0, actions, controller)
        index.append([key, scenario, field, 2.0])
    arrays["index"] = np.array(json.dumps({"columns": COLUMNS, "episodes": index}))
    np.savez_compressed(args.out, **arrays)
    rows = sum(len(v) for k, v in arrays.items() if k.endswith(":trajectory"))
    print(f"{len(index)} episodes, {rows} control instants, written to {args.out}")


if __name__ == "__main__":
    main()
