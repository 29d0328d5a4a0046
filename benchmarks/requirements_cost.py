"""What judging every episode by requirements costs: episodes per CPU second of the same random
episodes with and without hazardhunt's four library requirements, in alternating rounds of one
process (medians and their ratio), and the monitor's own CPU time per episode.

    python benchmarks/requirements_cost.py --controller nmpc --episodes 20 --rounds 5 \\
        --out benchmarks/results/requirements_cost.json
    python benchmarks/requirements_cost.py --controller pursuit --episodes 100
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from hazardhunt.sim.simulation import Simulation
from hazardhunt.spec.requirements import episode_signals, judged, requirements_of
from hazardhunt.sut.pursuit import PursuitController

LIBRARY_NAMES = ["separation", "slow-near-people", "no-restart-in-field", "reach-goal"]


def play(simulation: Simulation, episodes: int, seed: int) -> float:
    """CPU seconds for ``episodes`` random episodes (the same ones for the same seed)."""
    rng = np.random.default_rng(seed)
    decisions = simulation.horizon
    started = time.process_time()
    for _ in range(episodes):
        simulation.simulate(rng.uniform(-1.0, 1.0, (decisions, 2)), keep_trajectory=False)
    return time.process_time() - started


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--controller", choices=["nmpc", "pursuit"], default="nmpc")
    parser.add_argument("--scenario", default="crossing")
    parser.add_argument("--field", default="2m")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    controller = PursuitController() if args.controller == "pursuit" else None
    simulation = Simulation.build(args.scenario, args.field, controller=controller)
    requirements = requirements_of(LIBRARY_NAMES, simulation.controller.control_period)
    play(simulation, 1, seed=99)  # warm-up
    rates: dict[str, list[float]] = {"without": [], "with": []}
    for round_ in range(args.rounds):
        for name, judged_by in (("without", ()), ("with", requirements)):
            simulation.requirements = judged_by
            seconds = play(simulation, args.episodes, seed=round_)
            rates[name].append(args.episodes / seconds)
    # The monitor alone, on the trajectory of the last episode.
    simulation.requirements = ()
    trajectory = simulation.simulate(np.zeros((simulation.horizon, 2))).trajectory or ()
    started = time.process_time()
    for _ in range(50):
        signals = episode_signals(trajectory, 7.5, 0.0, (0.0, 0.0))
        judged(requirements, signals)
    monitor_ms = (time.process_time() - started) / 50 * 1000.0
    without, with_ = statistics.median(rates["without"]), statistics.median(rates["with"])
    result = {
        "command": " ".join([Path(sys.executable).name, *sys.argv]),
        "date": datetime.now(UTC).isoformat(),
        "controller": args.controller,
        "scenario": args.scenario,
        "field": args.field,
        "requirements": LIBRARY_NAMES,
        "episodes_per_round": args.episodes,
        "rounds": args.rounds,
        "episodes_per_cpu_s_without": rates["without"],
        "episodes_per_cpu_s_with": rates["with"],
        "median_without": without,
        "median_with": with_,
        "ratio_with_over_without": with_ / without,
        "monitor_cpu_ms_per_episode": monitor_ms,
        "samples_per_episode": len(trajectory),
    }
    print(
        f"{args.controller}: {without:.1f} episodes/CPU s without requirements, {with_:.1f} "
        f"with {len(requirements)} (ratio {with_ / without:.3f}); the monitor alone "
        f"{monitor_ms:.2f} ms per episode of {len(trajectory)} samples"
    )
    if args.out:
        args.out.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
