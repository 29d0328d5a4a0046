"""The simulation core: one decision or one whole episode of the human against the SUT."""

from hazardhunt.sim.simulation import (
    DecisionReport,
    EpisodeResult,
    Policy,
    Simulation,
    SimulationSettings,
)

__all__ = ["DecisionReport", "EpisodeResult", "Policy", "Simulation", "SimulationSettings"]
