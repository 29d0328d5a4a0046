"""Episodes per second of the simulation loop itself: the random tester's episodes on one
scenario, with a controller that solves nothing (pure pursuit) or the default NMPC.

Prints episodes per CPU second and per wall second (after one warm-up episode, without
start-up), and the CPU time per episode spent outside the controller's ``control`` call: the
physics, the safety layer, contact, risk, bookkeeping and the tester. CPU time is less
disturbed than wall time by other work on a shared machine; compare two versions of the code
by running this script alternately from each (``PYTHONPATH``) and taking medians.

    python benchmarks/simulation.py --controller pursuit --episodes 100
    python benchmarks/simulation.py --controller nmpc --episodes 15

``--space`` plays uniformly random decisions in a search space instead, the way ``cem`` and
``qd`` play theirs (with ``--clear-path``, off the walls and, in the closed-loop spaces, round
the obstacles):

    python benchmarks/simulation.py --controller conservative --space route --clear-path
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import time
from typing import Any

import numpy as np

from hazardhunt.env.agv import AGVEnv
from hazardhunt.sim.simulation import Simulation
from hazardhunt.sut.protocols import Controller
from hazardhunt.testers.base import EpisodeRecorder, is_failure
from hazardhunt.testers.evaluator import EpisodeEvaluator, Plan
from hazardhunt.testers.random_sampling import RandomTester
from hazardhunt.testers.spaces import DECISION_KINDS, DecisionSpace


def controller_named(name: str) -> Controller | None:
    """The controller to drive the robot; None builds the default NMPC."""
    if name == "pursuit":
        from hazardhunt.sut.pursuit import PursuitController

        return PursuitController()
    if name == "conservative":
        from hazardhunt.benchmark.conservative import ConservativeController

        return ConservativeController()
    return None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--controller", choices=["pursuit", "conservative", "nmpc"], default="pursuit"
    )
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--scenario", default="crossing")
    parser.add_argument("--field", default="1.25m")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--profile", action="store_true", help="print cProfile's top functions")
    parser.add_argument(
        "--space",
        choices=["random", *DECISION_KINDS],
        default="random",
        help="'random': the random tester's episodes; a decision space: uniform decisions in it",
    )
    parser.add_argument("--detour", "--clear-path", action="store_true", help="with --space")
    args = parser.parse_args()

    simulation = Simulation.build(
        args.scenario, args.field, controller=controller_named(args.controller)
    )
    inside_s = [0.0]
    control = simulation.controller.control

    def timed_control(*control_args: Any) -> Any:
        started = time.process_time()
        try:
            return control(*control_args)
        finally:
            inside_s[0] += time.process_time() - started

    simulation.controller.control = timed_control  # type: ignore[method-assign]
    recorder = EpisodeRecorder(AGVEnv.wrapping(simulation), lambda record: None, is_failure)
    tester = RandomTester(args.seed)
    rng = np.random.default_rng(args.seed)
    evaluator = EpisodeEvaluator(recorder)

    def play(episodes: int) -> None:
        if args.space == "random":
            tester.explore(recorder, recorder.episodes_done + episodes)
            return
        space = DecisionSpace(args.space, args.detour)
        decisions = rng.uniform(-1.0, 1.0, (episodes, recorder.horizon, space.size))
        evaluator.evaluate([Plan(space, sequence) for sequence in decisions])

    play(1)  # warm-up: caches, lazy imports
    recorder.episodes_done, inside_s[0] = 0, 0.0
    profile = cProfile.Profile() if args.profile else None
    wall, cpu = time.perf_counter(), time.process_time()
    if profile is not None:
        profile.enable()
    play(args.episodes)
    if profile is not None:
        profile.disable()
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    if profile is not None:
        pstats.Stats(profile).sort_stats("tottime").print_stats(30)
    print(
        f"{args.controller} {args.scenario} {args.field} {args.space}"
        f"{' detour' if args.detour else ''}: {args.episodes / cpu:.2f} episodes per "
        f"CPU s, {args.episodes / wall:.2f} per wall s, "
        f"{1000 * (cpu - inside_s[0]) / args.episodes:.2f} CPU ms per episode outside the "
        "controller"
    )


if __name__ == "__main__":
    main()
