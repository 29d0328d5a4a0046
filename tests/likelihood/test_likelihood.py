"""How likely a failure is: the people model and the SUT's uncertainties with exact likelihoods,
episodes that replay from their draw, estimators whose intervals cover a known probability,
estimates that resume, and bad input refused before anything runs."""

import json
from importlib.resources import files
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from hazardhunt.likelihood.distributions import Dimension, DistributionError, dimension
from hazardhunt.likelihood.encounters import Draw, Played, SimulationEncounters
from hazardhunt.likelihood.estimators import EstimatorParams, clopper_pearson
from hazardhunt.likelihood.people import (
    ModelError,
    WalkerModel,
    load_model,
    model_log_prob,
    model_sample,
)
from hazardhunt.likelihood.proposal import Proposal
from hazardhunt.likelihood.results import summarise
from hazardhunt.likelihood.run import EstimateConfig, EstimateRun, default_batch_size, draw_of
from hazardhunt.likelihood.toy import ClosedFormEncounters
from hazardhunt.likelihood.uncertainty import load_uncertainties
from hazardhunt.sim.effects import SutEffects
from hazardhunt.sim.simulation import Simulation
from tests.helpers import hazardhunt

ROOT = Path(__file__).parents[2]
HERE = "tests.likelihood.test_likelihood"


@pytest.mark.parametrize(
    ("table", "says"),
    [
        ({"distribution": "gamma", "a": 1}, "distribution must be one of"),
        ({"distribution": "normal", "mean": 0}, "normal needs sd"),
        ({"distribution": "normal", "mean": 0, "sd": -1}, "sd must be > 0"),
        ({"distribution": "uniform", "low": 2, "high": 1}, "low must be < high"),
        ({"distribution": "bernoulli", "p": 1.5}, "p must be in [0, 1]"),
        ({"distribution": "exponential", "mean": 1, "rate": 2}, "not rate"),
    ],
)
def test_an_invalid_distribution_names_the_variable_and_the_problem(table, says):
    with pytest.raises(DistributionError) as error:
        dimension("people.toml: behaviour", "speed", table)
    assert str(error.value).startswith("people.toml: behaviour: speed: ")
    assert says in str(error.value)


def walker_simulation(scenario="head-on", field="none"):
    return Simulation.build(scenario, field, decision_period=0.2)


def test_the_built_in_walkers_have_finite_likelihoods_and_walk_to_their_place():
    simulation = walker_simulation("crossing")
    model = load_model(None, simulation.scenario)
    rng = np.random.default_rng(0)
    values = model_sample(model, rng)
    assert np.isfinite(model_log_prob(model, values))
    assert model_log_prob(model, {**values, "speed": 2.0}) == -np.inf  # faster than anyone walks
    # Someone who sets off at once, never pauses and walks to the north end of the cross aisle
    # (the third place) crosses the robot's aisle: they end north of it.
    values.update(start_delay=0.0, pauses=0.0, looks=1.0, destination=2.0, speed=1.3)
    result = simulation.simulate(model.policy(values, simulation))
    assert result.summary.outcome in ("goal", "timeout")
    assert simulation.human_pose[1] > 17.0


def test_a_model_file_without_places_for_the_floor_is_refused(tmp_path):
    text = (ROOT / "src/hazardhunt/likelihood/people.toml").read_text()
    path = tmp_path / "people.toml"
    path.write_text(text.replace("[[places.shopfloor]]", "[[places.other]]"))
    with pytest.raises(ModelError, match=r"no \[\[places.shopfloor\]\]"):
        WalkerModel(walker_simulation().scenario, path)


