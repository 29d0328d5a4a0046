"""Search methods that choose the human's actions: random sampling and PPO, by name."""

from __future__ import annotations

from hazardhunt.testers.base import EpisodeRecord, EpisodeRecorder, Tester
from hazardhunt.testers.registry import (
    TESTERS,
    RegisteredTester,
    make_tester,
    register_tester,
)

__all__ = [
    "TESTERS",
    "EpisodeRecord",
    "EpisodeRecorder",
    "RegisteredTester",
    "Tester",
    "make_tester",
    "register_tester",
]
