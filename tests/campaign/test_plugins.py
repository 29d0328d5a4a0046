"""Your own controller, safety layer, tester and failure classifier, loaded by import path from
the command line and from campaign files: the worked example finds failures, bad plug-ins are
clear errors, a controller that raises is a recorded sut_error, configuration builds nothing,
and code named in results is never imported by reading them."""

import json
import shutil
import sys
import textwrap
from pathlib import Path

import pandas as pd
import pytest

from hazardhunt.campaign.config import ConfigError, RunConfig, check_plugins, load_campaign
from hazardhunt.sut.plugins import PluginError, build_controller, build_safety_layer
from tests.helpers import hazardhunt

EXAMPLE = Path(__file__).parents[2] / "examples" / "pure_pursuit"
CONTROLLER = "cautious_pursuit:CautiousPursuit"


def plugin_module(folder: Path, source: str, name: str = "my_sut") -> Path:
    path = folder / f"{name}.py"
    path.write_text(textwrap.dedent(source))
    return path


RAISING = """
    from hazardhunt.sut.protocols import ControlCommand

    class Raising:
        control_period = 0.2

        def reset(self, floor, route, robot, params):
            pass

        def control(self, time, robot, human):
            if time >= 1.0:
                raise RuntimeError("lost the localisation")
            return ControlCommand(speed=0.5, yaw_rate=0.0)

    class RaisingOnceTheHumanMoves(Raising):
        # Works against a human standing still (the trial episode before a run).

        def control(self, time, robot, human):
            if human is not None and len(human.recent_positions) > 1:
                last, before = human.recent_positions[-1], human.recent_positions[-2]
                if abs(last - before).max() > 1e-6:
                    raise RuntimeError("lost the localisation")
            return ControlCommand(speed=0.5, yaw_rate=0.0)

    class NotAController:
        def control(self, time, robot, human):
            pass
"""


