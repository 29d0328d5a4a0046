"""An example ROS 2 node through the bridge against the in-process controller it ports: the
same random episodes played by both, whether every episode's outcome, contact face, length and
trajectory are equal, the episodes per second of each, and the bridge's lock-step round trip
(publishing an instant's messages to the node's ``/cmd_vel``, in ms). Prints one JSON line.

- ``--node pursuit``: ``examples/ros2/pure_pursuit_node.py`` against
  ``hazardhunt.sut.pursuit:PursuitController``, on the crossing scenario;
- ``--node nmpc``: ``examples/ros2/nmpc_node.py`` against the built-in NMPC, on the crossing
  scenario on the shop floor's ROS map (``scenarios/shopfloor.yaml``, published at its 0.1 m),
  so that the obstacles the node reads from ``/map`` are the in-process NMPC's, in its order.

The trajectory compared is the physical one at each control instant: time, the human's and the
robot's states, visibility, stop, field and clearance (what a controller reports about itself,
its status, plans and solve times, does not travel over ``/cmd_vel``). ``max_difference`` is
the largest difference of any of those numbers between the two, over all episodes. The node's
start (a warm-up episode) is not timed.

    python benchmarks/ros2_parity.py --episodes 20 --seed 0 [--node nmpc] [--mode timer]
        [--reset restart]
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from hazardhunt.sim.simulation import Simulation
from hazardhunt.sut.nmpc import NMPCController
from hazardhunt.sut.pursuit import PursuitController
from hazardhunt.sut.ros2.bridge import Ros2Controller

ROOT = Path(__file__).parents[1]
NODES = {
    "pursuit": ROOT / "examples" / "ros2" / "pure_pursuit_node.py",
    "nmpc": ROOT / "examples" / "ros2" / "nmpc_node.py",
}
SCENARIOS = ROOT / "src" / "hazardhunt" / "scenarios"
PHYSICAL = ("time", "human_x", "human_y", "human_heading", "robot_x", "robot_y", "robot_heading",
            "robot_speed", "robot_yaw_rate", "human_visible", "emergency_stop", "human_in_field",
            "clearance")  # fmt: skip
"""The trajectory's fields that the controller does not report about itself."""


def crossing_on_map(folder: Path) -> Path:
    """The crossing scenario with the shop floor's ROS map for its map."""
    text = (SCENARIOS / "crossing.toml").read_text()
    path = folder / "crossing-on-map.toml"
    path.write_text(text.replace('"shopfloor.toml"', json.dumps(str(SCENARIOS / "shopfloor.yaml"))))
    return path


def play(
    scenario: str, controller: Any, actions: list[np.ndarray]
) -> tuple[list[Any], float, list[float]]:
    """Each episode's outcome, face, length and physical trajectory, the wall time of all but a
    warm-up episode, and every command's solve time (the round trip, through the bridge)."""
    simulation = Simulation.build(scenario, "none", controller=controller)
    simulation.simulate(actions[0])  # warm-up: the node starts here
    episodes, solve_times = [], []
    started = time.perf_counter()
    for episode_actions in actions:
        summary = simulation.simulate(episode_actions).summary
        samples = simulation.trajectory()
        solve_times += [sample.solve_time_s for sample in samples[:-1]]
        trajectory = [tuple(getattr(s, name) for name in PHYSICAL) for s in samples]
        episodes.append((summary.outcome, summary.contact_face, summary.sim_time, trajectory))
    return episodes, time.perf_counter() - started, solve_times


def largest_difference(ros: list[Any], local: list[Any]) -> float | None:
    """The largest difference of a trajectory number between the two (None: they do not
    line up, an episode of another length)."""
    largest = 0.0
    for (_, _, _, a), (_, _, _, b) in zip(ros, local, strict=True):
        if len(a) != len(b):
            return None
        difference = np.abs(np.array(a, dtype=np.float64) - np.array(b, dtype=np.float64))
        largest = max(largest, float(difference.max(initial=0.0)))
    return largest


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--node", choices=sorted(NODES), default="pursuit")
    parser.add_argument("--mode", choices=["answer", "timer"], default="answer")
    parser.add_argument("--reset", choices=["messages", "service", "restart"], default="messages")
    args = parser.parse_args()
    if args.node == "nmpc" and args.mode == "timer":
        parser.error("the NMPC node answers each odometry message (no --mode timer)")
    rng = np.random.default_rng(args.seed)
    actions = [rng.uniform(-1, 1, size=(15, 2)).astype(np.float32) for _ in range(args.episodes)]
    with tempfile.TemporaryDirectory() as folder:
        if args.node == "nmpc":
            scenario, resolution = str(crossing_on_map(Path(folder))), 0.1
            local_controller: Any = NMPCController()
            command = shlex.join([sys.executable, str(NODES["nmpc"])])
        else:
            scenario, resolution, local_controller = "crossing", 0.05, PursuitController()
            command = shlex.join(
                [sys.executable, str(NODES["pursuit"]), "--ros-args", "-p", f"mode:={args.mode}"]
            )
        local, local_time, _ = play(scenario, local_controller, actions)
        bridge = Ros2Controller(command=command, reset=args.reset, map_resolution=resolution)
        try:
            ros, ros_time, round_trips = play(scenario, bridge, actions)
        finally:
            bridge.close()
    milliseconds = np.array(round_trips) * 1e3
    print(
        json.dumps(
            {
                "node": args.node,
                "episodes": args.episodes,
                "seed": args.seed,
                "mode": args.mode,
                "reset": args.reset,
                "identical": ros == local,
                "same_outcomes": [e[:2] for e in ros] == [e[:2] for e in local],
                "max_difference": largest_difference(ros, local),
                "in_process_episodes_per_s": round(args.episodes / local_time, 2),
                "bridge_episodes_per_s": round(args.episodes / ros_time, 2),
                "control_instants": len(round_trips),
                "round_trip_ms_median": round(float(np.median(milliseconds)), 3),
                "round_trip_ms_p99": round(float(np.percentile(milliseconds, 99)), 3),
            }
        )
    )


if __name__ == "__main__":
    main()
