"""Off-the-shelf search methods against hazardhunt's testers on a requirement's robustness.

The problem of ``peers.py`` with another score: an episode (the human's open-loop actions) is
judged by a requirement in signal temporal logic (a library name or ``FILE.toml:NAME``), and
a violation is what every method hunts. The peers maximise a score built like the maximum
risk they maximise in ``peers.py``: ``1 / (1 + r)`` (at most 1) while the episode keeps the
requirement by a robustness ``r``, ``100 (1 - r)`` (at least 100) once it violates it by
``-r``; so VerifAI's threshold of -50 still parts counterexamples from the rest.
hazardhunt's testers run ``hazardhunt run --requirement REQ --search-on NAME``. For each
method and seed: violations, the first violating episode, the distinct violation classes
(the requirement and the signals that decided it) and the lowest robustness.

Run with the peers' venv (README.md here), which also needs ``rtamt``:

    /work/peers-venv/bin/python benchmarks/peers/requirement_peers.py --case crossing:2m \\
        --requirement benchmarks/requirements_hard.toml:near-while-moving --episodes 200 \\
        --seeds 0 1 2 --testers cem portfolio --hazardhunt .venv/bin/hazardhunt \\
        --out benchmarks/results/requirement_peers_crossing_2m.json
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
from evaluation import Case, Evaluation, horizon
from searchers import METHODS, Points, search

from hazardhunt.sim import Simulation
from hazardhunt.spec.descriptors import describe
from hazardhunt.spec.requirements import requirements_of
from hazardhunt.testers.objective import RequirementRule, violation_class

REPOSITORY = Path(__file__).resolve().parents[2]
VIOLATION_SCORE = 100.0
"""The peers' score of a violation is this x the search objective's (``1 - r``), above any
kept episode's (``1 / (1 + r)``)."""


@dataclass(frozen=True)
class Judged:
    """One played episode: what the peers learn from, and the requirement's verdict."""

    evaluation: Evaluation
    robustness: float
    violation: str | None
    """The violation's class (``near-while-moving/clearance+robot_speed``), None if kept."""


_simulations: dict[tuple[Case, str], Simulation] = {}


def judge(case: Case, requirement: str, points: Points) -> list[Judged]:
    """Play each row of ``points`` from the case's start and judge it by ``requirement``."""
    key = (case, requirement)
    if key not in _simulations:
        simulation = Simulation.build(case.scenario, case.field)
        period = simulation.controller.control_period
        simulation.requirements = requirements_of([requirement], period)
        _simulations[key] = simulation
    simulation = _simulations[key]
    rule = RequirementRule(simulation.requirements[0].name)
    judged = []
    for point in points:
        actions = np.clip(np.asarray(point, dtype=np.float64), -1.0, 1.0).reshape(-1, 2)
        result = simulation.simulate(actions, keep_trajectory=False)
        violated = rule.hit(result)
        score = rule.score(result) * (VIOLATION_SCORE if violated else 1.0)
        bearing, robot_speed = describe(result.summary)[:2]
        evaluation = Evaluation(score, result.summary.outcome, bearing, robot_speed, None)
        robustness = result.verdicts[rule.name].robustness
        violation = violation_class(rule.name, result) if violated else None
        judged.append(Judged(evaluation, robustness, violation))
    return judged


def peer_row(method: str, case: Case, requirement: str, seed: int, episodes: int) -> dict[str, Any]:
    """A peer's run: its budget spent on the requirement's score."""
    started = time.perf_counter()
    played: list[Judged] = []

    def evaluate(points: Points) -> list[Evaluation]:
        judged = judge(case, requirement, points)
        played.extend(judged)
        return [j.evaluation for j in judged]

    search(METHODS[method](2 * horizon(case), seed), evaluate, episodes)
    violations = [j.violation for j in played if j.violation is not None]
    return {
        "method": method,
        "kind": "peer",
        "seed": seed,
        "episodes": len(played),
        "violations": len(violations),
        "first_violation_episode": next(
            (i for i, j in enumerate(played) if j.violation is not None), None
        ),
        "classes": sorted(set(violations)),
        "min_robustness": min(j.robustness for j in played),
        "wall_time_s": time.perf_counter() - started,
    }


