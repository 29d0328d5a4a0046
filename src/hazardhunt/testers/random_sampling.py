"""Uniform random sampling: the study's closed-loop baseline, and open-loop sequences.

The study's baseline (:class:`RandomTester`) draws each decision's action uniformly from the
action space until one keeps the human clear of every static obstacle over the next decision
period (its straight-or-arc path checked at the physics step); if none of ``attempts`` draws
does, the human turns on the spot at a random rate. :class:`UniformSampler` draws whole
episodes' decisions uniformly, an arm of the default portfolio.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pydantic import Field

from hazardhunt.sim.simulation import EpisodeResult, Simulation
from hazardhunt.testers.base import EpisodeRecorder, check_parameters, is_whole_number
from hazardhunt.testers.clear_path import human_path
from hazardhunt.testers.evaluator import Plan
from hazardhunt.testers.search import SearchContext, SpaceParams


class RandomTester:
    """Uniform sampling over the action space, restricted to obstacle-free actions."""

    name = "random"

    def __init__(self, seed: int, attempts: int = 20) -> None:
        """Args:
        seed: Seeds the sampling.
        attempts: Draws per decision before falling back to turning on the spot.

        Raises:
            TesterParameterError: ``attempts`` is not a whole number >= 1.
        """
        whole = is_whole_number(attempts) and attempts >= 1
        check_parameters(self.name, {"attempts": (attempts, "a whole number >= 1", whole)})
        self.seed = seed
        self.attempts = attempts
        self.rng = np.random.default_rng(seed)

    def explore(self, env: EpisodeRecorder, episodes: int) -> None:
        while env.episodes_done < episodes:
            env.evaluate(self.choose)

    def choose(self, simulation: Simulation) -> NDArray[np.float32]:
        """One obstacle-free action for the human where it stands in ``simulation``."""
        sim = simulation
        for _ in range(self.attempts):
            action = self.rng.uniform(-1.0, 1.0, size=2).astype(np.float32)
            speed, turn_rate = sim.decode_action(action)
            path = human_path(
                sim.human_pose, speed, turn_rate, sim.decision_period, sim.physics_step
            )
            if sim.scenario.floor.discs_clear(path, sim.human_params.radius):
                return action
        # Turning on the spot is always clear, and lets a human facing a wall turn away.
        return np.array([-1.0, self.rng.uniform(-1.0, 1.0)], dtype=np.float32)

    def save(self, directory: Path) -> None:
        """Nothing is learned; the directory records the sampler's settings."""
        directory.mkdir(parents=True, exist_ok=True)
        (directory / "random.txt").write_text(f"seed={self.seed}\nattempts={self.attempts}\n")


class UniformParams(SpaceParams):
    """Uniform random sampling's settings."""

    batch_size: int = Field(default=10, ge=1, le=10_000)
    """Episodes per batch."""


class UniformSampler:
    """Every number of every decision uniform in [-1, 1], the decision spaces in turn."""

    def __init__(self, params: UniformParams, context: SearchContext) -> None:
        self.params = params
        self.rng = np.random.default_rng(context.seed)
        self.horizon = context.horizon
        self.batches = 0

    def ask(self) -> list[Plan]:
        spaces = self.params.space.decision_spaces
        space = spaces[self.batches % len(spaces)]
        shape = (self.params.batch_size, self.horizon, space.size)
        return [Plan(space, decisions) for decisions in self.rng.uniform(-1.0, 1.0, shape)]

    def tell(self, plans: list[Plan], results: list[EpisodeResult]) -> None:
        self.batches += 1

    def record(self) -> dict[str, Any]:
        return {}
