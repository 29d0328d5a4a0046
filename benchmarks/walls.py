"""How often the human walks into a wall: the share of its moving decisions in which a wall or
shelf blocks it, for the ways hazardhunt's testers choose actions.

A decision counts as moving when its speed is above 0.3 m/s, and as blocked when the human
covers less than half the distance its speed asks for (walls and shelves stop it or let it
slide, SPEC 2). Compared, per built-in scenario and over the same number of episodes:

- ``gaussian``: open-loop sequences from ``cem``'s first Gaussian (mean 0, spread 0.6, clipped);
- ``uniform``: open-loop sequences drawn uniformly (``qd``'s map-elites start);
- ``random``: the ``random`` tester, which draws each action until its path is clear;
- ``gaussian, clear path``: the first as ``cem`` plays it with ``clear_path=true``.

The robot runs the conservative controller (it solves nothing, so this takes seconds).

    python benchmarks/walls.py --episodes 60
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from hazardhunt.benchmark.conservative import ConservativeController
from hazardhunt.sim.simulation import Simulation
from hazardhunt.testers.clear_path import clear_action
from hazardhunt.testers.random_sampling import RandomTester
from hazardhunt.world.scenario import BUILTIN_SCENARIOS

MOVING = 0.3
"""Speed (m/s) above which a decision counts."""

Chooser = Callable[[Simulation, NDArray[np.float64]], NDArray[np.floating]]


def blocked_share(sim: Simulation, episodes: int, seed: int, choose: Chooser) -> float:
    """The share of moving decisions in which the human covered less than half its way."""
    rng = np.random.default_rng(seed)
    moving = blocked = 0
    for _ in range(episodes):
        sequence = np.clip(0.6 * rng.standard_normal((sim.horizon, 2)), -1.0, 1.0)
        uniform = rng.uniform(-1.0, 1.0, (sim.horizon, 2))
        sim.reset()
        for k in range(sim.horizon):
            action = choose(sim, np.stack([sequence[k], uniform[k]]))
            speed, _ = sim.decode_action(action)
            start = sim.human_position.copy()
            report = sim.decide(action)
            if speed > MOVING:
                moving += 1
                covered = float(np.linalg.norm(sim.human_position - start))
                blocked += covered < 0.5 * speed * sim.decision_period
            if report.outcome is not None:
                break
    return blocked / max(moving, 1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=60, help="episodes per scenario and way")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    random_tester = RandomTester(seed=args.seed)
    ways: dict[str, Chooser] = {
        "gaussian": lambda sim, drawn: drawn[0],
        "uniform": lambda sim, drawn: drawn[1],
        "random": lambda sim, drawn: random_tester.choose(sim),
        "gaussian, clear path": lambda sim, drawn: clear_action(sim, drawn[0]),
    }
    print(f"{'scenario':12}" + "".join(f"{way:>22}" for way in ways))
    for scenario in BUILTIN_SCENARIOS:
        sim = Simulation.build(scenario, "none", controller=ConservativeController())
        shares = [blocked_share(sim, args.episodes, args.seed, way) for way in ways.values()]
        print(f"{scenario:12}" + "".join(f"{share:>21.1%} " for share in shares))


if __name__ == "__main__":
    main()
