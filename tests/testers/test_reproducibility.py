"""Every tester spends exactly its budget, and one seed reproduces a run."""

import json

import pandas as pd
import pytest

from tests.helpers import run_tables
from tests.testers.conftest import CASES, EPISODES


@pytest.mark.parametrize("tester", list(CASES))
def test_stops_at_exactly_the_budget(seeded_run, tester):
    run = seeded_run(tester, 0)
    episodes, _ = run_tables(run)
    assert episodes["episode"].tolist() == list(range(EPISODES))
    assert json.loads((run / "summary.json").read_text())["episodes"] == EPISODES


@pytest.mark.parametrize("tester", list(CASES))
def test_same_seed_gives_identical_run_tables(seeded_run, tester):
    episodes, failures = run_tables(seeded_run(tester, 0))
    episodes_again, failures_again = run_tables(seeded_run(tester, 0, copy=1))
    assert len(failures) > 0, "the comparison needs failures to mean something"
    pd.testing.assert_frame_equal(episodes, episodes_again)
    pd.testing.assert_frame_equal(failures, failures_again)


@pytest.mark.parametrize("tester", list(CASES))
def test_different_seeds_give_different_run_tables(seeded_run, tester):
    episodes, failures = run_tables(seeded_run(tester, 0))
    episodes_other, failures_other = run_tables(seeded_run(tester, 1))
    assert not episodes.equals(episodes_other)
    assert not failures.equals(failures_other)
