"""PPO testers: the budget, reproducibility, the saved policy and the reward they learn from."""

import json
import tempfile
from typing import Any

import gymnasium as gym
import pandas as pd
import pytest
from stable_baselines3 import PPO

from hazardhunt.campaign.config import RunConfig
from hazardhunt.campaign.replay import replay_failure
from hazardhunt.campaign.simulations import simulation_of
from hazardhunt.env.agv import AGVEnv
from hazardhunt.testers import make_tester
from hazardhunt.testers.base import EpisodeRecorder
from tests.testers.conftest import CASES, SMALL_PPO


@pytest.fixture(scope="module")
def first_run(seeded_run):
    return seeded_run("ppo-acc", 0)


def test_saved_policy_loads_and_acts_in_the_action_space(first_run):
    model = PPO.load(first_run / "tester" / "ppo.zip", device="cpu")
    env = AGVEnv("head-on", "none")
    observation, _ = env.reset(seed=0)
    action, _ = model.predict(observation, deterministic=True)
    assert env.action_space.contains(action)
    env.step(action)


def test_effective_hyperparameters_are_saved(first_run):
    saved = json.loads((first_run / "tester" / "hyperparameters.json").read_text())
    assert saved["n_steps"] == 64
    assert saved["batch_size"] == 32
    assert saved["learning_rate"] == 3e-4  # SB3's default
    assert saved["seed"] == 0
    assert saved["device"] == "cpu"


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"learning_rat": 1e-3}, "tester 'ppo-max': learning_rat: unknown parameter"),
        ({"seed": 3}, "tester 'ppo-max': seed: is set by hazardhunt"),
        ({"env": "CartPole-v1"}, "env: is set by hazardhunt"),
        ({"device": "cuda"}, "device: is set by hazardhunt"),
        ({"n_envs": 0}, "n_envs: must be a whole number from 1 to 64, not 0"),
    ],
)
def test_bad_parameters_are_clear_errors(params, message):
    with pytest.raises(ValueError, match=message):
        make_tester("ppo-max", 0, params)


def test_failures_found_by_parallel_envs_replay_exactly(seeded_run):
    run = seeded_run("ppo-max-2-envs", 0)
    failures = pd.read_parquet(run / "failures.parquet")
    assert len(failures) > 0
    for episode in failures["episode"]:
        assert replay_failure(run, int(episode)).matches
    saved = json.loads((run / "tester" / "hyperparameters.json").read_text())
    assert saved["n_envs"] == 2


class StepLog(gym.Wrapper):
    """Keeps every step's reward and info."""

    def __init__(self, env):
        super().__init__(env)
        self.steps: list[tuple[float, dict[str, Any]]] = []

    def step(self, action):
        observation, reward, terminated, truncated, info = self.env.step(action)
        self.steps.append((reward, info))
        return observation, reward, terminated, truncated, info


def explore(name: str, seed: int, episodes: int) -> tuple[EpisodeRecorder, list[list[tuple]]]:
    """Let tester ``name`` explore a few episodes; returns the recorder and each episode's steps."""
    tester = make_tester(name, seed, SMALL_PPO)
    config = RunConfig(**CASES["ppo-acc"] | {"tester": name}, seed=seed, episodes=episodes)
    log = StepLog(AGVEnv.wrapping(simulation_of(config), tester.reward))
    recorder = EpisodeRecorder(log, on_episode=lambda record: None)
    tester.explore(recorder, episodes)
    by_episode: list[list[tuple]] = [[]]
    for reward, info in log.steps:
        by_episode[-1].append((reward, info))
        if info["outcome"] is not None:
            by_episode.append([])
    return recorder, by_episode[:-1]


def test_ppo_acc_learns_from_the_accumulated_risk():
    recorder, episodes = explore("ppo-acc", seed=0, episodes=2)
    assert recorder.unwrapped.reward_kind == "acc"
    for steps in episodes:
        rewards = [reward for reward, _ in steps]
        assert rewards == [info["risk_sum"] for _, info in steps]
        assert sum(rewards) == pytest.approx(steps[-1][1]["summary"].risk_sum)
        assert sum(rewards) > 0


def test_ppo_max_learns_from_the_episode_maximum_at_its_end():
    recorder, episodes = explore("ppo-max", seed=0, episodes=2)
    assert recorder.unwrapped.reward_kind == "max"
    for steps in episodes:
        rewards = [reward for reward, _ in steps]
        assert rewards[:-1] == [0.0] * (len(steps) - 1)
        assert rewards[-1] == steps[-1][1]["max_risk"] > 0


def test_the_first_reset_carries_the_run_seed():
    recorder, _ = explore("ppo-max", seed=12345, episodes=1)
    assert recorder.unwrapped.np_random_seed == 12345
    assert recorder.episodes_done == 1


def test_learning_leaves_nothing_in_the_temporary_directory(tmp_path, monkeypatch):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    explore("ppo-max", seed=0, episodes=1)
    # torch keeps one cache directory per user there (torchinductor_<user>), made once and reused.
    left = [path.name for path in tmp_path.iterdir() if not path.name.startswith("torchinductor_")]
    assert left == []


def test_ppo_max_searching_on_a_requirement_learns_from_its_robustness(monkeypatch, tmp_path):
    from hazardhunt.testers import ppo
    from hazardhunt.testers.objective import RequirementRule

    config = RunConfig(
        **CASES["ppo-acc"] | {"tester": "ppo-max"},
        seed=0,
        episodes=3,
        requirements=["slow-near-people"],
        search_on="slow-near-people",
    )
    recorded = []
    recorder = EpisodeRecorder(
        AGVEnv.wrapping(simulation_of(config), "max"), on_episode=recorded.append
    )
    recorder.objective = RequirementRule("slow-near-people")
    rewards: list[float] = []
    step = ppo.RequirementReward.step

    def logged(self, action):
        stepped = step(self, action)
        rewards.append(stepped[1])
        return stepped

    monkeypatch.setattr(ppo.RequirementReward, "step", logged)
    tester = make_tester("ppo-max", 0, SMALL_PPO)
    tester.explore(recorder, 3)
    # 0 until each episode's last decision, then 100 x the score of its robustness r:
    # 1 / (1 + r) while kept, 1 - r once violated; the risk plays no part.
    last = [len(record.result.actions) for record in recorded]
    ends = [sum(last[: i + 1]) - 1 for i in range(len(last))]
    assert [i for i, reward in enumerate(rewards) if reward != 0.0] == ends
    for index, record in zip(ends, recorded, strict=True):
        robustness = record.result.verdicts["slow-near-people"].robustness
        score = 1 - robustness if robustness < 0 else 1 / (1 + robustness)
        assert rewards[index] == pytest.approx(100 * score)
    # A copy of the env in a worker process gives the same reward.
    worker_env = ppo._ReporterFactory(recorder)()
    worker_env.reset(seed=0)
    for action in recorded[0].result.actions:
        _, reward, terminated, truncated, _ = worker_env.step(action)
    assert terminated or truncated
    assert reward == pytest.approx(rewards[ends[0]])
    tester.save(tmp_path)
    saved = json.loads((tmp_path / "hyperparameters.json").read_text())
    assert saved["reward"] == "requirement:slow-near-people"
