"""Search methods that choose the human's actions: random sampling, PPO, and one's own."""

from __future__ import annotations

from hazardhunt.testers.base import EpisodeRecord, EpisodeRecorder, Tester
from hazardhunt.testers.registry import (
    TESTERS,
    RegisteredTester,
    build_tester,
    make_tester,
    register_tester,
)

__all__ = [
    "TESTERS",
    "EpisodeRecord",
    "EpisodeRecorder",
    "RegisteredTester",
    "Tester",
    "build_tester",
    "make_tester",
    "register_tester",
]
