"""What an episode-level searcher costs besides the episodes it plays.

Runs a tester (``portfolio`` by default) against a controller that solves no optimisation (the
conservative controller of the mutation benchmark, where the searcher rather than the system
under test is the cost) and splits the CPU time of its search into playing episodes (the
evaluator) and everything else: the samplers' ask and tell, the portfolio's classification of
failures, the recording of each episode. Each tester first plays a warm-up run, untimed, so that
one-time costs (importing pyribs and torch, numba compiling pyribs' helpers on a machine's
first run: ``benchmarks/startup.py``) are left out. Prints the episodes per CPU second and the
share of the search's own bookkeeping, per tester, in one process (so that the ratios
compare). The random tester plays through the recorder, not the evaluator: this does not
measure it.

    python benchmarks/search_overhead.py --testers portfolio cem qd --episodes 600
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

from hazardhunt.campaign.config import PluginSpec, RunConfig
from hazardhunt.campaign.simulations import simulation_of
from hazardhunt.env.agv import AGVEnv
from hazardhunt.testers import make_tester
from hazardhunt.testers.base import EpisodeRecorder
from hazardhunt.testers.evaluator import EpisodeEvaluator

CONTROLLER = "hazardhunt.benchmark.conservative:ConservativeController"


def measure(tester: str, params: dict[str, Any], args: argparse.Namespace) -> dict[str, Any]:
    config = RunConfig(
        scenario=args.scenario,
        field=args.field,
        tester=tester,
        tester_params=params,
        seed=args.seed,
        episodes=args.episodes,
        controller=PluginSpec(path=CONTROLLER),
    )
    recorder = EpisodeRecorder(AGVEnv.wrapping(simulation_of(config)), lambda record: None)
    playing = [0.0]
    evaluate = EpisodeEvaluator.evaluate

    def timed(self: EpisodeEvaluator, plans: Any) -> Any:
        started = time.process_time()
        try:
            return evaluate(self, plans)
        finally:
            playing[0] += time.process_time() - started

    EpisodeEvaluator.evaluate = timed  # type: ignore[method-assign]
    try:
        started = time.process_time()
        make_tester(tester, args.seed, params).explore(recorder, args.episodes)
        total = time.process_time() - started
    finally:
        EpisodeEvaluator.evaluate = evaluate  # type: ignore[method-assign]
    own = total - playing[0]
    return {
        "tester": tester,
        "episodes": recorder.episodes_done,
        "episodes_per_cpu_s": recorder.episodes_done / total,
        "bookkeeping_share": own / total,
        "bookkeeping_ms_per_episode": 1000.0 * own / recorder.episodes_done,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--testers", nargs="+", default=["portfolio"])
    parser.add_argument("--episodes", type=int, default=600)
    parser.add_argument("--scenario", default="crossing")
    parser.add_argument("--field", default="none")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--warm-up", type=int, default=300, help="untimed episodes first")
    parser.add_argument("--out", help="write the rows as JSON here")
    args = parser.parse_args()
    rows = []
    for tester in args.testers:
        measure(tester, {}, argparse.Namespace(**{**vars(args), "episodes": args.warm_up}))
        row = measure(tester, {}, args)
        rows.append(row)
        print(
            f"{tester}: {row['episodes_per_cpu_s']:.1f} episodes per CPU s, bookkeeping "
            f"{100 * row['bookkeeping_share']:.1f} % "
            f"({row['bookkeeping_ms_per_episode']:.2f} ms per episode)",
            flush=True,
        )
    if args.out:
        with open(args.out, "w") as file:
            json.dump({"args": vars(args), "rows": rows}, file, indent=2)
            file.write("\n")


if __name__ == "__main__":
    main()