def tester_row(
    tester: str, case: Case, requirement: str, seed: int, episodes: int, hazardhunt: Path
) -> dict[str, Any]:
    """A hazardhunt tester's run searching on the requirement, from its summary.json."""
    name = requirement.rpartition(":")[2]
    with tempfile.TemporaryDirectory(prefix="hazardhunt-requirement-peers-") as scratch:
        out = Path(scratch) / "run"
        command = [
            str(hazardhunt), "run", f"--scenario={case.scenario}", f"--field={case.field}",
            f"--tester={tester}", f"--episodes={episodes}", f"--seed={seed}", f"--out={out}",
            f"--requirement={requirement}", f"--search-on={name}", "--json",
        ]  # fmt: skip
        path = os.pathsep.join(
            filter(None, [str(REPOSITORY / "src"), os.environ.get("PYTHONPATH")])
        )
        done = subprocess.run(
            command, env=os.environ | {"PYTHONPATH": path}, capture_output=True, text=True
        )
        if done.returncode != 0:
            raise RuntimeError(f"{' '.join(command)} exited with {done.returncode}:\n{done.stderr}")
        summary = json.loads((out / "summary.json").read_text())
    counted = summary["requirements"][name]
    return {
        "method": tester,
        "kind": "hazardhunt",
        "seed": seed,
        "episodes": summary["episodes"],
        "violations": counted["violations"],
        "first_violation_episode": counted["first_violation_episode"],
        "classes": sorted(f"{name}/{signals}" for signals in counted["decided_by"]),
        "min_robustness": counted["min_robustness"],
        "wall_time_s": summary["wall_time_s"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", default="crossing:2m", help="scenario:field")
    parser.add_argument("--requirement", required=True, help="a library name or FILE.toml:NAME")
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--methods", nargs="*", default=list(METHODS), choices=list(METHODS))
    parser.add_argument("--testers", nargs="*", default=["cem", "portfolio"])
    parser.add_argument("--hazardhunt", type=Path, default=REPOSITORY / ".venv/bin/hazardhunt")
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    case = Case.parse(args.case)
    started = time.perf_counter()
    rows = []
    for method in [*args.methods, *args.testers]:
        for seed in args.seeds:
            if method in METHODS:
                row = peer_row(method, case, args.requirement, seed, args.episodes)
            else:
                row = tester_row(
                    method, case, args.requirement, seed, args.episodes, args.hazardhunt
                )
            rows.append(row)
            print(
                f"{method:16} seed {seed}: {row['violations']:4} violations, first "
                f"{row['first_violation_episode']}, {len(row['classes'])} classes, "
                f"lowest robustness {row['min_robustness']:.3f}",
                flush=True,
            )
    print("\nmethod            violations (median)  first violation (median)  classes (union)")
    for method in [*args.methods, *args.testers]:
        mine = [row for row in rows if row["method"] == method]
        firsts = [r["first_violation_episode"] for r in mine]
        found = [f for f in firsts if f is not None]
        print(
            f"{method:16}  {statistics.median(r['violations'] for r in mine):>8}"
            f"  {statistics.median(found) if len(found) == len(firsts) else 'not every seed':>24}"
            f"  {len(set().union(*(r['classes'] for r in mine))):>6}"
        )
    if args.out is not None:
        record = {
            "command": " ".join(["python", *sys.argv]),
            "date": datetime.now(UTC).isoformat(timespec="seconds"),
            "case": str(case),
            "requirement": args.requirement,
            "episodes": args.episodes,
            "wall_time_s": time.perf_counter() - started,
            "runs": rows,
        }
        args.out.write_text(json.dumps(record, indent=2) + "\n")
        print(f"written to {args.out}")


if __name__ == "__main__":
    main()