@pytest.mark.parametrize(
    ("change", "says"),
    [
        pytest.param(
            lambda text: "behaviour = 5\n" + text[text.index("[walking]") :],
            "behaviour: must be a table, not 5",
            id="behaviour-a-number",
        ),
        pytest.param(
            lambda text: "places = { shopfloor = 3 }\n" + text[: text.index("[[places")],
            "places.shopfloor: must be a list of places ([[places.shopfloor]]), not 3",
            id="places-a-number",
        ),
        pytest.param(
            lambda text: text.replace("weight = 1.0", "weight = -1.0", 1),
            "places.shopfloor[0].weight: must be a number >= 0, not -1.0",
            id="negative-weight",
        ),
    ],
)
def test_a_model_file_of_the_wrong_shape_names_the_file_and_the_key(tmp_path, change, says):
    path = tmp_path / "people.toml"
    path.write_text(change((ROOT / "src/hazardhunt/likelihood/people.toml").read_text()))
    done = hazardhunt(
        "estimate", "--scenario", "head-on", "--field", "none", "--method", "mc",
        "--episodes", 100, "--people", path, "--out", tmp_path / "estimate", cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 2
    [line] = done.stderr.strip().splitlines()
    assert f"{path}: {says}" in line
    assert not (tmp_path / "estimate").exists()


class Elsewhere(Dimension):
    """Draws from [0, 1], scores as if it drew from [2, 3]."""

    def log_prob(self, value):
        return float(stats.uniform(2.0, 1.0).logpdf(value))


class ZeroLikelihood:
    """A model whose every draw has likelihood zero under itself."""

    def __init__(self, scenario):
        table = {"distribution": "uniform", "low": 0.0, "high": 1.0}
        self.dimensions = (Elsewhere("speed", stats.uniform(0.0, 1.0), table),)

    def policy(self, values, simulation):
        return lambda sim: np.array([-1.0, 0.0])


def test_a_model_whose_likelihood_is_not_finite_on_its_own_draws_is_refused():
    with pytest.raises(ModelError, match="speed: log_prob is -inf on its own draw"):
        load_model(f"{HERE}:ZeroLikelihood", walker_simulation().scenario)


def test_an_uncertainty_that_can_leave_its_range_is_refused(tmp_path):
    path = tmp_path / "uncertainties.toml"
    path.write_text(
        '[effects]\ndropped_frames = { distribution = "normal", mean = 0.1, sd = 0.1 }\n'
    )
    with pytest.raises(ModelError, match="dropped_frames: its values must lie in"):
        load_uncertainties(str(path))
    path.write_text('[effects]\nwheel_slip = { distribution = "uniform", low = 0, high = 1 }\n')
    with pytest.raises(ModelError, match="unknown wheel_slip"):
        load_uncertainties(str(path))


@pytest.mark.parametrize(
    ("line", "message"),
    [
        (
            'speed = { distribution = "truncnorm", mean = 5.5, sd = 0.2, low = 5.0, high = 6.0 }',
            "behaviour: speed: its values must lie in [0, 1.5], but the distribution reaches "
            "[5, 6]",
        ),
        (
            'start_delay = { distribution = "normal", mean = 5.0, sd = 1.0 }',
            "behaviour: start_delay: its values must lie in [0, inf]",
        ),
        (
            'looks = { distribution = "uniform", low = 0.0, high = 2.0 }',
            "behaviour: looks: its values must lie in [0, 1]",
        ),
    ],
)
def test_a_behaviour_the_simulated_human_cannot_play_is_refused(tmp_path, line, message):
    built_in = (files("hazardhunt.likelihood") / "people.toml").read_text()
    name = line.split(" = ", 1)[0]
    lines = [line if row.startswith(f"{name} = ") else row for row in built_in.splitlines()]
    path = tmp_path / "people.toml"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ModelError) as refused:
        load_model(str(path), walker_simulation().scenario)
    assert str(refused.value).startswith(f"{path}: behaviour: {name}")
    assert message in str(refused.value)


def test_nominal_effects_play_the_nominal_episode_and_effects_replay_exactly():
    simulation = walker_simulation()
    model = load_model(None, simulation.scenario)
    values = model_sample(model, np.random.default_rng(3))
    values.update(start_delay=0.0, looks=0.0, pauses=0.0, destination=0.0)  # walks at the robot
    nominal = simulation.simulate(model.policy(values, simulation))
    simulation.effects = SutEffects()
    assert simulation.simulate(model.policy(values, simulation)).summary == nominal.summary
    simulation.effects = SutEffects(0.08, 0.2, 0.05, 0.1, 3.0, seed=11)
    noisy = simulation.simulate(model.policy(values, simulation))
    again = simulation.simulate(model.policy(values, simulation))
    assert noisy.summary != nominal.summary
    assert again.summary == noisy.summary
    assert np.array_equal(again.actions, noisy.actions)


def test_a_weaker_brake_stops_later():
    simulation = Simulation.build("head-on", "2m", decision_period=0.2)
    stand = [np.array([-1.0, 0.0])] * 150
    strong = simulation.simulate(stand)
    simulation.effects = SutEffects(brake_deceleration=1.0)
    weak = simulation.simulate(stand)
    assert weak.summary.min_clearance < strong.summary.min_clearance


def toy_estimate(tmp_path, seed, episodes=600, method="ce", source=None):
    config = EstimateConfig(
        episodes=episodes, seed=seed, estimator=EstimatorParams(method=method, batch_size=100)
    )
    table = EstimateRun(
        config, tmp_path / f"toy-{seed}", source=source or ClosedFormEncounters()
    ).run()
    return config, table


def cross_entropy_repeated(tmp_path, toy, repetitions=30):
    """How many of the repetitions' intervals covered the truth, and their estimates."""
    covered, estimates = 0, []
    for seed in range(repetitions):
        config, table = toy_estimate(tmp_path, seed, episodes=1000, source=toy)
        result = summarise(config, table, toy.threshold)["probability"]
        covered += result["low"] <= toy.probability <= result["high"]
        estimates.append(result["probability"])
    return covered, estimates


def test_an_importance_sampling_estimate_says_what_its_interval_does_not_cover(tmp_path):
    config, table = toy_estimate(tmp_path, 0)
    caveat = summarise(config, table, 4.0)["caveat"]
    assert "missing" in caveat
    assert "--method mc" in caveat
    config, table = toy_estimate(tmp_path, 1, method="mc")
    assert summarise(config, table, 4.0)["caveat"] is None  # exact: nothing to say


