"""Testers written against earlier versions keep working (CHANGELOG.md)."""

from pathlib import Path

import numpy as np
import pandas as pd

from hazardhunt.campaign.config import PluginSpec, RunConfig
from hazardhunt.campaign.run import record_run
from hazardhunt.sim.simulation import Simulation
from hazardhunt.sut.pursuit import PursuitController
from hazardhunt.testers.spaces import DecisionSpace

EARLIER_TESTER = '''
import numpy as np


class AimedBatches:
    """Plays its batches with env.evaluate_batch(sequences, workers, clear_path, space), as
    testers did before the episode evaluator."""

    name = "aimed-batches"

    def __init__(self, seed):
        self.rng = np.random.default_rng(seed)
        self.played = []

    def explore(self, env, episodes):
        while env.episodes_done < episodes:
            count = min(3, episodes - env.episodes_done)
            batch = list(self.rng.uniform(-1.0, 1.0, (count, env.horizon, 3)))
            self.played += env.evaluate_batch(batch, 1, True, "aim")

    def save(self, directory):
        directory.mkdir(parents=True, exist_ok=True)
        (directory / "aims.npy").write_bytes(b"")
'''


def test_a_tester_that_plays_batches_with_evaluate_batch_still_runs(tmp_path):
    (tmp_path / "earlier_tester.py").write_text(EARLIER_TESTER)
    config = RunConfig(
        scenario="crossing",
        field="none",
        tester="aimed-batches",
        tester_plugin=PluginSpec(path="earlier_tester:AimedBatches", search_path=[str(tmp_path)]),
        seed=4,
        episodes=7,
        controller=PluginSpec(path="hazardhunt.sut.pursuit:PursuitController"),
    )
    summary = record_run(config, tmp_path / "run")
    assert summary["episodes"] == 7
    # Its episodes are those of the aimed decision space walking round obstacles.
    simulation = Simulation.build("crossing", "none", controller=PursuitController())
    rng = np.random.default_rng(4)
    first = rng.uniform(-1.0, 1.0, (3, simulation.horizon, 3))[0]
    expected = DecisionSpace("aim", detour=True).play(simulation, first, False)
    episodes = pd.read_parquet(Path(tmp_path / "run" / "episodes.parquet"))
    assert episodes["max_risk"].iloc[0] == expected.summary.max_risk
