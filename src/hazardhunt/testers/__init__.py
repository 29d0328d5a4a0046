"""Search methods that choose the human's actions: random sampling and PPO."""

from __future__ import annotations

from typing import Any

from hazardhunt.testers.base import EpisodeRecord, EpisodeRecorder, Tester

TESTER_NAMES = ("random", "ppo-acc", "ppo-max")
"""The built-in testers."""


def make_tester(name: str, seed: int, params: dict[str, Any] | None = None) -> Tester:
    """Build a tester by name (``random``, ``ppo-acc``, ``ppo-max``) with keyword ``params``."""
    params = dict(params or {})
    if name == "random":
        from hazardhunt.testers.random_sampling import RandomTester

        return RandomTester(seed, **params)
    if name in ("ppo-acc", "ppo-max"):
        from hazardhunt.testers.ppo import PPOTester

        return PPOTester(name, "acc" if name == "ppo-acc" else "max", seed, params)
    raise ValueError(f"unknown tester {name!r}: use one of {', '.join(TESTER_NAMES)}")


__all__ = ["TESTER_NAMES", "EpisodeRecord", "EpisodeRecorder", "Tester", "make_tester"]
