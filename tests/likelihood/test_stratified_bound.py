"""benchmarks/stratified_bound.py: what stratifying on a discrete variable can gain at most."""

import importlib.util
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).parents[2] / "benchmarks" / "stratified_bound.py"


def load():
    spec = importlib.util.spec_from_file_location("stratified_bound", SCRIPT)
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    path = list(sys.path)
    try:
        spec.loader.exec_module(module)  # puts benchmarks/ on the path for proposal_bound
    finally:
        sys.path[:] = path
    return module


def stratum(value: float, probability: float, failures: int, episodes: int) -> dict[str, float]:
    return {
        "value": value,
        "probability": probability,
        "episodes": episodes,
        "failures": failures,
        "rate": failures / episodes,
    }


def test_a_rare_stratum_that_fails_caps_what_the_other_can_gain():
    # 12 failures in 20,000 episodes, 11 of them among a tenth of the people (who do not look).
    bound = load().bound
    rows = [stratum(0.0, 0.1, 11, 2_000), stratum(1.0, 0.9, 1, 18_000)]
    found = bound(rows, 12 / 20_000, 0.3, 10.0)
    assert found["monte_carlo_episodes"] == pytest.approx(18_507, abs=1)
    assert found["neyman_efficiency"] == pytest.approx(3.0, abs=0.05)
    need = {row["value"]: row["efficiency_needed"] for row in found["needed"]}
    assert need[0.0] == pytest.approx(51, abs=1)
    assert need[1.0] > 300
    # The one failure among the nine tenths alone takes most of a tenth of Monte Carlo's budget.
    alone = {row["value"]: row["episodes_for_its_share"] for row in found["needed"]}
    assert alone[1.0] == pytest.approx(1_389, abs=1)
    assert alone[1.0] < found["episodes_allowed"]


def test_without_a_failure_among_the_many_the_strata_alone_reach_tenfold():
    bound = load().bound
    rows = [stratum(0.0, 0.1, 11, 2_000), stratum(1.0, 0.9, 0, 18_000)]
    found = bound(rows, 11 / 20_000, 0.3, 10.0)
    # Every episode goes where the failures are: ten times, as the stratum is a tenth.
    assert found["neyman_efficiency"] == pytest.approx(10.0, abs=0.1)
    need = {row["value"]: row["efficiency_needed"] for row in found["needed"]}
    assert need[0.0] == pytest.approx(1.0, abs=0.01)
    assert "gains nothing" in need[1.0]


def test_a_target_out_of_reach_of_any_sampler_in_one_stratum_says_so():
    bound = load().bound
    rows = [stratum(0.0, 0.5, 10, 1_000), stratum(1.0, 0.5, 10, 1_000)]
    found = bound(rows, 0.01, 0.3, 10.0)
    need = {row["value"]: row["efficiency_needed"] for row in found["needed"]}
    assert need[0.0].startswith("impossible")
    assert need[1.0].startswith("impossible")