def test_cross_entropy_intervals_cover_a_known_probability(tmp_path):
    toy = ClosedFormEncounters(threshold=3.5)
    covered, estimates = cross_entropy_repeated(tmp_path, toy)
    assert toy.probability < 1e-3  # rare: plain Monte Carlo at 1,000 episodes sees none mostly
    assert covered >= 26  # the normal interval on weights: about 92 % measured
    assert abs(np.mean(estimates) / toy.probability - 1.0) < 0.25


def test_cross_entropy_tilts_the_variables_that_matter_and_leaves_the_others():
    toy = ClosedFormEncounters(threshold=4.0, p_looks=0.9, idle=4)
    rng = np.random.default_rng(0)
    draws = [draw_of_toy(toy, rng) for _ in range(5000)]
    elites = [x for x in draws if x["a"] + x["b"] - 2.0 * x["looks"] >= 2.0]
    start = Proposal.model(toy.dimensions)
    fitted = start.fitted(elites, np.ones(len(elites)), 1.0, 0.1, penalty=2.0)
    assert fitted.shapes["a"][0] > 2 * fitted.shapes["a"][1]  # towards large a
    assert fitted.probabilities["looks"][0] > 0.5  # mostly inattentive
    for name in ("idle0", "idle2"):
        assert fitted.shapes[name] == (1.0, 1.0)
    for name in ("idle1", "idle3"):
        assert fitted.probabilities[name] == pytest.approx((0.8, 0.2))
    # Without the penalty, the noise of the elites tilts them all.
    loose = start.fitted(elites, np.ones(len(elites)), 1.0, 0.1, penalty=0.0)
    assert all(loose.shapes[name] != (1.0, 1.0) for name in ("idle0", "idle2"))


def draw_of_toy(toy, rng):
    return {d.name: float(d.distribution.rvs(random_state=rng)) for d in toy.dimensions}


@pytest.mark.slow
def test_cross_entropy_covers_a_known_probability_among_idle_variables(tmp_path):
    toy = ClosedFormEncounters(threshold=4.0, p_looks=0.9, idle=9)  # 12 variables, 3 matter
    covered, estimates = cross_entropy_repeated(tmp_path, toy)
    assert covered >= 26
    assert abs(np.median(estimates) / toy.probability - 1.0) < 0.2


def test_splitting_reaches_a_rare_probability_with_few_episodes(tmp_path):
    toy = ClosedFormEncounters(threshold=5.0, p_looks=0.0)  # p = 2e-4, no discrete dimension
    covered, estimates, played = 0, [], []
    for seed in range(20):
        config = EstimateConfig(
            episodes=2000,
            seed=seed,
            estimator=EstimatorParams(method="splitting", batch_size=300),
        )
        table = EstimateRun(config, tmp_path / f"split-{seed}", source=toy).run()
        result = summarise(config, table, toy.threshold)["probability"]
        covered += result["low"] <= toy.probability <= result["high"]
        estimates.append(result["probability"])
        played.append(len(table))
    assert max(played) <= 2000
    assert covered >= 17
    assert abs(np.median(estimates) / toy.probability - 1.0) < 0.4


def test_a_splitting_estimate_says_how_its_levels_went_and_when_its_chains_stood_still(tmp_path):
    toy = ClosedFormEncounters(threshold=5.0, p_looks=0.0)
    said = {}
    for correlation in (0.8, 0.0):  # small moves; a new independent draw every move
        params = EstimatorParams(method="splitting", batch_size=300, correlation=correlation)
        config = EstimateConfig(episodes=2000, seed=1, estimator=params)
        table = EstimateRun(config, tmp_path / f"rho-{correlation}", source=toy).run()
        summary = summarise(config, table, toy.threshold)
        levels = summary["levels"]
        assert levels[0]["accepted"] is None
        assert levels[0]["correlation"] == 0.0
        shares = np.prod([level["share"] for level in levels])
        assert shares == pytest.approx(summary["probability"]["probability"])
        said[correlation] = (min(level["accepted"] for level in levels[1:]), summary)
    moving, stuck = said[0.8], said[0.0]
    assert moving[0] > 0.1
    assert moving[1]["levels_warning"] is None
    # Independent draws rarely reach a high level: the chains keep few of their moves.
    assert stuck[0] < 0.1
    assert "the chains mostly stood still" in stuck[1]["levels_warning"]
    # None of its last level failed: the bound is above the chance of reaching that level.
    levels, result = stuck[1]["levels"], stuck[1]["probability"]
    assert levels[-1]["share"] == result["probability"] == 0.0
    assert result["high"] > np.prod([level["share"] for level in levels[:-1]])
    assert result["high"] >= toy.probability


