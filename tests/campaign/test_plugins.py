"""Your own controller and safety layer, loaded by import path from the command line and from
campaign files: the worked example finds failures, bad plug-ins are clear errors, and a
controller that raises is a recorded sut_error."""

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

        def reset(self, floor, route, robot):
            pass

        def control(self, time, robot, human):
            if time >= 1.0:
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
    # Its failures replay exactly: the run loads the plug-in again.
    failure = int(pd.read_parquet(out / "failures.parquet")["failure_id"].iloc[0])
    replayed = hazardhunt("replay", out, "--failure", failure, cwd=EXAMPLE)
    assert replayed.returncode == 0, replayed.stderr
    assert "reproduced" in replayed.stdout


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


def test_a_controller_that_raises_is_a_recorded_sut_error(tmp_path):
    plugin_module(tmp_path, RAISING)
    out = tmp_path / "run"
    done = hazardhunt(
        "run", "--scenario", "head-on", "--field", "none", "--tester", "random",
        "--episodes", 3, "--out", out, "--json", "--controller", "my_sut:Raising", cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["sut_errors"] == 3
    episodes = pd.read_parquet(out / "episodes.parquet")
    assert set(episodes["outcome"]) == {"sut_error"}
    assert all("RuntimeError: lost the localisation" in e for e in episodes["controller_errors"])


def test_the_laser_field_with_side_bands_loads_as_a_safety_layer():
    layer = build_safety_layer(
        "hazardhunt.sut.safety_layer:LaserSafetyLayer", {"diameter": 1.25, "side_margin": 0.4}
    )
    assert layer.side_margin == 0.4
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

        def reset(self, floor, route, robot):
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
