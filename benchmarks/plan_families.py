"""How often simple families of human plans expose a mutant: an exploration, not a tester.

For each mutant x scenario (behind ``--field``), plays ``--episodes`` episodes of each family,
drawn with seed 0, and prints the failures and the episode of the first. The families:

- ``aim-uniform`` / ``route-uniform``: every decision uniform in [-1, 1], aimed at the robot or
  at a point of its route (:mod:`hazardhunt.testers.spaces`);
- ``aim-const`` / ``route-const``: one uniform decision held throughout;
- ``aim-switch-fast`` / ``route-switch``: one decision, then another from a uniform time on
  (the aimed one at top speed);
- ``route-then-aim``: a route decision, then an aimed one at top speed from a uniform time on;
- ``ambush``: wait beside the route (0.9-3 m to a side) until the robot is within a uniform
  1-5 m, then go for a uniform bearing around it;
- ``ambush-late``: the same, waiting in the last quarter of the route (where a controller
  switches to docking, say).

Every family walks round walls and shelves (``detour``).

    python benchmarks/plan_families.py --families ambush route-then-aim \
        --mutants DockingMode StaleTrack --scenarios crossing overtaking head-on --episodes 100
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from hazardhunt.benchmark.conservative import MUTANTS, ConservativeController
from hazardhunt.benchmark.held_out import HELD_OUT_MUTANTS
from hazardhunt.sim.simulation import EpisodeResult, Simulation
from hazardhunt.testers.clear_path import play_decisions
from hazardhunt.testers.spaces import DecisionSpace

AIM, ROUTE = DecisionSpace("aim", detour=True), DecisionSpace("route", detour=True)
FAMILIES = (
    "aim-uniform",
    "route-uniform",
    "aim-const",
    "route-const",
    "aim-switch-fast",
    "route-switch",
    "route-then-aim",
    "ambush",
    "ambush-late",
)
Steer = Callable[[Simulation, int], NDArray[Any]]


def steering(family: str, rng: np.random.Generator, horizon: int) -> Steer:
    """The action of the family's plan drawn with ``rng`` at decision ``step``."""
    switch = int(rng.integers(1, horizon))
    first, second = rng.uniform(-1.0, 1.0, 3), rng.uniform(-1.0, 1.0, 3)
    every = rng.uniform(-1.0, 1.0, (horizon, 3))
    if family.startswith("ambush"):
        along = rng.uniform(0.5 if family == "ambush-late" else -1.0, 1.0)
        offset = rng.choice([-1, 1]) * rng.uniform(0.3, 1.0)
        trigger, bearing = rng.uniform(1.0, 5.0), rng.uniform(-1.0, 1.0)

        def ambush(sim: Simulation, step: int) -> NDArray[Any]:
            gap = np.hypot(*(np.asarray(sim.human_position) - (sim.robot.x, sim.robot.y)))
            if gap < trigger:
                return AIM.action(sim, np.array([1.0, bearing, -1.0]))
            return ROUTE.action(sim, np.array([1.0, along, offset]))

        return ambush
    space = AIM if family.startswith("aim") else ROUTE
    if family.endswith("uniform"):
        return lambda sim, step: space.action(sim, every[step])
    if family.endswith("const"):
        return lambda sim, step: space.action(sim, first)
    fast = family.endswith("fast") or family == "route-then-aim"
    later = np.array([1.0, *second[1:]]) if fast else second
    if family == "route-then-aim":
        return lambda sim, step: (ROUTE if step < switch else AIM).action(
            sim, first if step < switch else later
        )
    return lambda sim, step: space.action(sim, first if step < switch else later)


def play(sim: Simulation, steer: Steer) -> EpisodeResult:
    steps = iter(range(sim.horizon))
    return play_decisions(
        sim, [np.zeros(3)] * sim.horizon, lambda s, decision: steer(s, next(steps)), False
    )


def main() -> None:
    suts = {c.__name__: c for c in (ConservativeController, *MUTANTS, *HELD_OUT_MUTANTS)}
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--families", nargs="+", default=list(FAMILIES), choices=FAMILIES)
    parser.add_argument("--mutants", nargs="+", default=["DockingMode"], choices=list(suts))
    parser.add_argument("--scenarios", nargs="+", default=["crossing", "overtaking", "head-on"])
    parser.add_argument("--field", default="1.25m")
    parser.add_argument("--episodes", type=int, default=100)
    args = parser.parse_args()
    for mutant in args.mutants:
        for scenario in args.scenarios:
            sim = Simulation.build(scenario, args.field, controller=suts[mutant]())
            cells = []
            for family in args.families:
                rng = np.random.default_rng(0)
                outcomes = [
                    play(sim, steering(family, rng, sim.horizon)).outcome
                    for _ in range(args.episodes)
                ]
                fails = [i for i, outcome in enumerate(outcomes) if outcome == "failure"]
                cells.append(f"{family}={len(fails)}({fails[0] if fails else '-'})")
            print(mutant, scenario, " ".join(cells), flush=True)


if __name__ == "__main__":
    main()
