"""The env honours the Gymnasium and Stable-Baselines3 contracts."""

import pickle
import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gymnasium_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import hazardhunt
from hazardhunt.env.agv import AGVEnv


def make(**kwargs):
    options = {"scenario": "crossing", "field": "1.25m", "reward": "max", "decision_period": 2.0}
    return gymnasium.make(hazardhunt.ENV_ID, **(options | kwargs))


def test_make_with_the_documented_keywords():
    env = make(scenario="head-on", field="2m", reward="acc", decision_period=1.0)
    unwrapped = env.unwrapped
    assert isinstance(unwrapped, AGVEnv)
    assert unwrapped.simulation.scenario.name == "head-on"
    assert unwrapped.simulation.field.diameter == 2.0
    assert unwrapped.reward_kind == "acc"
    assert unwrapped.simulation.decision_period == 1.0


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"field": "3m"}, "unknown field '3m': use one of none, 1.25m, 2m"),
        ({"reward": "sum"}, "reward must be one of"),
        ({"decision_period": 0.3}, "decision_period .* multiple of the controller's"),
        ({"scenario": "roundabout"}, "no such scenario file"),
        ({"solver": "snopt"}, "solver must be 'fatrop' or 'ipopt'"),
    ],
)
def test_bad_arguments_are_clear_errors(kwargs, message):
    with pytest.raises(ValueError, match=message):
        make(**kwargs)


@pytest.mark.parametrize("reward", ["acc", "max"])
def test_gymnasium_env_checker_passes_without_warnings(reward):
    env = make(reward=reward).unwrapped
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        gymnasium_check_env(env, skip_render_check=False)
    assert [str(w.message) for w in caught] == []


def test_sb3_env_checker_passes_without_warnings():
    env = make().unwrapped
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3_check_env(env, warn=True)
    assert [str(w.message) for w in caught] == []


def rollout(env, actions, seed):
    trace = [env.reset(seed=seed)]
    for action in actions:
        observation, reward, terminated, truncated, info = env.step(action)
        trace.append((observation, reward, terminated, truncated, info))
        if terminated or truncated:
            break
    return trace


def assert_same(trace_a, trace_b, ignore=frozenset()):
    assert len(trace_a) == len(trace_b)
    for step_a, step_b in zip(trace_a, trace_b, strict=True):
        for part_a, part_b in zip(step_a, step_b, strict=True):
            if isinstance(part_a, dict):
                keys = set(part_a) - ignore
                assert keys == set(part_b) - ignore
                for key in keys:
                    assert repr(part_a[key]) == repr(part_b[key]), key
            else:
                np.testing.assert_array_equal(part_a, part_b)


def random_actions(count, seed):
    return np.random.default_rng(seed).uniform(-1, 1, size=(count, 2)).astype(np.float32)


def test_same_seed_and_actions_give_identical_episodes():
    actions = random_actions(15, seed=3)
    env_a = make().unwrapped
    env_b = make().unwrapped
    assert_same(rollout(env_a, actions, 7), rollout(env_b, actions, 7))
    # The same env again, after other episodes: nothing leaks from one episode to the next.
    rollout(env_a, random_actions(15, seed=4), 1)
    assert_same(rollout(env_a, actions, 7), rollout(env_b, actions, 7))


def test_wall_clock_times_stay_out_of_the_infos_in_their_own_channel():
    env = make().unwrapped
    trace = rollout(env, random_actions(6, seed=5), 0)
    assert not any("time_s" in key for *_, info in trace[1:] for key in info)
    timing = env.simulation.timing()
    assert timing.wall_time_s > 0.0
    assert timing.solve_time_max_s > 0.0


def test_pickled_env_continues_exactly_like_the_original():
    env = make().unwrapped
    actions = random_actions(8, seed=11)
    env.reset(seed=2)
    for action in actions[:3]:
        env.step(action)
    clone = pickle.loads(pickle.dumps(env))
    for action in actions[3:]:
        original, copy = env.step(action), clone.step(action)
        assert_same([original], [copy])
        if original[2] or original[3]:
            break


def test_observation_stays_in_its_space_and_episode_ends_by_30_s():
    env = make(reward="acc").unwrapped
    env.reset(seed=0)
    steps = 0
    for action in random_actions(40, seed=9):
        observation, _, terminated, truncated, info = env.step(action)
        steps += 1
        assert env.observation_space.contains(observation)
        if terminated or truncated:
            break
    assert steps <= 15
    assert info["sim_time"] <= 30.0 + 1e-9
    assert info["outcome"] in {"goal", "failure", "safe_contact", "timeout", "stall", "sut_error"}
    summary = info["summary"]
    assert summary.decision_steps == steps
    assert summary.controller_calls > 0
