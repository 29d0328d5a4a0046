"""The tester registry: the built-in testers by name, what each is, and the order of tables."""

import math

import pytest

from hazardhunt.testers import TESTERS, base, make_tester, register_tester
from hazardhunt.testers.base import reward_of
from hazardhunt.testers.random_sampling import RandomTester
from hazardhunt.testers.registry import colour_of, sort_testers


def test_the_built_in_testers_are_registered_with_their_reward_and_colour():
    assert list(TESTERS) == [
        "random",
        "ppo-acc",
        "ppo-max",
        "cem",
        "qd",
        "ppo-novelty",
        "portfolio",
    ]
    assert {name: entry.reward for name, entry in TESTERS.items()} == {
        "random": "max",
        "ppo-acc": "acc",
        "ppo-max": "max",
        "cem": "max",
        "qd": "max",
        "ppo-novelty": "max",
        "portfolio": "max",
    }
    colours = [entry.colour for entry in TESTERS.values()]
    assert len(set(colours)) == len(colours)
    assert all(entry.description for entry in TESTERS.values())


def test_a_registered_tester_is_built_by_name_with_the_runs_seed():
    tester = make_tester("random", 7, {"attempts": 3})
    assert isinstance(tester, RandomTester)
    assert (tester.name, tester.seed, tester.attempts) == ("random", 7, 3)
    for name, entry in TESTERS.items():
        assert reward_of(make_tester(name, 0)) == entry.reward


@pytest.mark.parametrize(
    ("name", "params", "message"),
    [
        ("genetic", {}, "unknown tester 'genetic': use one of random, ppo-acc, ppo-max"),
        ("random", {"attempt": 3}, "tester 'random': attempt: unknown parameter; the tester takes"),
        ("random", {"seed": 3}, "tester 'random': seed: is set by hazardhunt"),
    ],
)
def test_unknown_testers_and_parameters_are_clear_errors(name, params, message):
    with pytest.raises(ValueError, match=message):
        make_tester(name, 0, params)


@pytest.mark.parametrize(
    ("name", "params", "message"),
    [
        ("random", {"attempts": "many"}, "attempts: must be a whole number, not 'many'"),
        ("random", {"attempts": True}, "attempts: must be a whole number, not True"),
        ("random", {"attempts": 0}, "attempts: must be a whole number >= 1, not 0"),
        ("cem", {"smoothing": math.nan}, "smoothing: must be a finite number, not nan"),
        ("cem", {"n_workers": 1000}, "n_workers (now workers): must be less than or equal to 64"),
        ("qd", {"bins": [8, "3", 3]}, 'bins.1: must be a whole number, not "3"'),
        ("qd", {"bins": [1000, 1000, 3]}, "bins: must be one whole number >= 1 per measure"),
        ("ppo-max", {"learning_rate": 0}, "learning_rate: must be a number in (0, 1], not 0"),
        ("ppo-max", {"n_steps": "64"}, "n_steps: must be a whole number >= 1, not '64'"),
        ("ppo-max", {"gamma": 1.5}, "gamma: must be a number in (0, 1], not 1.5"),
        ("ppo-max", {"ent_coef": math.inf}, "ent_coef: must be a number >= 0, not inf"),
        ("ppo-max", {"normalize_advantage": 1}, "normalize_advantage: must be true or false"),
        ("ppo-acc", {"policy_kwargs": {"net_arch": [64, 0]}}, "policy_kwargs.net_arch: must be"),
        ("ppo-max", {"n_envs": 1000}, "n_envs: must be a whole number from 1 to 64, not 1000"),
    ],
)
def test_a_value_a_tester_cannot_use_is_an_error_naming_its_key(name, params, message):
    with pytest.raises(base.TesterParameterError) as caught:
        make_tester(name, 0, params)
    assert message in str(caught.value)
    assert caught.value.key == message.split(":")[0]


def test_a_name_is_registered_once_and_is_no_import_path():
    with pytest.raises(ValueError, match="already registered"):
        register_tester("random", RandomTester, reward="max", description="again", colour="k")
    with pytest.raises(ValueError, match="cannot name a tester"):
        register_tester("pkg:Tester", RandomTester, reward="max", description="", colour="k")
    assert "pkg:Tester" not in TESTERS


def test_registered_testers_come_first_in_registration_order_then_the_others_by_name():
    names = ["mine:Greedy", "ppo-max", "random", "charge", "ppo-max"]
    assert sort_testers(names) == ["random", "ppo-max", "charge", "mine:Greedy"]
    assert colour_of("random") == TESTERS["random"].colour
    assert colour_of("charge") == colour_of("charge")
