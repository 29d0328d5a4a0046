"""Encounters: one draw of the people model and of the SUT's uncertainties, played as an episode.

An :class:`EncounterSource` turns draws (the values of every dimension and a noise seed) into
played episodes; :class:`SimulationEncounters` plays them in the simulation against the SUT.
The estimators see only the dimensions and the played rows, so a source of one's own (a
surrogate, a closed-form test system) estimates the same way.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from hazardhunt.campaign.store import sut_error_of
from hazardhunt.likelihood.distributions import Dimension
from hazardhunt.likelihood.people import HumanModel, ModelError
from hazardhunt.likelihood.uncertainty import Uncertainties
from hazardhunt.sim.simulation import EpisodeResult, Simulation
from hazardhunt.spec.episode import EpisodeSummary
from hazardhunt.spec.failure_classes import MechanismClassifier


@dataclass(frozen=True)
class Draw:
    """What one encounter is made of: every dimension's value and the seed of its noise."""

    values: Mapping[str, float]
    seed: int


@dataclass(frozen=True)
class Played:
    """An encounter's outcome, as the estimators read it."""

    outcome: str
    failure: bool
    failure_class: str | None
    score: float
    """The episode's largest risk (at or above the failure threshold on a failure)."""
    min_clearance: float
    sim_time: float
    sut_error: bool
    error: str = ""
    """What the SUT raised (or how it failed), for an encounter that ended in a SUT error."""


class EncounterSource(Protocol):
    """Draws in, played encounters out."""

    @property
    def dimensions(self) -> Sequence[Dimension]:
        """The independent random variables of an encounter."""
        ...

    @property
    def threshold(self) -> float:
        """The score at and above which an encounter is a failure."""
        ...

    def play(self, draw: Draw) -> Played:
        """Play one encounter."""
        ...


def joint_dimensions(model: HumanModel, uncertainties: Uncertainties) -> tuple[Dimension, ...]:
    """The people's dimensions, then the SUT's.

    Raises:
        ModelError: A name is in both.
    """
    people = tuple(model.dimensions)
    clash = {d.name for d in people} & {d.name for d in uncertainties.dimensions}
    if clash:
        raise ModelError(
            f"the people model and the uncertainties both name {', '.join(sorted(clash))}"
        )
    return (*people, *uncertainties.dimensions)


class SimulationEncounters:
    """Encounters played in a simulation against its SUT."""

    def __init__(
        self, simulation: Simulation, model: HumanModel, uncertainties: Uncertainties
    ) -> None:
        self.simulation = simulation
        self.model = model
        self.uncertainties = uncertainties
        self.dimensions = joint_dimensions(model, uncertainties)
        self.threshold = simulation.risk_params.collision_risk
        self.classifier = MechanismClassifier(robot=simulation.robot_params)

    def episode(self, draw: Draw, keep_trajectory: bool = False) -> EpisodeResult:
        """The encounter's episode (its trajectory always kept for a failure)."""
        simulation = self.simulation
        simulation.effects = self.uncertainties.effects(draw.values, draw.seed)
        policy = self.model.policy(draw.values, simulation)

        def keep(summary: EpisodeSummary) -> bool:
            return keep_trajectory or summary.outcome == "failure"

        try:
            return simulation.simulate(policy, keep)
        finally:
            simulation.effects = None

    def play(self, draw: Draw) -> Played:
        result = self.episode(draw)
        summary = result.summary
        failure = summary.outcome == "failure"
        failure_class = None
        if failure:
            failure_class = self.classifier.classify(
                result.trajectory or (), summary, self.simulation.field
            )
        return Played(
            outcome=str(summary.outcome),
            failure=failure,
            failure_class=failure_class,
            score=float(summary.max_risk),
            min_clearance=float(summary.min_clearance),
            sim_time=float(summary.sim_time),
            sut_error=summary.outcome == "sut_error",
            error=sut_error_of(summary) if summary.outcome == "sut_error" else "",
        )


def played_row(played: Played) -> dict[str, Any]:
    """A played encounter as columns of the episode table."""
    return {
        "outcome": played.outcome,
        "failure": played.failure,
        "failure_class": played.failure_class or "",
        "score": played.score,
        "min_clearance": played.min_clearance,
        "sim_time": played.sim_time,
        "sut_error": played.sut_error,
        "error": played.error,
    }
