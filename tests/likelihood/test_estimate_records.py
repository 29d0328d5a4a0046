"""What an estimate records and refuses: the models its batches were played on (a changed
people, uncertainties or plug-in file is not mixed in), no symbolic link in its directory, no
likelihood that is not a number; and the report of a received estimate, which names a damaged
draw, a changed model or an unreadable summary in one line, and says so when a most likely
failure no longer fails."""

import json
import shutil
import warnings
from importlib.resources import files
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hazardhunt.analysis.risk_report import write_estimate_report
from hazardhunt.campaign.config import EnvOptions
from hazardhunt.errors import InputError
from hazardhunt.likelihood.distributions import Dimension
from hazardhunt.likelihood.estimators import EstimatorParams
from hazardhunt.likelihood.people import ModelError, WalkerModel
from hazardhunt.likelihood.results import summarise, write_summary
from hazardhunt.likelihood.run import EstimateConfig, EstimateRun
from hazardhunt.likelihood.toy import ClosedFormEncounters
from tests.helpers import hazardhunt

ROOT = Path(__file__).parents[2]
HERE = "tests.likelihood.test_estimate_records"
FAST_SUT = ["--controller", "hazardhunt.benchmark.conservative:ConservativeController"]
UNCERTAINTIES = (
    '[effects]\nbrake_deceleration = { distribution = "uniform", low = 5.5, high = 8.5 }\n'
)


def built_in_people(path):
    path.write_text(files("hazardhunt.likelihood").joinpath("people.toml").read_text())
    return path


def files_in(directory):
    return {p.relative_to(directory): p.read_bytes() for p in directory.rglob("*") if p.is_file()}


def toy_config(episodes=300, **models):
    return EstimateConfig(
        episodes=episodes, seed=3, estimator=EstimatorParams(method="mc", batch_size=100), **models
    )


