"""Candidate NMPC solvers on recorded closed-loop problems, side by side.

Records the problems that the default NMPC solves in closed loop against a random human (the
initial guess, the parameters, whether the guess is a shifted plan), solves each with IPOPT to
a tolerance of 1e-10 as the reference, then replays them with every candidate, problem by
problem in turn so that a change in the machine's load touches all of them alike. Per candidate:
solve times, iterations, failed solves and how far the first command (speed and yaw rate at the
end of the first stage) lies from the reference's. Prints a table and writes JSON.

Candidates: the compiled fatrop with today's settings, with the settings before the tuning and
with other settings of fatrop's interior-point method; CasADi's ``sqpmethod`` with the QP
solvers of its wheel, started from the reference's own multipliers (the best warm start a
shifted plan could give); ``alpaqa`` (PANOC with an augmented Lagrangian). Slow candidates solve
every ``--slow-stride``-th problem only.

    python benchmarks/nmpc_candidates.py --episodes 4 --out benchmarks/results/nmpc_candidates.json
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from hazardhunt.sim.simulation import Simulation
from hazardhunt.sut import nmpc_problem
from hazardhunt.sut.compiled import compile_solvers
from hazardhunt.sut.nmpc import NMPCController, NMPCParams
from hazardhunt.world.scenario import BUILTIN_SCENARIOS

Solve = Callable[[np.ndarray, np.ndarray, bool, int], tuple[np.ndarray, float, bool]]
"""(guess, parameters, warm, problem index) -> (solution, iterations, success)."""
FATROP_VARIANTS: dict[str, dict[str, float]] = {
    "fatrop-previous": {"mu_superlinear_decrease_power": 1.5, "bound_push": 1e-6},
    "fatrop mu_init=1e-8": {"mu_init": 1e-8},
    "fatrop tol=1e-5": {"tol": 1e-5},
    "fatrop bound_push=1e-5": {"bound_push": 1e-5, "bound_frac": 1e-5},
    "fatrop barrier_tol_factor=100": {"barrier_tol_factor": 100.0},
}
"""fatrop options on top of today's warm-start settings (``bound_push`` sets ``bound_frac``)."""
QP_SOLVERS = {
    "daqp": {},
    "proxqp": {},
    "qrqp": {"print_iter": False, "print_header": False, "print_info": False},
    "hpipm": {"N": 20, "nx": [5] * 21, "nu": [4] * 20 + [2], "ng": [5] * 21},
}


@dataclass
class Candidate:
    name: str
    solve: Solve | None
    stride: int = 1
    error: str = ""
    times_ms: list[float] = field(default_factory=list)
    iterations: list[float] = field(default_factory=list)
    errors: list[float] = field(default_factory=list)
    failed: int = 0


def record_problems(episodes: int, seed: int) -> list[dict[str, Any]]:
    """The problems the default NMPC solves in closed loop, with its own solutions."""
    problems: list[dict[str, Any]] = []
    controller = NMPCController()
    problem = controller._problem
    solve = problem.solve

    def recording(guess: Any, parameters: np.ndarray, warm: bool) -> Any:
        x0 = guess.stages.ravel()[problem.variable_index]
        problems.append({"x0": x0, "p": parameters.copy(), "warm": warm})
        return solve(guess, parameters, warm)

    problem.solve = recording  # type: ignore[method-assign]
    for scenario in BUILTIN_SCENARIOS:
        simulation = Simulation.build(scenario, "1.25m", controller=controller)
        rng = np.random.default_rng(seed)

        def uniform(_: Simulation, rng: np.random.Generator = rng) -> np.ndarray:
            return rng.uniform(-1.0, 1.0, size=2)

        for _ in range(episodes):
            simulation.simulate(uniform, keep_trajectory=False)
    return problems


class Bench:
    """The NMPC's problem, its reference solutions and the candidates' constructors."""

    def __init__(self, problems: list[dict[str, Any]]) -> None:
        self.params = NMPCParams()
        self.problem = nmpc_problem.Problem(self.params, NMPCController().robot)
        self.nlp, self.equality, _, _ = self.problem._formulate()
        self.problems = problems
        reference = ca.nlpsol(
            "reference",
            "ipopt",
            self.nlp,
            {"print_time": False, "ipopt": {"print_level": 0, "sb": "yes", "tol": 1e-10}},
        )
        self.reference = []
        for item in problems:
            result = reference(x0=item["x0"], p=item["p"], **self.problem.fixed_arguments)
            self.reference.append({key: np.asarray(value).ravel() for key, value in result.items()})

    def command(self, x: np.ndarray) -> np.ndarray:
        stages = x.take(self.problem.stage_source).reshape(self.params.horizon + 1, -1)
        return stages[1, [nmpc_problem.SPEED, nmpc_problem.YAW_RATE]]

    def fatrop(self, changes: dict[str, float]) -> Solve:
        options = nmpc_problem.solver_options(self.params, self.equality, True)
        options["fatrop"].update(changes)
        if "bound_push" in changes:
            options["fatrop"]["bound_frac"] = changes["bound_push"]
        (warm,) = compile_solvers([ca.nlpsol("nmpc", "fatrop", self.nlp, options)])
        warm.set_fixed(**self.problem.bounds)
        assert self.problem.compiled is not None
        cold = self.problem.compiled[1]

        def solve(x0: np.ndarray, p: np.ndarray, is_warm: bool, _: int) -> Any:
            result = (warm if is_warm else cold).solve(x0, p)
            return result.x, float(result.iterations), result.success

        return solve

    def casadi(self, plugin: str, options: dict[str, Any]) -> Solve:
        solver = ca.nlpsol("candidate", plugin, self.nlp, {"print_time": False, **options})
        multipliers = plugin == "sqpmethod"

        def solve(x0: np.ndarray, p: np.ndarray, _: bool, index: int) -> Any:
            arguments = {"x0": x0, "p": p, **self.problem.fixed_arguments}
            if multipliers:
                arguments["lam_x0"] = self.reference[index]["lam_x"]
                arguments["lam_g0"] = self.reference[index]["lam_g"]
            try:
                result = solver(**arguments)
            except RuntimeError:
                return x0, float("nan"), False
            stats = solver.stats()
            iterations = stats.get("iter_count", np.nan)
            return np.asarray(result["x"]).ravel(), iterations, stats["success"]

        return solve


