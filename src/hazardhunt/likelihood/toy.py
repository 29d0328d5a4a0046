"""A test system whose failure probability is known in closed form, for validating estimators.

Two standard normal numbers ``a`` and ``b`` and a Bernoulli ``looks`` (1 with probability
``p_looks``) make an encounter. Its score is ``a + b``, less 2 when the person looks, and it
fails when the score reaches ``threshold``: the sum is normal with variance 2, so the
probability of a failure is ``(1 - p_looks) * Q(threshold / sqrt(2)) + p_looks *
Q((threshold + 2) / sqrt(2))`` with ``Q`` the standard normal tail. A search must find both the
rare sum and, mostly, the rare inattention.

``idle`` more variables that change nothing (normal and Bernoulli in turn) make the search
harder as a simulator's many parameters do: an estimator must leave them as the model has them.
"""

from __future__ import annotations

import math

from scipy import stats

from hazardhunt.likelihood.distributions import dimension
from hazardhunt.likelihood.encounters import Draw, Played


class ClosedFormEncounters:
    """Encounters with a known probability of failure (:attr:`probability`)."""

    def __init__(self, threshold: float = 4.0, p_looks: float = 0.9, idle: int = 0) -> None:
        self.threshold = threshold
        self.p_looks = p_looks
        normal = {"distribution": "normal", "mean": 0.0, "sd": 1.0}
        coin = {"distribution": "bernoulli", "p": 0.2}
        self.dimensions = (
            dimension("toy", "a", normal),
            dimension("toy", "b", normal),
            dimension("toy", "looks", {"distribution": "bernoulli", "p": p_looks}),
            *(dimension("toy", f"idle{i}", coin if i % 2 else normal) for i in range(idle)),
        )

    @property
    def probability(self) -> float:
        """The probability of a failure per encounter."""
        tail = stats.norm.sf
        inattentive = (1.0 - self.p_looks) * float(tail(self.threshold / math.sqrt(2.0)))
        attentive = self.p_looks * float(tail((self.threshold + 2.0) / math.sqrt(2.0)))
        return inattentive + attentive

    def play(self, draw: Draw) -> Played:
        total = draw.values["a"] + draw.values["b"]
        looks = round(draw.values["looks"]) == 1
        score = total - 2.0 if looks else total
        failure = score >= self.threshold
        return Played(
            outcome="failure" if failure else "goal",
            failure=failure,
            failure_class="sum" if failure else None,
            score=score,
            min_clearance=0.0,
            sim_time=0.0,
            sut_error=False,
        )
