"""The study's baseline: uniform random actions that do not walk the human into a wall.

Each decision draws actions uniformly from the action space until one keeps the human clear of
every static obstacle over the next decision period (its straight-or-arc path checked at the
physics step); if none of ``attempts`` draws does, the human turns on the spot at a random rate.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from hazardhunt.sim.simulation import Simulation
from hazardhunt.testers.base import EpisodeRecorder, check_parameters, is_whole_number
from hazardhunt.testers.clear_path import human_path


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