def candidates(bench: Bench, slow_stride: int) -> list[Candidate]:
    """Every candidate, or its construction's error."""
    made = [Candidate("fatrop", bench.fatrop({}))]
    specs: list[tuple[str, Callable[[], Solve], int]] = [
        (name, lambda c=changes: bench.fatrop(c), 1) for name, changes in FATROP_VARIANTS.items()
    ]
    for qp, qp_options in QP_SOLVERS.items():
        sqp = {
            "qpsol": qp,
            "qpsol_options": {"error_on_fail": False, **qp_options},
            "print_header": False,
            "print_iteration": False,
            "print_status": False,
            "tol_pr": 1e-6,
            "tol_du": 1e-6,
            "max_iter": 30,
            "convexify_strategy": "regularize",
        }
        specs.append((f"sqpmethod+{qp}", lambda o=sqp: bench.casadi("sqpmethod", o), slow_stride))
    specs.append(("alpaqa", lambda: bench.casadi("alpaqa", {}), slow_stride))
    for name, make, stride in specs:
        try:
            made.append(Candidate(name, make(), stride))
        except RuntimeError as error:
            lines = str(error).strip().splitlines()
            reason = next((line for line in lines if "Assertion" in line), lines[-1])
            made.append(Candidate(name, None, error=reason.split("/")[-1][:200]))
    return made


def replay(bench: Bench, made: list[Candidate], every: int) -> None:
    """Solve every ``every``-th problem with each candidate in turn."""
    for count, index in enumerate(range(0, len(bench.problems), every)):
        item = bench.problems[index]
        expected = bench.command(bench.reference[index]["x"])
        for candidate in made:
            if candidate.solve is None or count % candidate.stride:
                continue
            started = time.perf_counter()
            x, iterations, success = candidate.solve(item["x0"], item["p"], item["warm"], index)
            candidate.times_ms.append(1e3 * (time.perf_counter() - started))
            candidate.iterations.append(iterations)
            candidate.failed += not success
            candidate.errors.append(float(np.abs(bench.command(x) - expected).max()))


def summary(candidate: Candidate, base_median: float) -> dict[str, Any]:
    if candidate.solve is None:
        return {"candidate": candidate.name, "unavailable": candidate.error}
    times, errors = np.array(candidate.times_ms), np.array(candidate.errors)
    return {
        "candidate": candidate.name,
        "solves": len(times),
        "solve_ms": {
            "median": float(np.median(times)),
            "p99": float(np.percentile(times, 99)),
            "mean": float(times.mean()),
        },
        "median_ratio": float(np.median(times) / base_median),
        "iterations": {  # NaN where the solver does not count them (alpaqa)
            "median": float(np.median(candidate.iterations)),
            "mean": float(np.mean(candidate.iterations)),
        },
        "failed_solves": candidate.failed,
        "command_error": {
            "median": float(np.median(errors)),
            "p99": float(np.percentile(errors, 99)),
            "above_1e-3": int((errors > 1e-3).sum()),
        },
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=4, help="episodes per scenario")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--every", type=int, default=1, help="replay every k-th problem")
    parser.add_argument("--slow-stride", type=int, default=10)
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/nmpc_candidates.json"))
    args = parser.parse_args()
    problems = record_problems(args.episodes, args.seed)
    bench = Bench(problems)
    made = candidates(bench, args.slow_stride)
    replay(bench, made, args.every)
    base = float(np.median(made[0].times_ms))
    results = [summary(c, base) for c in made]
    print(
        f"{len(problems)} recorded problems ({sum(p['warm'] for p in problems)} warm-started), "
        f"every {args.every}-th replayed; command error against IPOPT at tol 1e-10"
    )
    print(
        f"{'candidate':30} {'solves':>6} {'median':>7} {'p99':>7} {'ratio':>6} {'iter':>5} "
        f"{'mean':>5} {'failed':>6} {'err p99':>8} {'>1e-3':>5}"
    )
    for r in results:
        if "unavailable" in r:
            print(f"{r['candidate']:30} unavailable: {r['unavailable']}")
            continue
        ms, it, err = r["solve_ms"], r["iterations"], r["command_error"]
        print(
            f"{r['candidate']:30} {r['solves']:6d} {ms['median']:7.3f} {ms['p99']:7.3f} "
            f"{r['median_ratio']:6.2f} {it['median']:5.1f} {it['mean']:5.2f} "
            f"{r['failed_solves']:6d} {err['p99']:8.1e} {err['above_1e-3']:5d}"
        )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    report = {"problems": len(problems), "every": args.every, "results": results}
    args.out.write_text(json.dumps(report, indent=2))
    print(f"written to {args.out}")


if __name__ == "__main__":
    main()