def test_the_example_controller_from_the_command_line_fails_within_a_few_hundred_episodes(
    tmp_path,
):
    out = tmp_path / "run"
    done = hazardhunt(
        "run", "--scenario", "crossing", "--field", "none", "--tester", "random",
        "--episodes", 150, "--seed", 0, "--out", out, "--json",
        "--controller", CONTROLLER, "--controller-param", "stop_distance=1.0",
        cwd=EXAMPLE,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert summary["failures"] > 0
    config = json.loads((out / "config.json").read_text())
    assert config["run"]["controller"]["path"] == CONTROLLER
    assert config["run"]["controller"]["params"] == {"stop_distance": 1.0}
    # Its failures replay exactly once the plug-in is named again: the same import path
    # confirms the run's controller, with the parameters the run recorded.
    failure = int(pd.read_parquet(out / "failures.parquet")["episode"].iloc[0])
    refused = hazardhunt("replay", out, "--episode", failure, cwd=EXAMPLE)
    assert refused.returncode == 2
    assert f"names the plug-in '{CONTROLLER}'" in refused.stderr
    replayed = hazardhunt(
        "replay", out, "--episode", failure, "--controller", CONTROLLER, cwd=EXAMPLE
    )
    assert replayed.returncode == 0, replayed.stderr
    assert "reproduced" in replayed.stdout
    assert "importing module 'cautious_pursuit'" in replayed.stderr


def test_the_example_controller_from_a_campaign_file_fails(tmp_path):
    shutil.copy(EXAMPLE / "cautious_pursuit.py", tmp_path)
    campaign = tmp_path / "campaign.toml"
    campaign.write_text(
        'scenarios = ["crossing"]\nfields = ["none"]\ntesters = ["random"]\nseeds = [1]\n'
        'episodes = 150\n[controller]\npath = "cautious_pursuit:CautiousPursuit"\n'
        "params = { stop_distance = 1.0 }\n"
    )
    done = hazardhunt("campaign", campaign, "--out", tmp_path / "results", cwd=Path("/"))
    assert done.returncode == 0, done.stderr
    (run,) = (tmp_path / "results" / "runs").iterdir()
    assert json.loads((run / "summary.json").read_text())["failures"] > 0


@pytest.mark.parametrize(
    ("path", "message"),
    [
        ("no_such_module:Thing", "cannot import module 'no_such_module'"),
        ("my_sut:Missing", "module 'my_sut' has no attribute 'Missing'"),
        ("my_sut", "is not an import path of the form 'package.module:Name'"),
        ("my_sut:NotAController", "does not satisfy the Controller protocol: it lacks"),
    ],
)
def test_a_bad_controller_is_one_clear_line_and_runs_nothing(tmp_path, path, message):
    plugin_module(tmp_path, RAISING)
    done = hazardhunt(
        "run", "--scenario", "crossing", "--field", "none", "--tester", "random",
        "--episodes", 2, "--out", tmp_path / "run", "--controller", path, cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 2
    assert message in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(
    ("command", "option"),
    [
        (["replay", "RUN", "--episode", "0"], "--controller"),
        (["replay", "RUN", "--episode", "0"], "--safety-layer"),
        (["regress", "RUN"], "--controller"),
        (["report", "RUN"], "--classifier"),
        (["export", "RUN", "--out", "cases"], "--classifier"),
        (["campaign", "campaign.toml", "--out", "results"], "--classifier"),
        (["estimate", "--episodes", "100", "--out", "estimate"], "--people"),
        (["estimate", "--episodes", "100", "--out", "estimate"], "--controller"),
    ],
)  # fmt: skip
def test_every_command_names_the_option_whose_plug_in_does_not_import(tmp_path, command, option):
    command = [str(tmp_path / "run") if word == "RUN" else word for word in command]
    done = hazardhunt(*command, option, "no_such_module:Thing", cwd=tmp_path)
    assert done.returncode == 2
    assert done.stderr.strip() == (
        f"error: {option}: 'no_such_module:Thing': cannot import module 'no_such_module': "
        "No module named 'no_such_module'"
    )
    assert sorted(path.name for path in tmp_path.iterdir()) == []


def test_parameters_the_class_does_not_take_are_named(tmp_path):
    with pytest.raises(PluginError, match=r"does not take these parameters: .*'stop_distnce'"):
        build_controller(CONTROLLER, {"stop_distnce": 1.0}, [str(EXAMPLE)])


def test_a_campaign_file_with_a_bad_controller_names_the_file_and_key(tmp_path):
    campaign = tmp_path / "campaign.toml"
    campaign.write_text(
        'scenarios = ["crossing"]\nfields = ["none"]\ntesters = ["random"]\nseeds = [0]\n'
        'episodes = 3\n[controller]\npath = "nowhere:Controller"\n'
    )
    with pytest.raises(ConfigError, match=r"campaign.toml: controller: .*cannot import module"):
        load_campaign(campaign)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("tester", "params"),
    [("cem", ["population=2", "n_workers=2"]), ("ppo-max", ["n_envs=2", "n_steps=8"])],
)
def test_worker_processes_load_a_controller_found_only_in_the_working_directory(
    tmp_path, tester, params
):
    plugin_module(tmp_path, RAISING)
    out = tmp_path / "run"
    options = [item for param in params for item in ("--tester-param", param)]
    done = hazardhunt(
        "run", "--scenario", "head-on", "--field", "none", "--tester", tester, *options,
        "--episodes", 4, "--out", out, "--json",
        "--controller", "my_sut:RaisingOnceTheHumanMoves", cwd=tmp_path,
    )  # fmt: skip
    # The plug-in ran in the workers: it raised there in every episode, which fails the run.
    assert done.returncode == 1
    assert "every one of its 4 episodes ended in a SUT error" in done.stderr
    assert "RuntimeError: lost the localisation" in done.stderr


def test_a_controller_that_raises_on_the_trial_episode_is_one_line_and_runs_nothing(tmp_path):
    plugin_module(tmp_path, RAISING)
    out = tmp_path / "run"
    done = hazardhunt(
        "run", "--scenario", "head-on", "--field", "none", "--tester", "random",
        "--episodes", 3, "--out", out, "--json", "--controller", "my_sut:Raising", cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 2
    assert done.stderr.strip() == (
        "error: controller 'my_sut:Raising': control() raised RuntimeError: lost the "
        "localisation (on a trial episode before the run; nothing was run)"
    )
    assert not out.exists()


def test_the_laser_field_with_side_bands_loads_as_a_safety_layer():
    layer = build_safety_layer(
        "hazardhunt.sut.safety_layer:LaserSafetyLayer", {"diameter": 1.25, "side_margin": 0.4}
    )
    assert layer.field.side_margin == 0.4
    with pytest.raises(PluginError, match="does not satisfy the SafetyLayer protocol"):
        build_safety_layer("hazardhunt.sut.route:Route", {"points": [[0, 0], [1, 0]]})


def test_a_run_on_your_own_scenario_is_found_again_from_any_folder(tmp_path):
    out = tmp_path / "run"
    done = hazardhunt(
        "run", "--scenario", "../loading_dock/dock_crossing.toml", "--field", "sides",
        "--tester", "random", "--episodes", 20, "--out", out, "--controller", CONTROLLER,
        cwd=EXAMPLE,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    stored = json.loads((out / "config.json").read_text())["run"]["scenario"]
    assert Path(stored).is_absolute()
    assert Path(stored) == (EXAMPLE.parent / "loading_dock" / "dock_crossing.toml").resolve()
    report = hazardhunt("report", out, cwd=tmp_path)
    assert report.returncode == 0, report.stderr


def test_loading_a_plug_in_leaves_sys_path_as_it_was(tmp_path):
    plugin_module(tmp_path, RAISING, "path_probe")
    before = list(sys.path)
    controller = build_controller("path_probe:Raising", {}, [str(tmp_path)])
    assert controller.control_period == 0.2
    assert sys.path == before
    with pytest.raises(PluginError, match="cannot import module 'path_probe_missing'"):
        build_controller("path_probe_missing:Raising", {}, [str(tmp_path)])
    assert sys.path == before


COUNTING = """
    from pathlib import Path

    from hazardhunt.sut.protocols import ControlCommand

    class Counting:
        \"\"\"A controller that notes every construction in built.txt next to it.\"\"\"

        control_period = 0.2

        def __init__(self, cruise_speed=1.0):
            with Path(__file__).with_name("built.txt").open("a") as log:
                log.write("built\\n")
            self.cruise_speed = cruise_speed

        def reset(self, floor, route, robot, params):
            pass

        def control(self, time, robot, human):
            return ControlCommand(speed=self.cruise_speed, yaw_rate=0.0)
"""


def constructions(folder: Path) -> int:
    log = folder / "built.txt"
    return log.read_text().count("built") if log.exists() else 0


def test_validating_a_configuration_builds_no_plug_in(tmp_path):
    plugin_module(tmp_path, COUNTING, "counting_once")
    data = {
        "scenario": "crossing",
        "field": "none",
        "tester": "random",
        "seed": 0,
        "episodes": 3,
        "controller": {"path": "counting_once:Counting", "search_path": [str(tmp_path)]},
    }
    config = RunConfig.model_validate(data)
    assert RunConfig.model_validate(config.model_dump()) == config
    assert constructions(tmp_path) == 0
    check_plugins(config)  # where a command line is read: once
    assert constructions(tmp_path) == 1


def test_a_campaign_file_builds_each_plug_in_once_however_many_runs(tmp_path):
    plugin_module(tmp_path, COUNTING, "counting_campaign")
    campaign = tmp_path / "campaign.toml"
    campaign.write_text(
        'scenarios = ["crossing", "head-on"]\nfields = ["none", "2m"]\ntesters = ["random"]\n'
        'seeds = [0, 1]\nepisodes = 3\n[controller]\npath = "counting_campaign:Counting"\n'
    )
    config = load_campaign(campaign)
    assert constructions(tmp_path) == 1
    assert len(config.runs()) == 8
    assert constructions(tmp_path) == 1


TESTER_MODULE = """
    import math
    from pathlib import Path

    import numpy as np

    class Charge:
        \"\"\"Waits beside the main aisle of the crossing, then runs into the robot's side.\"\"\"

        name = "charge"
        reward = "max"

        def __init__(self, seed, speed=1.5):
            self.seed = seed
            self.speed = speed

        def explore(self, env, episodes):
            while env.episodes_done < episodes:
                env.evaluate(self.action)

        def action(self, sim):
            x, y, heading = sim.human_pose
            robot = sim.robot
            if robot.x > x - 0.45:
                target, speed = (robot.x, robot.y), self.speed
            elif y < 8.8:
                target, speed = (10.0, 8.8), self.speed
            else:
                target, speed = (x, y + 1.0), 0.0
            error = math.atan2(target[1] - y, target[0] - x) - heading
            error = math.atan2(math.sin(error), math.cos(error))
            human = sim.human_params
            turn = np.clip(error / sim.decision_period, -human.max_turn_rate, human.max_turn_rate)
            return np.array(
                [2.0 * speed / human.max_speed - 1.0, turn / human.max_turn_rate],
                dtype=np.float32,
            )

        def save(self, directory):
            directory.mkdir(parents=True, exist_ok=True)
            (directory / "charge.txt").write_text(f"speed={self.speed}\\n")

    class Sleepy:
        name = "sleepy"
        reward = "max"

        def __init__(self, seed):
            pass

        def save(self, directory):
            pass

    class Stumbles(Charge):
        \"\"\"Raises in the middle of its episodes.\"\"\"

        def explore(self, env, episodes):
            env.evaluate(self.action)
            raise KeyError("no such aisle")
"""

CLASSIFIER_MODULE = """
    from pathlib import Path

    Path(__file__).with_name("classifier-imported").touch()

    FACES = ("front", "left", "right", "rear")

    class ByFace:
        \"\"\"Names a failure by the face the human touched.\"\"\"

        name = "by-face"

        def __init__(self, prefix="hit"):
            self.prefix = prefix

        def classes_for(self, field):
            return (*(f"{self.prefix}/{face}" for face in FACES), "other")

        def classify(self, trajectory, summary, field):
            face = summary.contact_face
            return f"{self.prefix}/{face}" if face in FACES else "other"
"""


@pytest.fixture(scope="module")
def charged(tmp_path_factory):
    """A run of the Charge tester plug-in, its failures classified by the ByFace plug-in."""
    folder = tmp_path_factory.mktemp("plugins")
    plugin_module(folder, TESTER_MODULE, "my_testers")
    plugin_module(folder, CLASSIFIER_MODULE, "my_classes")
    out = folder / "run"
    done = hazardhunt(
        "run", "--scenario", "crossing", "--field", "none", "--episodes", 3,
        "--decision-period", 0.2, "--out", out, "--json",
        "--tester", "my_testers:Charge", "--tester-param", "speed=1.5",
        "--classifier", "my_classes:ByFace", "--classifier-param", "prefix=struck",
        cwd=folder,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    (folder / "classifier-imported").unlink()
    return folder, out, json.loads(done.stdout)


def test_a_tester_plug_in_runs_and_a_classifier_plug_in_names_its_failures(charged):
    _, out, summary = charged
    assert summary["tester"] == "my_testers:Charge"
    assert summary["episodes"] == 3
    assert summary["failures"] == 3  # the charge hits the robot's right side every time
    assert summary["classifier"] == "by-face"
    assert summary["classes"] == ["struck/right"]
    assert summary["classes_total"] == 4
    assert set(pd.read_parquet(out / "failures.parquet")["class"]) == {"struck/right"}
    assert (out / "tester" / "charge.txt").read_text() == "speed=1.5\n"
    run = json.loads((out / "config.json").read_text())["run"]
    assert run["tester_plugin"]["path"] == "my_testers:Charge"
    assert run["tester_plugin"]["params"] == {"speed": 1.5}
    assert run["classifier"]["path"] == "my_classes:ByFace"
    assert run["classifier"]["params"] == {"prefix": "struck"}


def test_reading_results_never_imports_the_classifier_they_name(charged):
    folder, out, _ = charged
    report = hazardhunt("report", out, cwd=folder)
    assert report.returncode == 0, report.stderr
    classes = pd.read_csv(out / "report" / "tables" / "classes.csv")
    assert classes[["classes", "k / K"]].values.tolist() == [["struck/right", "1 / 4"]]
    cases = folder / "cases"
    export = hazardhunt("export", out, "--out", cases, cwd=folder)
    assert export.returncode == 0, export.stderr
    (case,) = cases.glob("*.toml")
    assert 'path = "my_classes:ByFace"' in case.read_text()
    refused = hazardhunt("regress", cases, cwd=folder)
    assert refused.returncode == 2
    [line] = refused.stderr.strip().splitlines()
    assert "'my_classes:ByFace'" in line
    assert "regress --classifier" in line
    assert not (folder / "classifier-imported").exists()
    named = hazardhunt(
        "regress", cases, "--json", "--classifier", "my_classes:ByFace",
        "--classifier-param", "prefix=struck", cwd=folder,
    )  # fmt: skip
    assert named.returncode == 1, named.stderr
    [result] = json.loads(named.stdout)["cases"]
    assert (result["verdict"], result["failure_class"]) == ("still fails", "struck/right")


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["nowhere:Tester"], "--tester: 'nowhere:Tester': cannot import module 'nowhere'"),
        (["my_testers:Sleepy"], "tester: 'my_testers:Sleepy' does not satisfy the Tester "
         "protocol: it lacks explore"),
        (["my_testers:Charge", "--tester-param", "sped=1"],
         "tester: 'my_testers:Charge' does not take these parameters: got an unexpected keyword "
         "argument 'sped'"),
    ],
)  # fmt: skip
def test_a_bad_tester_plug_in_is_one_clear_line_and_runs_nothing(tmp_path, options, message):
    plugin_module(tmp_path, TESTER_MODULE, "my_testers")
    done = hazardhunt(
        "run", "--scenario", "crossing", "--field", "none", "--episodes", 3,
        "--out", tmp_path / "run", "--tester", *options, cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 2
    [line] = done.stderr.strip().splitlines()
    assert line.startswith(f"error: {message}")
    assert not (tmp_path / "run").exists()


def test_a_tester_plug_in_that_raises_is_one_line_naming_where_and_keeps_nothing(tmp_path):
    module = plugin_module(tmp_path, TESTER_MODULE, "my_testers")
    done = hazardhunt(
        "run", "--scenario", "crossing", "--field", "none", "--episodes", 3,
        "--out", tmp_path / "run", "--tester", "my_testers:Stumbles", cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 1
    [line] = done.stderr.strip().splitlines()
    assert line.startswith("error: run crossing__none__my_testers_Stumbles__seed0: tester ")
    assert "'my_testers:Stumbles' raised KeyError: 'no such aisle'" in line
    assert f"({module}, line " in line
    assert not (tmp_path / "run").exists()


def test_a_campaign_runs_a_tester_plug_in_beside_a_built_in_one(tmp_path):
    plugin_module(tmp_path, TESTER_MODULE, "mixed_testers")
    campaign = tmp_path / "campaign.toml"
    campaign.write_text(
        'scenarios = ["crossing"]\nfields = ["none"]\ntesters = ["random", "charge"]\n'
        "seeds = [0]\nepisodes = 2\n[env]\ndecision_period = 0.2\n"
        '[tester.charge]\npath = "mixed_testers:Charge"\nspeed = 1.5\n'
    )
    config = load_campaign(campaign)
    assert config.tester_plugins["charge"].params == {"speed": 1.5}
    out = tmp_path / "results"
    done = hazardhunt("campaign", campaign, "--out", out, cwd=Path("/"))
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in (out / "runs").iterdir()) == [
        "crossing__none__charge__seed0",
        "crossing__none__random__seed0",
    ]
    summary = json.loads(
        (out / "runs" / "crossing__none__charge__seed0" / "summary.json").read_text()
    )
    assert (summary["tester"], summary["failures"]) == ("charge", 2)


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ('[tester.random]\npath = "campaign_testers:Charge"\n',
         "tester.random: 'random' is a built-in tester"),
        ('[tester.charge]\npath = "campaign_testers:Sleepy"\n',
         "tester.charge: 'campaign_testers:Sleepy' does not satisfy the Tester protocol"),
        ("", "testers.1: unknown tester 'charge'"),
    ],
)  # fmt: skip
def test_a_campaign_file_with_a_bad_tester_plug_in_names_the_file_and_key(tmp_path, table, message):
    plugin_module(tmp_path, TESTER_MODULE, "campaign_testers")
    campaign = tmp_path / "campaign.toml"
    campaign.write_text(
        'scenarios = ["crossing"]\nfields = ["none"]\ntesters = ["random", "charge"]\n'
        f"seeds = [0]\nepisodes = 2\n{table}"
    )
    with pytest.raises(ConfigError, match=f"campaign.toml: {message}"):
        load_campaign(campaign)


def test_validating_a_configuration_builds_each_registered_tester_once(monkeypatch):
    from hazardhunt.campaign import config as config_module

    built = []
    real = config_module.make_tester

    def counting(name, seed, params=None):
        built.append(name)
        return real(name, seed, params)

    monkeypatch.setattr(config_module, "make_tester", counting)
    RunConfig(
        scenario="crossing",
        field="none",
        tester="qd",
        tester_params={"batch_size": 4},
        seed=0,
        episodes=8,
    )
    assert built == ["qd"]
