"""What the study reported (SPEC 8), to print beside hazardhunt's own numbers.

Source: the study's Table I (failure classes found), Table II (mean runtime per run of 20,000
episodes) and Lesson 1. The study's bar chart of failures per run has no numbers in the text.
"""

from __future__ import annotations

STUDY_EPISODES = 20_000
"""Episodes per run in the study."""

STUDY_BASELINE = "random"
"""The tester the study compared the others with (Lessons 1 and 2)."""

STUDY_REWARDS = ("ppo-acc", "ppo-max")
"""The two testers whose runtimes Table II compares: PPO with the accumulated reward and PPO
with the maximum reward."""

STUDY_CLASSES: dict[tuple[str, str], dict[str, tuple[int, int]]] = {
    ("crossing", "none"): {"ppo-max": (8, 8), "ppo-acc": (8, 8), "random": (8, 8)},
    ("crossing", "1.25m"): {"ppo-max": (6, 9), "ppo-acc": (7, 9), "random": (5, 9)},
    ("crossing", "2m"): {"ppo-max": (8, 9), "ppo-acc": (6, 9), "random": (7, 9)},
    ("head-on", "none"): {"ppo-max": (8, 8), "ppo-acc": (8, 8), "random": (8, 8)},
    ("head-on", "1.25m"): {"ppo-max": (5, 9), "ppo-acc": (5, 9), "random": (5, 9)},
    ("head-on", "2m"): {"ppo-max": (7, 9), "ppo-acc": (6, 9), "random": (6, 9)},
    ("overtaking", "none"): {"ppo-max": (8, 8), "ppo-acc": (8, 8), "random": (8, 8)},
    ("overtaking", "1.25m"): {"ppo-max": (7, 9), "ppo-acc": (6, 9), "random": (5, 9)},
    ("overtaking", "2m"): {"ppo-max": (5, 9), "ppo-acc": (7, 9), "random": (7, 9)},
}
"""Table I: classes found / classes possible, per (scenario, field) and tester."""

STUDY_RUNTIME_MINUTES: dict[tuple[str, str], dict[str, int]] = {
    ("crossing", "1.25m"): {"ppo-acc": 42 * 60 + 13, "ppo-max": 34 * 60 + 23},
    ("crossing", "2m"): {"ppo-acc": 47 * 60 + 50, "ppo-max": 25 * 60 + 34},
    ("crossing", "none"): {"ppo-acc": 47 * 60 + 47, "ppo-max": 33 * 60 + 49},
    ("overtaking", "1.25m"): {"ppo-acc": 77 * 60 + 45, "ppo-max": 34 * 60 + 57},
    ("overtaking", "2m"): {"ppo-acc": 50 * 60 + 16, "ppo-max": 19 * 60 + 41},
    ("overtaking", "none"): {"ppo-acc": 52 * 60 + 51, "ppo-max": 37 * 60 + 24},
    ("head-on", "1.25m"): {"ppo-acc": 77 * 60 + 3, "ppo-max": 42 * 60 + 47},
    ("head-on", "2m"): {"ppo-acc": 48 * 60 + 44, "ppo-max": 28 * 60 + 28},
    ("head-on", "none"): {"ppo-acc": 64 * 60 + 43, "ppo-max": 52 * 60 + 40},
}
"""Table II: mean runtime of one 20,000-episode run, in minutes (the study printed hh:mm)."""

STUDY_LESSON_1: dict[str, tuple[int, int]] = {"ppo-max": (24, 27), "ppo-acc": (19, 27)}
"""Lesson 1: (scenario, field, seed) comparisons in which the tester found more failures than
random sampling, out of all comparisons."""
