"""The episode-level searchers (cem, qd) and the novelty bonus of ppo-novelty."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from stable_baselines3.common.vec_env import DummyVecEnv

from hazardhunt.campaign.config import ConfigError, PluginSpec, RunConfig, load_campaign
from hazardhunt.campaign.replay import replay_failure
from hazardhunt.campaign.run import record_run
from hazardhunt.env.agv import AGVEnv
from hazardhunt.spec.descriptors import descriptor_distance
from hazardhunt.testers import make_tester
from hazardhunt.testers.cem import coloured_noise
from hazardhunt.testers.ppo import NOVELTY_CAP, NoveltyBonus
from hazardhunt.testers.qd import DEFAULT_MEASURES
from hazardhunt.testers.spaces import DECISION_KINDS, DecisionSpace
from tests.helpers import run_tables

RECORDED = json.loads((Path(__file__).parents[1] / "spec" / "recorded_failures.json").read_text())


def test_the_qd_archive_is_kept_with_its_measures(seeded_run):
    run = seeded_run("qd", 0)
    archive = pd.read_parquet(run / "tester" / "archive.parquet")
    assert len(archive) > 3  # cells of different mechanisms
    assert set(DEFAULT_MEASURES) <= set(archive.columns)
    assert archive["bearing"].between(-np.pi, np.pi).all()
    episodes = pd.read_parquet(run / "episodes.parquet")
    # Every cell holds the best episode that fell into it: no cell beats the best episode.
    assert archive["objective"].max() == pytest.approx(episodes["max_risk"].max())


def head_on_run(directory: Path, tester: str, params: dict, episodes: int, seed: int = 0) -> dict:
    """Run ``tester`` with ``params`` on head-on without a field into ``directory``; its
    summary."""
    config = RunConfig(
        scenario="head-on",
        field="none",
        tester=tester,
        tester_params=params,
        seed=seed,
        episodes=episodes,
    )
    return record_run(config, directory)


def test_a_budget_that_ends_within_a_batch_is_spent_exactly(tmp_path):
    # 2 elites in a batch of 8; the last batch plays 1 episode.
    assert head_on_run(tmp_path / "run", "cem", {"population": 8}, episodes=9)["episodes"] == 9


@pytest.mark.slow
@pytest.mark.parametrize(
    "played",
    [{}, {"clear_path": True}, {"space": "aim"}, {"space": "mixed", "clear_path": True}],
)
def test_a_batch_on_two_worker_processes_gives_the_same_run(played, tmp_path):
    def run(workers):
        directory = tmp_path / f"run-{workers}"
        params = {"population": 6, "n_workers": workers} | played
        head_on_run(directory, "cem", params, episodes=12, seed=3)
        return run_tables(directory)

    (episodes_1, failures_1), (episodes_2, failures_2) = run(1), run(2)
    pd.testing.assert_frame_equal(episodes_1, episodes_2)
    pd.testing.assert_frame_equal(failures_1, failures_2)


@pytest.mark.parametrize(
    ("tester", "params", "message"),
    [
        (
            "cem",
            {"population": 1},
            r"population \(now batch_size\): must be greater than or equal to 2, not 1",
        ),
        ("cem", {"elite_fraction": 1.5}, "elite_fraction: must be less than or equal to 1"),
        ("cem", {"populaton": 10}, "populaton: unknown parameter"),
        ("cem", {"population": 8, "batch_size": 8}, "population: is the earlier name of"),
        ("qd", {"measures": ["bearing", "colour"]}, "measures: must be distinct names of"),
        ("qd", {"bins": [4, 4]}, "bins: must be one whole number >= 1 per measure"),
        ("qd", {"algorithm": "nsga"}, "algorithm: must be 'cma-me', 'cma-mae' or 'map-elites'"),
        ("qd", {"es": "adam"}, "es: must be 'cma_es', 'sep_cma_es' or 'lm_ma_es'"),
        (
            "qd",
            {"clear_path": "yes"},
            r'clear_path \(now space.detour\): must be true or false, not "yes"',
        ),
        (
            "cem",
            {"space": "sideways"},
            "space.kind: must be one of open, aim, route, ambush, mixed",
        ),
        ("qd", {"space": {"kind": ["aim", "aim"]}}, "space.kind: a list of kinds names each of"),
        ("cem", {"space": {"kind": ["mixed"]}}, r"space.kind: .* not \['mixed'\]"),
        ("cem", {"space": {"kind": "aim", "detours": True}}, "space.detours: unknown setting"),
        ("cem", {"space": 3, "clear_path": True}, "space: must be a table, not 3"),
        ("cem", {"space": {"kind": "route", "fit_offsets": 1}}, "space.fit_offsets: must be true"),
        ("cem", {"noise_exponent": -1}, "noise_exponent: must be greater than or equal to 0"),
        ("cem", {"n_workers": 65}, r"n_workers \(now workers\): must be less than or equal to 64"),
        ("cem", {"workers": 65}, "workers: must be less than or equal to 64, not 65"),
        ("qd", {"aim": True}, "aim: unknown parameter"),
        ("qd", {"probes": 1}, r"probes \(now space.plain_attacks\): must be true or false, not 1"),
        ("ppo-novelty", {"novelty": -1}, "novelty: must be a number from 0 to"),
        ("portfolio", {"arms": [{"name": "a", "method": "mcts"}]}, "arms.0.method: must be one"),
        (
            "portfolio",
            {"arms": [{"name": "a", "method": "cem", "params": {"batch_size": 1}}]},
            "arms: arm 'a': batch_size: must be greater than or equal to 2, not 1",
        ),
        (
            "portfolio",
            {"arms": [{"name": "a", "method": "cem", "params": {"population": "ten"}}]},
            r"arms: arm 'a': population \(now batch_size\): must be a whole number",
        ),
        (
            "portfolio",
            {"arms": [{"name": "b", "method": "boundary", "params": {"steps": 0}}]},
            "arms: arm 'b': steps: must be greater than or equal to 1, not 0",
        ),
    ],
)
def test_bad_search_parameters_are_clear_errors(tester, params, message):
    with pytest.raises(ValueError, match=message):
        make_tester(tester, 0, params)


LONG_EPISODES = """\
scenarios = ["crossing"]
fields = ["none"]
testers = ["qd"]
seeds = [0]
episodes = 1
[env]
episode_duration = 3600
decision_period = 0.2
"""


def test_qd_over_episodes_too_long_for_a_full_covariance_is_refused_before_it_starts(
    tmp_path,
):
    file = tmp_path / "long.toml"
    file.write_text(LONG_EPISODES)
    with pytest.raises(ConfigError) as error:
        load_campaign(file)
    assert str(error.value).startswith(
        f"{file}: tester.qd.es: episodes of 18,000 decisions make action sequences of 36,000 "
        "numbers, for which 2 emitter(s) with es='cma_es' and 72 cells need 58.0 GiB"
    )
    # A diagonal covariance fits: the same campaign with it loads.
    file.write_text(LONG_EPISODES + '[tester.qd]\nes = "sep_cma_es"\n')
    assert load_campaign(file).tester == {"qd": {"es": "sep_cma_es"}}


def test_qd_with_a_diagonal_covariance_searches_and_says_so(tmp_path):
    directory = tmp_path / "run"
    params = {"es": "sep_cma_es", "batch_size": 4}
    assert head_on_run(directory, "qd", params, episodes=16)["episodes"] == 16
    assert json.loads((directory / "tester" / "qd.json").read_text())["es"] == "sep_cma_es"
    assert len(pd.read_parquet(directory / "tester" / "archive.parquet")) > 1


@pytest.mark.parametrize("space", ["aim", "mixed", ["ambush", "aim"]])
def test_qd_over_closed_loop_decisions_finds_failures_that_replay_from_their_actions(
    space, tmp_path
):
    directory = tmp_path / "run"
    params = {"space": space, "batch_size": 4, "emitters": 3}
    assert head_on_run(directory, "qd", params, episodes=24)["episodes"] == 24
    assert json.loads((directory / "tester" / "qd.json").read_text())["space"]["kind"] == space
    failures = pd.read_parquet(directory / "failures.parquet")
    assert len(failures) > 0
    for episode in failures["episode"]:
        assert replay_failure(directory, int(episode)).matches


def test_the_novelty_bonus_pays_for_a_new_failure_not_for_the_same_one_again():
    example = RECORDED["examples"]["front/moving"]
    env = AGVEnv(example["scenario"], example["field"], decision_period=example["decision_period"])
    venv = NoveltyBonus(DummyVecEnv([lambda: env]), weight=100.0, neighbours=1)
    bonuses = []
    for _ in range(2):
        venv.reset()
        for action in example["actions"]:
            _, rewards, dones, infos = venv.step(np.array([action], dtype=np.float32))
            if dones[0]:
                summary = infos[0]["summary"]
                assert summary.outcome == "failure"
                bonuses.append(rewards[0] - summary.max_risk)
                break
    # The first failure is as novel as can be; the same failure again earns nothing.
    assert bonuses[0] == pytest.approx(100.0 * NOVELTY_CAP, rel=1e-6)
    assert bonuses[1] == pytest.approx(0.0, abs=1e-4)


def test_a_standing_and_a_walking_failure_at_the_same_place_are_different_mechanisms():
    walking = np.array([1.5, 0.8, 0.0, 1.4])  # bearing, robot speed, stop history, human speed
    standing = np.array([1.5, 0.8, 0.0, 0.0])
    faster = np.array([1.5, 0.8, 0.0, 1.5])
    assert descriptor_distance(walking, standing) == pytest.approx(1.0)
    assert descriptor_distance(walking, faster) == 0.0  # walking, however fast


def test_coloured_noise_keeps_its_spread_and_smooths_the_sequences():
    white = coloured_noise(np.random.default_rng(0), (2000, 15, 3), 0.0)
    np.testing.assert_array_equal(white, np.random.default_rng(0).standard_normal((2000, 15, 3)))
    for exponent in (1.0, 2.0):
        noise = coloured_noise(np.random.default_rng(0), (2000, 15, 3), exponent)
        assert noise.std(axis=0) == pytest.approx(np.ones((15, 3)), abs=0.08)
        neighbours = np.mean(noise[:, 1:] * noise[:, :-1])
        assert neighbours > 0.4  # one decision tells much about the next


def test_cem_with_coloured_noise_searches_and_says_so(tmp_path):
    directory = tmp_path / "run"
    params = {"population": 6, "noise_exponent": 2, "space": "route"}
    assert head_on_run(directory, "cem", params, episodes=12)["episodes"] == 12
    settings = json.loads((directory / "tester" / "cem.json").read_text())
    assert (settings["noise_exponent"], settings["space"]["kind"]) == (2.0, "route")


def test_the_plain_attacks_hold_one_decision_at_top_speed():
    counts = {}
    for kind in DECISION_KINDS:
        plans = DecisionSpace(kind).plain_attacks(15)
        counts[kind] = len(plans)
        assert plans.shape[1:] == (15, DecisionSpace(kind).size)
        assert (plans[:, :, 0] == 1.0).all()
        assert (plans == plans[:, :1, :]).all()  # one decision throughout
        assert len(np.unique(plans[:, 0], axis=0)) == len(plans)  # no two alike
    assert counts == {"open": 3, "aim": 12, "route": 9, "ambush": 18}
    # Among the aimed ones: walk into the robot's left and right sides; among the route's: stand
    # on it at its goal.
    aimed = DecisionSpace("aim").plain_attacks(1)[:, 0].tolist()
    assert [1.0, 0.5, -1.0] in aimed
    assert [1.0, -0.5, -1.0] in aimed
    assert [1.0, 1.0, 0.0] in DecisionSpace("route").plain_attacks(1)[:, 0].tolist()


@pytest.mark.parametrize(
    ("tester", "params"),
    [("cem", {"population": 12}), ("qd", {"batch_size": 4, "emitters": 1})],
)
def test_the_boundary_probes_catch_a_robot_that_docks_blind(tester, params, tmp_path):
    # DockingMode stops for nobody in its last 3 m; a human waiting on its route at the goal,
    # one of the route space's boundary values, is run into. In the crossing the goal lies
    # behind a shelf block from where the human starts.
    def run(probes: bool, name: str) -> dict:
        config = RunConfig(
            scenario="crossing",
            field="none",
            tester=tester,
            tester_params={**params, "space": "route", "clear_path": True, "probes": probes},
            seed=0,
            episodes=12,
            controller=PluginSpec(path="hazardhunt.benchmark.conservative:DockingMode"),
        )
        return record_run(config, tmp_path / name)

    probed = run(True, "probed")
    assert probed["failures"] > 0
    assert probed["first_failure_episode"] < len(DecisionSpace("route").plain_attacks(1))
    settings = json.loads((tmp_path / "probed" / "tester" / f"{tester}.json").read_text())
    assert settings["space"]["plain_attacks"] is True
    assert run(False, "unprobed")["failures"] == 0


COMPILED_ONCE = """
import numpy as np
from ribs.emitters.opt import CMAEvolutionStrategy
from hazardhunt.testers.qd import compile_once
compile_once()
es = CMAEvolutionStrategy(sigma0=0.5, solution_dim=6, batch_size=4, seed=0, dtype=np.float64)
es.reset(np.zeros(6))
es.ask()
es.tell(np.arange(4), np.arange(4.0), 2)
es.ask()
helpers = (CMAEvolutionStrategy._transform_and_check_sol, CMAEvolutionStrategy._calc_cov_update)
print(sum(len(helper.stats.cache_hits) for helper in helpers))
"""


def test_qd_compiles_pyribs_helpers_once_per_machine_not_once_per_run():
    # Every run (or campaign worker) is a new process; numba compiling pyribs' CMA-ES helpers
    # in each cost about 3 s. The second process loads them from numba's cache on disk.
    runs = [
        subprocess.run([sys.executable, "-c", COMPILED_ONCE], capture_output=True, text=True)
        for _ in range(2)
    ]
    assert all(run.returncode == 0 for run in runs), runs[-1].stderr
    assert int(runs[1].stdout) == 2  # both helpers loaded from the cache


WITHOUT_TORCH = """
import sys
from hazardhunt.testers.qd import compile_once
compile_once()
print("torch" in sys.modules)
import torch
from ribs.archives import GridArchive
print(float(torch.ones(3).sum()), GridArchive.__name__)
"""


def test_qd_loads_pyribs_without_torch_and_torch_still_loads_after():
    # pyribs imports torch where it can (1.3 s of every run's start) though a search never
    # passes it a tensor; a process that needs torch later (PPO) still gets it.
    run = subprocess.run([sys.executable, "-c", WITHOUT_TORCH], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == ["False", "3.0", "GridArchive"]
