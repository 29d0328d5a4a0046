"""Plug-ins that misbehave, as a hostile or careless user writes them: testers and people models
that end the process, raise what is not an ``Exception``, return non-finite actions or nothing.

Name them by import path: ``--tester tests.misbehaving:ThrowingTester --tester-param
error='"SystemExit(7)"'``, ``--people tests.misbehaving:ExitingPeople``, or as a portfolio
arm's ``method``.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from hazardhunt.benchmark.conservative import ConservativeController
from hazardhunt.likelihood.distributions import Dimension
from hazardhunt.testers.evaluator import Plan
from hazardhunt.testers.search import SearchTester, SpaceParams

THROWN = {
    "SystemExit(0)": lambda: SystemExit(0),
    "SystemExit(7)": lambda: SystemExit(7),
    "KeyboardInterrupt": KeyboardInterrupt,
    "GeneratorExit": GeneratorExit,
    "BaseException": lambda: BaseException("not an Exception"),
}
"""What a misbehaving plug-in raises, by name."""

STAND = np.array([-1.0, 0.0])


class ThrowingTester:
    """A tester whose ``explore`` raises ``error`` (a key of :data:`THROWN`), after playing
    ``first`` episodes standing still."""

    name = "throwing"

    def __init__(self, seed: int, error: str = "SystemExit(0)", first: int = 0) -> None:
        self.seed, self.error, self.first = seed, error, first

    def explore(self, env, episodes):
        for _ in range(self.first):
            env.evaluate(np.tile(STAND, (env.horizon, 1)))
        raise THROWN[self.error]()

    def save(self, directory):
        pass


class ExitingTester(ThrowingTester):
    """A tester whose ``explore`` raises ``SystemExit(0)``."""


class NonFiniteTester:
    """A tester that plays every episode with the action ``(value, 0)`` (``nan``, ``inf``),
    as whole episodes (``evaluate``) or stepping the env (``step``)."""

    name = "non-finite"

    def __init__(self, seed: int, value: str = "nan", how: str = "evaluate") -> None:
        self.seed, self.value, self.how = seed, float(value), how

    def explore(self, env, episodes):
        action = np.array([self.value, 0.0])
        while env.episodes_done < episodes:
            if self.how == "evaluate":
                env.evaluate(np.tile(action, (env.horizon, 1)))
                continue
            env.reset(seed=self.seed)
            done = False
            while not done:
                _, _, terminated, truncated, _ = env.step(action.astype(np.float32))
                done = terminated or truncated

    def save(self, directory):
        pass


class _ArmSampler:
    """A sampler of a portfolio arm that misbehaves when asked, per ``how``."""

    def __init__(self, params, context, how):
        self.space, self.horizon, self.how = params.space.decision_spaces[0], context.horizon, how

    def ask(self):
        if self.how in THROWN:
            raise THROWN[self.how]()
        value = float(self.how)  # "nan": proposes non-finite decisions
        return [Plan(self.space, np.full((self.horizon, self.space.size), value))]

    def tell(self, plans, results):
        pass

    def record(self):
        return {}


class ExitingSearch(SearchTester):
    """A search tester (or portfolio arm) whose sampler raises ``SystemExit(0)`` when asked."""

    name = "exiting-search"
    params_model = SpaceParams
    how = "SystemExit(0)"

    def make_sampler(self, context):
        return _ArmSampler(self.params, context, self.how)


class NonFiniteSearch(ExitingSearch):
    """A search tester (or portfolio arm) whose sampler proposes NaN decisions."""

    name = "non-finite-search"
    how = "nan"


class WalkingPeople:
    """A well-behaved people model: one variable, the start delay in s; the human stands until
    then and walks straight ahead. The misbehaving models below change one thing of it."""

    def __init__(self, scenario):
        table = {"distribution": "uniform", "low": 0.0, "high": 2.0}
        self.dimensions = (Dimension("start_delay", stats.uniform(0.0, 2.0), table),)

    def policy(self, values, simulation):
        start = values["start_delay"]
        return lambda sim: self.action(sim, start)

    def action(self, simulation, start):
        return STAND if simulation.sim_time < start else np.array([0.0, 0.0])


class ExitingPeople(WalkingPeople):
    """``policy()`` raises ``SystemExit(0)``."""

    def policy(self, values, simulation):
        raise SystemExit(0)


class ThrowingPeople(WalkingPeople):
    """``policy()`` raises a ``BaseException`` that is not an ``Exception``."""

    def policy(self, values, simulation):
        raise BaseException("not an Exception")


class RaisingPolicyPeople(WalkingPeople):
    """``policy()`` raises a ValueError."""

    def policy(self, values, simulation):
        raise ValueError("no such aisle")


class RaisingActionPeople(WalkingPeople):
    """The policy's action raises a ZeroDivisionError."""

    def action(self, simulation, start):
        return 1 / 0


class NonePolicyPeople(WalkingPeople):
    """``policy()`` returns None."""

    def policy(self, values, simulation):
        return None


class NoneActionPeople(WalkingPeople):
    """The policy's action is None."""

    def action(self, simulation, start):
        return None


class NaNPeople(WalkingPeople):
    """The human's action is NaN: the audit's model, whose 100 encounters were counted as
    tested and safe."""

    def action(self, simulation, start):
        return np.array([math.nan, 0.0])


class LateNaNPeople(WalkingPeople):
    """The action turns NaN once the human has set off: the first decision, which the check
    before the estimate plays, is fine."""

    def action(self, simulation, start):
        return np.array([math.nan, 0.0]) if simulation.sim_time > 1.0 else STAND


class LateExitingPeople(WalkingPeople):
    """The action raises ``SystemExit(0)`` once the human has set off."""

    def action(self, simulation, start):
        if simulation.sim_time > 1.0:
            raise SystemExit(0)
        return STAND


class InterruptingController(ConservativeController):
    """A controller that raises ``KeyboardInterrupt`` itself (no Ctrl-C was pressed) from
    ``after`` s into an episode: from 0, on the trial episode before a run."""

    def __init__(self, after: float = 0.0, **params) -> None:
        super().__init__(**params)
        self.after = after

    def control(self, time, robot, human):
        if time >= self.after:
            raise KeyboardInterrupt
        return super().control(time, robot, human)


class ExitingClassifier:
    """A failure classifier whose ``classify`` raises ``SystemExit(0)``."""

    name = "exiting"

    def classes_for(self, field):
        return ("face", "other")

    def classify(self, trajectory, summary, field):
        raise SystemExit(0)