def test_plain_monte_carlo_is_the_clopper_pearson_interval(tmp_path):
    toy = ClosedFormEncounters(threshold=0.0, p_looks=0.5)  # p = 0.25
    config, table = toy_estimate(tmp_path, 0, episodes=1000, method="mc", source=toy)
    result = summarise(config, table, toy.threshold)["probability"]
    failures = int(table["failure"].sum())
    assert result["probability"] == failures / 1000
    assert (result["low"], result["high"]) == clopper_pearson(failures, 1000)
    assert (table["log_weight"] == 0).all()


@pytest.mark.parametrize("written_before", [False, True])
def test_an_interrupted_estimate_resumes_with_the_same_episodes(tmp_path, written_before):
    toy = ClosedFormEncounters()
    config = EstimateConfig(
        episodes=500, seed=4, estimator=EstimatorParams(method="ce", batch_size=100)
    )
    whole = EstimateRun(config, tmp_path / "whole", source=toy).run()

    def stop_after_two(done, total):
        if done >= 200:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        EstimateRun(config, tmp_path / "cut", source=toy).run(stop_after_two)
    assert len(list((tmp_path / "cut" / "batches").glob("*.parquet"))) == 2
    if written_before:  # as an earlier version wrote it: without the settings added since
        path = tmp_path / "cut" / "config.json"
        written = json.loads(path.read_text())
        for later in ("penalty", "fit_failures"):
            del written["estimator"][later]
        path.write_text(json.dumps(written))
    resumed = EstimateRun(config, tmp_path / "cut", source=toy).run()
    pd.testing.assert_frame_equal(resumed, whole)


def test_an_estimate_directory_whose_configuration_does_not_read_is_a_one_line_error(tmp_path):
    (tmp_path / "config.json").write_text('{"episodes": "many"')
    config = EstimateConfig(episodes=300, estimator=EstimatorParams(method="mc"))
    with pytest.raises(ValueError, match=r"config\.json: ") as error:
        EstimateRun(config, tmp_path, source=ClosedFormEncounters())
    assert "\n" not in str(error.value)


def test_a_directory_that_holds_something_else_is_refused_and_left_as_it_was(tmp_path):
    config = EstimateConfig(episodes=300, estimator=EstimatorParams(method="mc"))
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine")
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.json").write_text('{"run": {"scenario": "crossing"}}')
    for directory in (mine, run):
        before = sorted(path.name for path in directory.iterdir())
        with pytest.raises(ValueError, match=r": exists and is not an estimate; choose another"):
            EstimateRun(config, directory, source=ClosedFormEncounters())
        assert sorted(path.name for path in directory.iterdir()) == before
    # A configuration half written when an estimate was stopped does not count as other files.
    (tmp_path / "stopped").mkdir()
    (tmp_path / "stopped" / "config.json.partial").write_text('{"scen')
    EstimateRun(config, tmp_path / "stopped", source=ClosedFormEncounters())
    assert (tmp_path / "stopped" / "config.json").exists()


