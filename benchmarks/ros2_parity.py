"""The example pure-pursuit ROS 2 node through the bridge against the in-process controller it
ports (``hazardhunt.sut.pursuit:PursuitController``): the same random episodes played by both,
whether every episode's outcome, contact face, length and trajectory are equal, the episodes per
second of each, and the bridge's lock-step round trip (publishing an instant's messages to the
node's ``/cmd_vel``, in ms). The node's start (its first episode) is not timed. Prints one JSON
line.

    python benchmarks/ros2_parity.py --episodes 20 --seed 0 [--mode timer] [--reset restart]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shlex
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from hazardhunt.sim.simulation import Simulation
from hazardhunt.sut.pursuit import PursuitController
from hazardhunt.sut.ros2.bridge import Ros2Controller

NODE = Path(__file__).parents[1] / "examples" / "ros2" / "pure_pursuit_node.py"


def play(controller: Any, actions: list[np.ndarray]) -> tuple[list[Any], float, list[float]]:
    """Each episode's outcome, face, length and trajectory (its solve times taken out), the
    wall time of all but a warm-up episode, and every command's solve time."""
    simulation = Simulation.build("crossing", "none", controller=controller)
    simulation.simulate(actions[0])  # warm-up: the node starts here
    episodes, solve_times = [], []
    started = time.perf_counter()
    for episode_actions in actions:
        summary = simulation.simulate(episode_actions).summary
        samples = simulation.trajectory()
        solve_times += [sample.solve_time_s for sample in samples[:-1]]
        trajectory = [dataclasses.replace(s, solve_time_s=0.0) for s in samples]
        episodes.append((summary.outcome, summary.contact_face, summary.sim_time, trajectory))
    return episodes, time.perf_counter() - started, solve_times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--mode", choices=["answer", "timer"], default="answer")
    parser.add_argument("--reset", choices=["messages", "service", "restart"], default="messages")
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    actions = [rng.uniform(-1, 1, size=(15, 2)).astype(np.float32) for _ in range(args.episodes)]
    local, local_time, _ = play(PursuitController(), actions)
    command = shlex.join([sys.executable, str(NODE), "--ros-args", "-p", f"mode:={args.mode}"])
    bridge = Ros2Controller(command=command, reset=args.reset)
    try:
        ros, ros_time, round_trips = play(bridge, actions)
    finally:
        bridge.close()
    milliseconds = np.array(round_trips) * 1e3
    print(
        json.dumps(
            {
                "episodes": args.episodes,
                "seed": args.seed,
                "mode": args.mode,
                "reset": args.reset,
                "identical": ros == local,
                "same_outcomes": [e[0] for e in ros] == [e[0] for e in local],
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
