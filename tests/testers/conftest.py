"""Short seeded runs of each tester, made once per test session and shared."""

from pathlib import Path

import pytest

from hazardhunt.campaign.config import RunConfig
from hazardhunt.campaign.run import record_run

EPISODES = 24
SMALL_PPO = {"n_steps": 64, "batch_size": 32}
"""Small rollouts, so that a 24-episode run (about 200 steps) includes several updates."""

CASES = {
    # Without a protective field, failures turn up within a few dozen episodes.
    "random": {"scenario": "overtaking", "field": "none", "tester": "random"},
    "ppo-acc": {
        "scenario": "head-on",
        "field": "none",
        "tester": "ppo-acc",
        "tester_params": SMALL_PPO,
    },
    # Whole episodes as points: small batches, so that 24 episodes are several of them.
    "cem": {
        "scenario": "head-on",
        "field": "none",
        "tester": "cem",
        "tester_params": {"population": 8},
    },
    "qd": {
        "scenario": "head-on",
        "field": "none",
        "tester": "qd",
        "tester_params": {"emitters": 2, "batch_size": 4},
    },
    "ppo-novelty": {
        "scenario": "head-on",
        "field": "none",
        "tester": "ppo-novelty",
        "tester_params": SMALL_PPO,
    },
    # Two small arms, so that 24 episodes are several batches of each.
    "portfolio": {
        "scenario": "head-on",
        "field": "none",
        "tester": "portfolio",
        "tester_params": {
            "arms": [
                {"name": "uniform", "method": "uniform", "params": {"batch_size": 4}},
                {
                    "name": "aimed",
                    "method": "cem",
                    "params": {"batch_size": 4, "space": {"kind": "aim", "detour": True}},
                },
            ]
        },
    },
    # Two copies of the env in worker processes, their episodes recorded as they end.
    "ppo-max-2-envs": {
        "scenario": "head-on",
        "field": "none",
        "tester": "ppo-max",
        "tester_params": SMALL_PPO | {"n_envs": 2},
    },
}


@pytest.fixture(scope="session")
def seeded_run(tmp_path_factory):
    """``seeded_run(tester, seed, copy=0)``: the directory of a finished run of ``CASES[tester]``
    (``copy`` makes an independent second run of the same configuration)."""
    made: dict[tuple[str, int, int], Path] = {}

    def run(tester: str, seed: int, copy: int = 0) -> Path:
        key = (tester, seed, copy)
        if key not in made:
            directory = tmp_path_factory.mktemp(f"{tester}-seed{seed}-{copy}") / "run"
            record_run(RunConfig(**CASES[tester], seed=seed, episodes=EPISODES), directory)
            made[key] = directory
        return made[key]

    return run