def test_an_out_the_estimate_cannot_write_is_one_line_and_exit_2(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    done = hazardhunt(
        "estimate", "--scenario", "head-on", "--field", "none", "--method", "mc",
        "--episodes", 100, "--out", tmp_path / "notes.txt" / "estimate", cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 2
    [line] = done.stderr.strip().splitlines()
    assert f"--out: {tmp_path / 'notes.txt'} is a file, not a directory" in line


def test_an_estimate_of_another_configuration_is_not_mixed_in(tmp_path):
    toy = ClosedFormEncounters()
    EstimateRun(
        EstimateConfig(episodes=300, estimator=EstimatorParams(method="ce", batch_size=100)),
        tmp_path,
        source=toy,
    )
    other = EstimateConfig(
        episodes=300, seed=1, estimator=EstimatorParams(method="ce", batch_size=100)
    )
    with pytest.raises(ValueError, match=r"another configuration \(seed: there 0, here 1\)"):
        EstimateRun(other, tmp_path, source=toy)
    other = EstimateConfig(episodes=300, estimator=EstimatorParams(method="mc", batch_size=100))
    with pytest.raises(ValueError, match=r"\(estimator\.method: there 'ce', here 'mc'\)"):
        EstimateRun(other, tmp_path, source=toy)


def mc_config(episodes, batch_size=100, method="mc"):
    return EstimateConfig(
        episodes=episodes, seed=3, estimator=EstimatorParams(method=method, batch_size=batch_size)
    )


def test_a_larger_budget_extends_a_monte_carlo_estimate_with_the_episodes_it_would_have_played(
    tmp_path,
):
    toy = ClosedFormEncounters()
    whole = EstimateRun(mc_config(500), tmp_path / "whole", source=toy).run()
    EstimateRun(mc_config(300), tmp_path / "grown", source=toy).run()
    (tmp_path / "grown" / "estimate.json").write_text("{}")  # as the smaller budget left it
    grown = EstimateRun(mc_config(500), tmp_path / "grown", source=toy).run()
    pd.testing.assert_frame_equal(grown, whole)
    assert not (tmp_path / "grown" / "estimate.json").exists()  # stale: written anew at the end
    assert json.loads((tmp_path / "grown" / "config.json").read_text())["episodes"] == 500


@pytest.mark.parametrize(
    ("first", "then", "said"),
    [
        (mc_config(300, method="ce"), mc_config(500, method="ce"), "a ce estimate plans its"),
        (mc_config(250), mc_config(500), "whose last batch has 50 episodes, not 100"),
        (mc_config(300), mc_config(200), "more than 200; give --episodes 300 or more"),
    ],
    ids=["cross-entropy", "short last batch", "smaller"],
)
def test_an_estimate_that_cannot_be_extended_so_is_refused_and_left_as_it_was(
    tmp_path, first, then, said
):
    toy = ClosedFormEncounters()
    EstimateRun(first, tmp_path, source=toy).run()
    before = sorted(p.name for p in (tmp_path / "batches").iterdir())
    with pytest.raises(ValueError, match=said) as error:
        EstimateRun(then, tmp_path, source=toy)
    assert "\n" not in str(error.value)
    assert sorted(p.name for p in (tmp_path / "batches").iterdir()) == before
    assert json.loads((tmp_path / "config.json").read_text())["episodes"] == first.episodes


def test_a_failure_of_an_estimate_replays_exactly_from_its_row_and_the_report_draws_it(tmp_path):
    done = hazardhunt(
        "estimate", "--scenario", "head-on", "--field", "none", "--method", "mc",
        "--episodes", 100, "--batch-size", 50, "--out", tmp_path / "est", cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "failures per" in done.stdout
    assert "plain Monte Carlo would need" not in done.stdout  # no comparison with itself
    summary = json.loads((tmp_path / "est" / "estimate.json").read_text())
    assert summary["probability"]["failures"] > 0
    likeliest = summary["most_likely"]["all"]
    table = pd.concat(
        pd.read_parquet(p) for p in sorted((tmp_path / "est" / "batches").glob("*.parquet"))
    )
    row = table.set_index("episode").loc[likeliest["episode"]]
    config = EstimateConfig.model_validate_json((tmp_path / "est" / "config.json").read_text())
    from hazardhunt.likelihood.run import encounters_of

    source: SimulationEncounters = encounters_of(config)
    draw = draw_of(row, source.dimensions)
    assert isinstance(draw, Draw)
    replayed = source.play(draw)
    assert replayed.outcome == "failure"
    assert replayed.sim_time == row["sim_time"]
    assert replayed.failure_class == likeliest["failure_class"]
    shown = hazardhunt("report", tmp_path / "est", cwd=ROOT)
    assert shown.returncode == 0, shown.stderr
    page = (tmp_path / "est" / "report" / "index.html").read_text()
    assert "How likely a failure is" in page
    assert f"{summary['probability']['probability']:.3g}" in page
    assert page.count("data:image/png") >= 2  # the convergence and a most likely failure
    assert (tmp_path / "est" / "report" / "tables" / "classes.csv").exists()
    commands_for_runs_name_an_estimate(tmp_path / "est", likeliest["episode"])
    damaged_estimates_are_named_and_mend(tmp_path / "est", done.args[3:])
    received_estimates_that_do_not_replay_are_one_line(tmp_path / "est")
    # More episodes for the same estimate: its batch size is kept without --batch-size.
    command = [*done.args[3:]]
    command[command.index("--episodes") + 1] = "150"
    del command[command.index("--batch-size") : command.index("--batch-size") + 2]
    grown = hazardhunt(*command, cwd=ROOT)
    assert grown.returncode == 0, grown.stderr
    assert json.loads((tmp_path / "est" / "estimate.json").read_text())["episodes"] == 150
    assert len(list((tmp_path / "est" / "batches").glob("*.parquet"))) == 3


def commands_for_runs_name_an_estimate(directory, episode):
    """``replay``, ``export`` and ``copy`` of an estimate say that it is one, and which command
    shows it, in one line, and write nothing."""
    elsewhere = directory.parent / "elsewhere"
    for command in (
        ("replay", directory, "--episode", episode),
        ("export", directory, "--out", elsewhere),
        ("copy", directory, "--out", elsewhere),
    ):
        refused = hazardhunt(*command, cwd=ROOT)
        assert refused.returncode == 2
        [line] = refused.stderr.strip().splitlines()
        assert f"{directory}: an estimate, not a run; 'hazardhunt report {directory}'" in line
    assert not elsewhere.exists()


def received_estimates_that_do_not_replay_are_one_line(directory):
    """The report of a received estimate whose most likely failure's draw is out of the
    model's range, whose model changed since or whose summary nests too deep to read is a
    one-line error naming the file, and writes nothing."""
    from hazardhunt.analysis.risk_report import write_estimate_report
    from hazardhunt.errors import InputError

    summary = json.loads((directory / "estimate.json").read_text())
    episode = summary["most_likely"]["all"]["episode"]
    batch = directory / "batches" / f"{episode // 50:05d}.parquet"
    played = batch.read_bytes()
    for value, said in ((np.nan, "x.destination is nan"), (99.0, "x.destination is 99.0")):
        table = pd.read_parquet(batch)
        table.loc[table["episode"] == episode, "x.destination"] = value
        table.to_parquet(batch, index=False)
        with pytest.raises(InputError) as error:
            write_estimate_report(directory)
        assert str(error.value).startswith(f"{batch}: episode {episode}: {said}, which the model")
        assert "\n" not in str(error.value)
    batch.write_bytes(played)
    configured = (directory / "config.json").read_text()
    config = json.loads(configured)
    config["digests"]["people"] = "0" * 64  # as an estimate made on another model records
    (directory / "config.json").write_text(json.dumps(config))
    with pytest.raises(InputError) as error:
        write_estimate_report(directory)
    assert str(error.value) == (
        f"people.toml (built-in): changed since the estimate in {directory} was made (its "
        "SHA-256 is not the one config.json records for people): its most likely failures "
        "cannot be replayed on it; restore it to report on the estimate"
    )
    (directory / "config.json").write_text(configured)
    written = (directory / "estimate.json").read_text()
    (directory / "estimate.json").write_text("[" * 200_000 + "]" * 200_000)
    shown = hazardhunt("report", directory, cwd=ROOT)
    assert shown.returncode == 2, shown.stderr
    [line] = shown.stderr.strip().splitlines()
    assert line.startswith(f"error: {directory / 'estimate.json'}: cannot be read (")
    (directory / "estimate.json").write_text(written)
    assert not (directory / ".report.partial").exists()


def damaged_estimates_are_named_and_mend(directory, command):
    """A damaged estimate directory is a one-line error naming the file, never a traceback;
    deleting a damaged batch and running the command again plays it anew, as it was."""
    written = (directory / "estimate.json").read_text()
    (directory / "estimate.json").write_text("{")
    shown = hazardhunt("report", directory, cwd=ROOT)
    assert shown.returncode == 2
    assert "estimate.json: cannot be read" in shown.stderr
    # Of the wrong shape, where only its keys' types tell: named too, not a traceback.
    stored = json.loads(written)
    for key, value, said in (
        ("episodes", "150", 'episodes: must be a whole number, not "150"'),
        ("probability", {**stored["probability"], "low": None}, "probability.low: must be"),
        ("method", ..., "method: missing"),
    ):
        changed = {k: v for k, v in stored.items() if k != key}
        (directory / "estimate.json").write_text(
            json.dumps(changed if value is ... else changed | {key: value})
        )
        shown = hazardhunt("report", directory, cwd=ROOT)
        assert shown.returncode == 2, shown.stderr
        [line] = shown.stderr.strip().splitlines()
        assert f"estimate.json: cannot be read (not an estimate's summary: {said}" in line
    likeliest = {name: {**found, "episode": 10**6} for name, found in stored["most_likely"].items()}
    (directory / "estimate.json").write_text(json.dumps(stored | {"most_likely": likeliest}))
    shown = hazardhunt("report", directory, cwd=ROOT)
    assert shown.returncode == 2, shown.stderr
    assert "most_likely names episode 1000000, which the batches do not hold" in shown.stderr
    (directory / "estimate.json").write_text(written)
    configured = (directory / "config.json").read_bytes()
    (directory / "config.json").write_bytes(b"\xff{")  # not UTF-8
    shown = hazardhunt("report", directory, cwd=ROOT)
    assert shown.returncode == 2, shown.stderr
    assert (
        shown.stderr.strip()
        == f"error: {directory / 'config.json'}: (top level): Invalid JSON: "
        + ("expected value at line 1 column 1")
    )
    (directory / "config.json").write_bytes(configured)
    batch = directory / "batches" / "00001.parquet"
    batch.write_bytes(batch.read_bytes()[:100])
    for again in (hazardhunt(*command, cwd=ROOT), hazardhunt("report", directory, cwd=ROOT)):
        assert again.returncode == 2
        assert "00001.parquet: cannot be read" in again.stderr
        assert "Traceback" not in again.stderr
    batch.unlink()
    again = hazardhunt(*command, cwd=ROOT)
    assert again.returncode == 0, again.stderr
    assert (directory / "estimate.json").read_text() == written


class SometimesCrashing(ClosedFormEncounters):
    """A SUT that raises whenever the person's ``b`` is above 1 (about 16 % of encounters)."""

    def play(self, draw):
        if draw.values["b"] > 1.0:
            return Played("sut_error", False, None, 0.0, 0.0, 0.0, True)
        return super().play(draw)


def test_episodes_the_sut_could_not_play_widen_the_probability_not_lower_it(tmp_path):
    toy = SometimesCrashing(threshold=0.0, p_looks=0.5)
    config, table = toy_estimate(tmp_path, 0, episodes=1000, method="mc", source=toy)
    summary = summarise(config, table, toy.threshold)
    errors = int(table["sut_error"].sum())
    assert summary["sut_errors"] == errors > 100
    # The estimate is over the episodes the SUT played.
    tested = table[~table["sut_error"]]
    assert summary["probability"]["episodes"] == summary["episodes_tested"] == len(tested)
    assert summary["probability"]["probability"] == pytest.approx(tested["failure"].mean())
    untested = summary["untested"]
    assert untested["probability"]["probability"] == pytest.approx(errors / 1000)
    # Counted as failures, the encounters the SUT could not play raise the upper end.
    assert untested["failure_or_untested"]["high"] > summary["probability"]["high"] + 0.1
    assert untested["failure_and_tested"]["low"] < summary["probability"]["low"]


def test_a_splitting_range_holds_every_encounter_the_sut_could_not_play(tmp_path):
    # Failures are rare (2e-4) and the SUT errs in 16 % of encounters, each before its score
    # rises (score 0): no such encounter reaches the levels the chains climb.
    toy = SometimesCrashing(threshold=5.0, p_looks=0.0)
    config = EstimateConfig(
        episodes=2000, seed=0, estimator=EstimatorParams(method="splitting", batch_size=300)
    )
    table = EstimateRun(config, tmp_path / "split", source=toy).run()
    summary = summarise(config, table, toy.threshold)
    untested = summary["untested"]
    # How often the SUT errs is the first level's share (plain Monte Carlo over the model).
    first_level = table["sut_error"].to_numpy(bool)[:300]
    erred = untested["probability"]
    assert erred["probability"] == pytest.approx(first_level.mean())
    assert (erred["low"], erred["high"]) == clopper_pearson(int(first_level.sum()), 300)
    truth = float(stats.norm.sf(1.0))  # P(b > 1)
    assert erred["low"] <= truth <= erred["high"]
    # Counted as failures, they put the probability of a failure at that share at least.
    either = untested["failure_or_untested"]
    assert summary["probability"]["high"] < 0.01
    assert either["low"] >= erred["low"] > 0.1
    assert either["high"] >= truth + toy.probability
    assert untested["failure_and_tested"]["high"] < 0.01
    assert "from the first level" in untested["note"]


class CrashingAtRandom(ClosedFormEncounters):
    """A SUT that raises in about half of the encounters, whatever the encounter is (when its
    noise seed is odd)."""

    def play(self, draw):
        if draw.seed % 2:
            return Played("sut_error", False, None, 0.0, 0.0, 0.0, True, "RuntimeError: flaky")
        return super().play(draw)


def test_importance_sampling_leaves_out_the_episodes_the_sut_could_not_play(tmp_path):
    toy = CrashingAtRandom()
    config, table = toy_estimate(tmp_path, 0, episodes=1000, source=toy)
    summary = summarise(config, table, toy.threshold)
    result, untested = summary["probability"], summary["untested"]
    assert 400 < summary["sut_errors"] < 600
    # Over the tested episodes, the estimate covers the truth; counting the others as safe
    # encounters, as before, halved it.
    assert result["low"] <= toy.probability <= result["high"]
    counted_as_safe = untested["failure_and_tested"]["probability"]
    assert counted_as_safe == pytest.approx(result["probability"] / 2, rel=0.2)
    assert (
        "unbiased only if the SUT's errors have nothing to do with the encounter"
        in (untested["note"])
    )


def test_an_estimate_is_over_the_episodes_the_sut_played(tmp_path):
    def estimate_wearing_out(out, method, lasts):
        return hazardhunt(
            "estimate", "--scenario", "head-on", "--field", "none", "--method", method,
            "--episodes", 100 if method == "mc" else 150, "--batch-size", 50, "--out", out,
            "--controller", "tests.campaign.test_nothing_tested:WearsOut",
            "--controller-param", f"lasts={lasts}", cwd=ROOT,
        )  # fmt: skip

    # 10 episodes played (the trial episode plays on a controller of its own), 90 not: the
    # interval is over 10.
    done = estimate_wearing_out(tmp_path / "mc", "mc", 10)
    assert done.returncode == 0, done.stderr
    summary = json.loads((tmp_path / "mc" / "estimate.json").read_text())
    result = summary["probability"]
    assert result["episodes"] == summary["episodes_tested"] == 10
    assert (result["low"], result["high"]) == pytest.approx(clopper_pearson(result["failures"], 10))
    assert f"[{result['low']:.3g}, {result['high']:.3g}] (clopper-pearson)" in done.stdout
    assert "100 (90 SUT errors)" in done.stdout
    assert (
        "warning: 90 of the 100 episodes ended in a SUT error and tested nothing (the first: "
        "controller: RuntimeError: worn out); the estimate and its interval are over the 10 "
        "tested episodes it counts"
    ) in done.stderr
    # Cross-entropy counts the episodes drawn once its proposal stopped moving: the last 50,
    # every one of which erred. Nothing it counts was tested: exit 1, nothing kept.
    done = estimate_wearing_out(tmp_path / "ce", "ce", 50)
    assert done.returncode == 1
    assert (
        "error: every one of the 50 episodes drawn from the final proposal, the ones it counts, "
        "ended in a SUT error (the first: controller: RuntimeError: worn out): nothing was tested"
    ) in done.stderr
    assert not (tmp_path / "ce").exists()


def test_too_small_a_budget_and_an_untested_sut_exit_non_zero(tmp_path):
    small = hazardhunt(
        "estimate", "--method", "ce", "--episodes", 200, "--batch-size", 100,
        "--out", tmp_path / "small", cwd=ROOT,
    )  # fmt: skip
    assert small.returncode == 2
    assert "fewer than 3 batches" in small.stderr
    assert not (tmp_path / "small").exists()
    for options, message in (
        (("--batch-size", 500), "batch_size: batches of 500 episodes are more than the budget"),
        (("--field", "3m"), "field: unknown field '3m': use one of none, 1.25m, 2m"),
    ):
        refused = hazardhunt(
            "estimate", "--episodes", 100, *options, "--out", tmp_path / "small", cwd=ROOT
        )
        assert refused.returncode == 2
        assert message in refused.stderr
        assert "Traceback" not in refused.stderr
        assert not (tmp_path / "small").exists()
    # A controller that cannot start an episode stops on the trial episode, before anything
    # is written, naming what it raised.
    broken = estimate_with(tmp_path / "broken", "ResetRaises")
    assert broken.returncode == 2
    assert "reset() raised FileNotFoundError: map.yaml" in broken.stderr
    assert "on a trial episode before the estimate" in broken.stderr
    assert not (tmp_path / "broken").exists()
    # One that passes the trial and raises in every episode: exit 1, the first error named,
    # and nothing kept, so that the same command starts anew once the controller is mended.
    broken = estimate_with(tmp_path / "broken", "RaisesOnceTheHumanMoves")
    assert broken.returncode == 1
    assert "every one of the 100 episodes ended in a SUT error" in broken.stderr
    assert "(the first: controller: RuntimeError: lost the localisation)" in broken.stderr
    assert "nothing was tested" in broken.stderr
    assert not (tmp_path / "broken").exists()


def test_a_small_budget_without_a_batch_size_gets_batches_it_can_play(tmp_path):
    assert [default_batch_size(m, 2000) for m in ("mc", "ce", "splitting")] == [200, 200, 200]
    assert [default_batch_size(m, 150) for m in ("mc", "ce", "splitting")] == [150, 50, 75]
    # The smallest budget with cross-entropy, which needs three batches: what a user who types
    # it without --batch-size gets is an estimate, not an error about the default.
    controller = "hazardhunt.benchmark.conservative:ConservativeController"
    result = hazardhunt(
        "estimate", "--method", "ce", "--episodes", 100, "--scenario", "head-on",
        "--field", "none", "--controller", controller, "--out", tmp_path / "ce", cwd=ROOT,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    config = json.loads((tmp_path / "ce" / "config.json").read_text())
    assert config["estimator"]["batch_size"] == 33
    assert len(list((tmp_path / "ce" / "batches").glob("*.parquet"))) >= 3


def estimate_with(out, controller):
    return hazardhunt(
        "estimate", "--scenario", "head-on", "--field", "none", "--method", "mc",
        "--episodes", 100, "--batch-size", 50, "--out", out,
        "--controller", f"tests.campaign.test_nothing_tested:{controller}", cwd=ROOT,
    )  # fmt: skip


def test_a_weight_that_overflows_is_reported_not_dropped():
    from hazardhunt.likelihood.estimators import estimate
    from hazardhunt.likelihood.run import EstimateError

    failed = np.array([True, False, True])
    with pytest.raises(OverflowError, match=r"log weight 900\.0"):
        estimate(failed, np.array([0.0, 900.0, 1.0]), np.ones(3))
    table = pd.DataFrame(
        {
            "failure": failed,
            "failure_class": ["a", "", "a"],
            "log_weight": [0.0, 900.0, 1.0],
            "defensive": [0.1] * 3,
            "adapting": [False] * 3,
            "sut_error": [False] * 3,
            "batch": [0] * 3,
            "episode": [0, 1, 2],
            "log_p": [0.0] * 3,
            "score": [100.0, 0.0, 100.0],
        }
    )
    with pytest.raises(EstimateError, match="cannot be computed: a likelihood ratio overflows"):
        summarise(EstimateConfig(), table, 100.0)


@pytest.mark.slow
def test_workers_play_the_same_episodes(tmp_path):
    def estimate_with(workers):
        config = EstimateConfig(
            scenario="head-on",
            field="none",
            episodes=120,
            estimator=EstimatorParams(method="mc", batch_size=40),
        )
        return EstimateRun(config, tmp_path / f"w{workers}", workers=workers).run()

    one, two = estimate_with(1), estimate_with(2)
    pd.testing.assert_frame_equal(one, two)