@pytest.mark.slow
def test_resuming_after_the_people_file_changed_is_refused_naming_it(tmp_path):
    people = built_in_people(tmp_path / "people.toml")
    arguments = [
        "estimate", "--scenario", "head-on", "--field", "none", "--episodes", 100,
        "--batch-size", 50, "--people", people, *FAST_SUT, "--out", tmp_path / "estimate",
    ]  # fmt: skip
    done = hazardhunt(*arguments, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    written = files_in(tmp_path / "estimate")
    # Those who look out for the robot, now all of them: another model of people.
    model = people.read_text()
    people.write_text(model.replace('"bernoulli", p = 0.9', '"bernoulli", p = 1.0'))
    assert people.read_text() != model
    for more in (100, 150):  # resumed, or extended
        arguments[arguments.index("--episodes") + 1] = more
        refused = hazardhunt(*arguments, cwd=ROOT)
        assert refused.returncode == 2, refused.stderr
        [line] = refused.stderr.strip().splitlines()
        assert line.startswith(f"error: {people}: changed since the batches in ")
        assert "resuming would mix two models in one estimate" in line
        assert files_in(tmp_path / "estimate") == written


def test_a_changed_model_file_or_plug_in_model_is_not_mixed_in(tmp_path, monkeypatch):
    toy = ClosedFormEncounters()
    people = built_in_people(tmp_path / "people.toml")
    uncertainties = tmp_path / "uncertainties.toml"
    uncertainties.write_text(UNCERTAINTIES)
    config = toy_config(people=str(people), uncertainties=str(uncertainties))
    EstimateRun(config, tmp_path / "u", source=toy).run()
    EstimateRun(config, tmp_path / "u", source=toy).run()  # unchanged: resumes
    written = files_in(tmp_path / "u")
    uncertainties.write_text(UNCERTAINTIES.replace("5.5, high = 8.5", "1.0, high = 1.5"))
    for extended in (config, config.model_copy(update={"episodes": 500})):
        with pytest.raises(InputError) as error:
            EstimateRun(extended, tmp_path / "u", source=toy)
        assert str(error.value) == (
            f"{uncertainties}: changed since the batches in {tmp_path / 'u'} were played on it "
            "(its SHA-256 is not the one config.json records for uncertainties): resuming "
            "would mix two models in one estimate; restore it, or choose another --out for an "
            "estimate of it as it is now"
        )
    assert files_in(tmp_path / "u") == written
    uncertainties.write_text(UNCERTAINTIES)
    people.write_text(people.read_text().replace('"bernoulli", p = 0.9', '"bernoulli", p = 1.0'))
    with pytest.raises(InputError, match=r"people\.toml: changed since the batches"):
        EstimateRun(config, tmp_path / "u", source=toy)
    # A model of one's own: the source of its module.
    monkeypatch.chdir(tmp_path)
    module = tmp_path / "my_people.py"
    module.write_text(
        "from hazardhunt.likelihood.people import WalkerModel\n\n"
        "class People(WalkerModel):\n    pass\n"
    )
    config = toy_config(people="my_people:People")
    EstimateRun(config, tmp_path / "p", source=toy).run()
    module.write_text(module.read_text() + "\n# looks = 1.0\n")
    with pytest.raises(InputError, match=r"^my_people:People: changed since the batches"):
        EstimateRun(config, tmp_path / "p", source=toy)


def test_an_estimate_of_an_earlier_version_resumes_and_records_its_models_from_then_on(tmp_path):
    toy = ClosedFormEncounters()
    uncertainties = tmp_path / "uncertainties.toml"
    uncertainties.write_text(UNCERTAINTIES)
    config = toy_config(episodes=500, uncertainties=str(uncertainties))
    whole = EstimateRun(config, tmp_path / "whole", source=toy).run()

    def stop_after_two(done, total):
        if done >= 200:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        EstimateRun(config, tmp_path / "cut", source=toy).run(stop_after_two)
    path = tmp_path / "cut" / "config.json"
    written = json.loads(path.read_text())
    del written["digests"]  # as an earlier version wrote it
    path.write_text(json.dumps(written))
    with pytest.warns(UserWarning, match="written by an earlier version, which recorded no digest"):
        resumed = EstimateRun(config, tmp_path / "cut", source=toy).run()
    pd.testing.assert_frame_equal(resumed, whole)
    assert (
        json.loads(path.read_text())["digests"]
        == json.loads((tmp_path / "whole" / "config.json").read_text())["digests"]
    )
    uncertainties.write_text(UNCERTAINTIES.replace("8.5", "9.5"))
    with pytest.raises(InputError, match="changed since the batches"):
        EstimateRun(config, tmp_path / "cut", source=toy)


def test_an_estimate_holding_a_symbolic_link_is_refused_and_nothing_is_written_through_it(
    tmp_path,
):
    toy = ClosedFormEncounters()
    received = tmp_path / "received"
    EstimateRun(toy_config(), received, source=toy).run()
    elsewhere = tmp_path / "elsewhere"
    (received / "batches").rename(elsewhere)
    (received / "batches").symlink_to(elsewhere)
    before = sorted(p.name for p in elsewhere.iterdir())
    for config in (toy_config(), toy_config(episodes=500)):  # resumed, or extended
        with pytest.raises(InputError) as error:
            EstimateRun(config, received, source=toy).run()
        assert str(error.value) == (
            f"{received}: batches is a symbolic link (an estimate holds none; it is not "
            "followed): put what it links to in its place"
        )
    assert sorted(p.name for p in elsewhere.iterdir()) == before
    assert json.loads((received / "config.json").read_text())["episodes"] == 300
    # The report reads nothing through it either.
    shown = hazardhunt("report", received, cwd=ROOT)
    assert shown.returncode == 2, shown.stderr
    assert shown.stderr.strip() == f"error: {error.value}"
    assert not (received / "report").exists()


class NotANumberWhenFast(Dimension):
    """A walking speed whose density is not a number above 1.499 m/s, where none of the 64
    draws checked before an estimate falls and the estimate's 40th draw does."""

    def log_prob(self, value):
        return float("nan") if value > 1.499 else super().log_prob(value)


class NotANumberPastTheCheck(WalkerModel):
    def __init__(self, scenario):
        super().__init__(scenario)
        speed, *others = self.dimensions
        self.dimensions = (NotANumberWhenFast(speed.name, speed.distribution, speed.table), *others)


def test_a_likelihood_that_is_not_a_number_past_the_checked_draws_gives_no_estimate(tmp_path):
    out = tmp_path / "estimate"
    done = hazardhunt(
        "estimate", "--scenario", "head-on", "--field", "none", "--episodes", 100,
        "--batch-size", 50, "--people", f"{HERE}:NotANumberPastTheCheck", *FAST_SUT,
        "--out", out, cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    [line] = done.stderr.strip().splitlines()
    assert line == (
        f"error: people model {HERE}:NotANumberPastTheCheck: speed: log_prob is nan on its own "
        "draw 1.4997133155007416 (episode 39, past the 64 draws checked before the estimate); "
        "no estimate is given, and nothing of it was kept"
    )
    assert "failures per" not in done.stdout
    assert not out.exists()


def test_a_stored_likelihood_that_is_not_a_number_gives_no_estimate(tmp_path):
    config = toy_config()
    table = EstimateRun(config, tmp_path, source=ClosedFormEncounters()).run()
    table.loc[7, "log_p"] = np.nan  # as a batch played before such draws were refused holds
    with pytest.raises(ModelError, match=r"log_prob is nan on the draw of episode 7: no estimate"):
        summarise(config, table, 4.0)


@pytest.fixture(scope="module")
def received(tmp_path_factory):
    """A finished estimate of the built-in SUT with a people file of its own, with failures
    to replay: 100 episodes of at most 14 s."""
    here = tmp_path_factory.mktemp("received")
    config = EstimateConfig(
        scenario="head-on",
        field="none",
        people=str(built_in_people(here / "people.toml")),
        env=EnvOptions(decision_period=0.2, episode_duration=14.0),
        episodes=100,
        estimator=EstimatorParams(method="mc", batch_size=50),
    )
    run = EstimateRun(config, here / "estimate")
    table = run.run()
    write_summary(here / "estimate", summarise(config, table, run.source.threshold))
    return here


def copy_of(received, tmp_path):
    shutil.copytree(received, tmp_path, dirs_exist_ok=True)
    estimate = tmp_path / "estimate"
    config = json.loads((estimate / "config.json").read_text())
    config["people"] = str(tmp_path / "people.toml")  # as it names it here
    (estimate / "config.json").write_text(json.dumps(config))
    return estimate


@pytest.mark.slow
def test_a_most_likely_failure_that_no_longer_fails_is_shown_as_such(received, tmp_path):
    estimate = copy_of(received, tmp_path)
    # The SUT changed since: a protective field now stops the robot before the human.
    config = json.loads((estimate / "config.json").read_text())
    (estimate / "config.json").write_text(json.dumps(config | {"field": "1.25m"}))
    summary = json.loads((estimate / "estimate.json").read_text())
    likeliest = summary["most_likely"]["all"]  # one failure to draw, for a short test
    summary["most_likely"] = {"all": likeliest}
    (estimate / "estimate.json").write_text(json.dumps(summary))
    with warnings.catch_warnings(record=True) as warned:
        warnings.simplefilter("always")
        page = write_estimate_report(estimate).read_text()
    said = (
        f"Episode {likeliest['episode']} failed when the estimate played it; replayed from its "
        "draw, it ended in a safe contact: the SUT or the model has changed since"
    )
    assert said in page
    assert (
        f"all: episode {likeliest['episode']} (replayed: ended in a safe contact, no longer" in page
    )
    assert any(
        f"the most likely failure of all (episode {likeliest['episode']}) ended in a safe "
        "contact when replayed from its draw: the SUT or the model has changed" in str(w.message)
        for w in warned
    )
