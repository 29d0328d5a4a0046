"""What an episode-level search looks for: the contact rule's failures, or a requirement's
violations (``docs/requirements.md``).

An :class:`Objective` says of a played episode whether it is a *hit* (what the search is
after) and how close it came (its *score*, higher closer, never negative). The episode-level
samplers (``cem``, ``qd`` and the portfolio's arms) read both through the run's objective,
so that the same search that hunts unsafe contacts by their risk hunts a requirement's
violations by its robustness, which guides it long before the first violation.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from hazardhunt.sim.simulation import EpisodeResult


class Objective(Protocol):
    """What a search is after."""

    @property
    def name(self) -> str:
        """``contact``, or the requirement's name."""
        ...

    def hit(self, result: EpisodeResult) -> bool:
        """Whether the episode is what the search is after."""
        ...

    def score(self, result: EpisodeResult) -> float:
        """How close the episode came (at least 0; higher is closer)."""
        ...


@dataclass(frozen=True)
class ContactRule:
    """The study's requirement: an unsafe contact is a hit; the episode's largest risk its
    score."""

    name: str = "contact"

    def hit(self, result: EpisodeResult) -> bool:
        return result.summary.outcome == "failure"

    def score(self, result: EpisodeResult) -> float:
        return result.summary.max_risk


@dataclass(frozen=True)
class RequirementRule:
    """A requirement of the run (:attr:`Simulation.requirements`): a violation is a hit; the
    score falls with the robustness, ``1 / (1 + r)`` while it is kept by ``r`` and ``1 - r``
    once violated by ``-r`` (1 at the border)."""

    name: str

    def hit(self, result: EpisodeResult) -> bool:
        return self._robustness(result) < 0.0

    def score(self, result: EpisodeResult) -> float:
        robustness = self._robustness(result)
        return 1.0 - robustness if robustness < 0.0 else 1.0 / (1.0 + robustness)

    def _robustness(self, result: EpisodeResult) -> float:
        verdict = result.verdicts.get(self.name)
        if verdict is None:  # an episode the requirement did not judge: nothing to go on
            return float("inf")
        return verdict.robustness


CONTACT = ContactRule()
"""The objective of a run that names no requirement to search on."""


def objective_of(search_on: str | None) -> Objective:
    """The objective of a run that searches on the requirement ``search_on`` (None: the
    contact rule)."""
    return CONTACT if search_on is None else RequirementRule(search_on)


def violation_class(name: str, result: EpisodeResult) -> str:
    """The class of a violation of the requirement ``name``: the requirement and the signals
    that explain it (``slow-near-people/clearance+robot_speed``)."""
    verdict = result.verdicts.get(name)
    return f"{name}/{'unexplained' if verdict is None else verdict.decided_by}"
