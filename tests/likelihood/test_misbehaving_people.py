"""A people model of one's own that ends the process, raises, returns nothing or gives the human
an action that is not a number: one line naming it, before anything is written when the trial
draw finds it, and never an encounter counted as tested."""

from pathlib import Path

import pytest

from hazardhunt.campaign.plugins import PluginSpec
from hazardhunt.likelihood.estimators import EstimatorParams
from hazardhunt.likelihood.people import ModelError
from hazardhunt.likelihood.run import EstimateConfig, EstimateError, EstimateRun
from tests.helpers import hazardhunt

ROOT = Path(__file__).parents[2]
MISBEHAVING = "tests.misbehaving"
CHEAP = "hazardhunt.benchmark.conservative:ConservativeController"


def estimate(out, people, *options):
    return hazardhunt(
        "estimate", "--scenario", "head-on", "--field", "none", "--method", "mc",
        "--episodes", 100, "--batch-size", 50, "--people", f"{MISBEHAVING}:{people}",
        "--controller", CHEAP, "--out", out, *options, cwd=ROOT,
    )  # fmt: skip


def config_of(people):
    return EstimateConfig(
        scenario="head-on",
        field="none",
        people=f"{MISBEHAVING}:{people}",
        controller=PluginSpec(path=CHEAP),
        estimator=EstimatorParams(method="mc", batch_size=50),
        episodes=100,
    )


TRIAL = "(on a trial draw before the estimate; nothing was written)"


@pytest.mark.parametrize(
    ("people", "says"),
    [
        ("ExitingPeople", "policy() raised SystemExit: 0 ("),
        ("NaNPeople", "its policy's action at 0 s: the human's action is [nan, 0.0], not two"),
    ],
)
def test_a_model_that_exits_or_walks_nan_stops_the_estimate_in_one_line(tmp_path, people, says):
    # SystemExit(0) used to end `estimate` with exit 0, having written config.json; a NaN
    # action, to be played as a human standing still: 100 encounters tested and safe.
    done = estimate(tmp_path / "estimate", people)
    assert done.returncode == 2, done.stderr
    [line] = done.stderr.strip().splitlines()
    assert line.startswith(f"error: people model '{MISBEHAVING}:{people}': {says}")
    assert line.endswith(TRIAL)
    assert done.stdout == ""
    assert not (tmp_path / "estimate").exists()


@pytest.mark.parametrize(
    ("people", "says"),
    [
        ("ThrowingPeople", "policy() raised BaseException: not an Exception ("),
        ("RaisingPolicyPeople", "policy() raised ValueError: no such aisle ("),
        ("RaisingActionPeople", "its policy raised ZeroDivisionError: division by zero ("),
        ("NonePolicyPeople", "policy() returned None, not a policy"),
        ("NoneActionPeople", "its policy's action at 0 s: the human's action is None, not two"),
    ],
)
def test_a_model_that_raises_or_returns_none_is_refused_before_anything_is_written(
    tmp_path, people, says
):
    # It used to be a traceback of some 80 lines, with config.json left behind.
    with pytest.raises(ModelError) as refused:
        EstimateRun(config_of(people), tmp_path / "estimate")
    assert str(refused.value).startswith(f"people model '{MISBEHAVING}:{people}': {says}")
    assert str(refused.value).endswith(TRIAL)
    assert not (tmp_path / "estimate").exists()


@pytest.mark.parametrize(
    ("people", "says"),
    [
        ("LateNaNPeople", "its policy's action at 1.2 s: the human's action is [nan, 0.0]"),
        ("LateExitingPeople", "its policy raised SystemExit: 0 ("),
    ],
)
def test_a_model_that_fails_once_its_human_walks_is_an_error_not_a_tested_encounter(
    tmp_path, people, says
):
    run = EstimateRun(config_of(people), tmp_path / "estimate")  # the trial draw passes
    with pytest.raises(EstimateError) as failed:
        run.run()
    assert str(failed.value).startswith(f"people model '{MISBEHAVING}:{people}': {says}")
    assert str(failed.value).endswith("; nothing of the estimate was kept")
    assert not (tmp_path / "estimate").exists()


def test_a_well_behaved_model_of_ones_own_is_estimated(tmp_path):
    done = estimate(tmp_path / "estimate", "WalkingPeople")
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "estimate" / "estimate.json").is_file()


@pytest.mark.slow
def test_a_model_that_exits_in_a_worker_process_is_the_same_one_line(tmp_path):
    done = estimate(tmp_path / "estimate", "LateExitingPeople", "--workers", 2)
    assert done.returncode == 1, done.stderr
    [line] = done.stderr.strip().splitlines()
    assert line.startswith(
        f"error: people model '{MISBEHAVING}:LateExitingPeople': its policy raised SystemExit: 0"
    )
    assert line.endswith("; nothing of the estimate was kept")
    assert not (tmp_path / "estimate").exists()
