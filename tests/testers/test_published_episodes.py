"""The search configurations that published results were measured with play the same episodes.

``published_episodes.json`` holds, per configuration, a digest of the actions of the first 40
episodes it played against the built-in NMPC on the crossing without a field (seed 1), and their
outcomes, recorded before the searchers became ask/tell samplers. Each configuration is played in
the form the published commands give it (``population``, ``clear_path``, ``probes``) and in
today's form (``batch_size``, ``space = {kind, detour, plain_attacks}``).
"""

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from hazardhunt.campaign.config import RunConfig
from hazardhunt.campaign.simulations import simulation_of
from hazardhunt.env.agv import AGVEnv
from hazardhunt.testers import EpisodeRecord, make_tester
from hazardhunt.testers.base import EpisodeRecorder

PUBLISHED = json.loads((Path(__file__).parent / "published_episodes.json").read_text())


def todays_form(params: dict) -> dict:
    """The published parameters in today's names."""
    renamed = {"population": "batch_size", "n_workers": "workers", "sigma0": "initial_spread"}
    today = {renamed.get(key, key): value for key, value in params.items()}
    space = {"kind": today.pop("space", "open")}
    if "clear_path" in today:
        space["detour"] = today.pop("clear_path")
    if "probes" in today:
        space["plain_attacks"] = today.pop("probes")
    return today | {"space": space}


def played(tester: str, params: dict, episodes: int, seed: int) -> tuple[str, list]:
    config = RunConfig(
        scenario="crossing",
        field="none",
        tester=tester,
        tester_params=params,
        seed=seed,
        episodes=episodes,
    )
    records: list[EpisodeRecord] = []
    recorder = EpisodeRecorder(AGVEnv.wrapping(simulation_of(config)), records.append)
    make_tester(tester, seed, params).explore(recorder, episodes)
    digest = hashlib.sha256()
    for record in records:
        digest.update(np.asarray(record.result.actions, dtype=np.float32).tobytes())
    return digest.hexdigest(), [record.result.summary.outcome for record in records]


def check(published: dict, params: dict) -> None:
    digest, outcomes = played(published["tester"], params, published["episodes"], published["seed"])
    assert outcomes == published["outcomes"]
    assert digest == published["actions_sha256"]


def test_cem_mixed_with_detour_and_plain_attacks_plays_the_published_episodes():
    published = PUBLISHED[2]
    assert published["params"]["space"] == "mixed"
    check(published, todays_form(published["params"]))


@pytest.mark.slow
@pytest.mark.parametrize("form", ["published", "today"])
@pytest.mark.parametrize("index", range(len(PUBLISHED)))
def test_every_published_configuration_plays_its_episodes(index, form):
    published = PUBLISHED[index]
    params = published["params"]
    check(published, params if form == "published" else todays_form(params))
