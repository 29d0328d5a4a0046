"""Controllers, safety layers and failure classifiers written against the protocols of
hazardhunt 0.1.0 keep working, with a warning that says what changed (CHANGELOG.md); one that
fits no version is a one-line error naming the signature expected."""

import textwrap
import warnings

import pandas as pd
import pytest

from hazardhunt.campaign.config import RunConfig
from hazardhunt.campaign.plugins import PluginSpec, make_classifier
from hazardhunt.campaign.run import record_run
from hazardhunt.sut.compat import ProtocolWarning
from hazardhunt.sut.plugins import PluginError, build_controller, build_safety_layer
from hazardhunt.sut.safety_layer import FIELD_SETTINGS
from tests.helpers import WALL_CLOCK_COLUMNS, hazardhunt

HERE = "tests.campaign.test_earlier_protocols"

SUT_OF_0_1_0 = '''
from hazardhunt.sut.pursuit import PursuitController
from hazardhunt.sut.safety_layer import LaserSafetyLayer


class PursuitBefore:
    """The pure-pursuit controller as written for 0.1.0: reset without the robot's parameters."""

    control_period = 0.2

    def __init__(self):
        self.inner = PursuitController()

    def reset(self, floor, route, robot):
        from hazardhunt.world.bodies import RobotParams

        self.inner.reset(floor, route, robot, RobotParams())

    def control(self, time, robot, human):
        return self.inner.control(time, robot, human)


class FieldBefore:
    """The 1.25 m laser field as written for 0.1.0: update without the time."""

    def __init__(self):
        self.inner = LaserSafetyLayer(diameter=1.25)
        self.time = 0.0

    def reset(self):
        self.inner.reset()
        self.time = 0.0

    def update(self, robot, human_position, radius):
        status = self.inner.update(self.time, robot, human_position, radius)
        self.time += 0.05
        return status


class FacesBefore:
    """A classifier as written for 0.1.0: the field as its diameter, records as rows."""

    name = "faces"

    def classes_for(self, field_diameter):
        assert field_diameter is None or isinstance(field_diameter, float)
        return ("front", "side", "rear", "other")

    def classify(self, trajectory, summary, field_diameter):
        assert isinstance(summary, dict) and all(isinstance(row, dict) for row in trajectory)
        face = summary["contact_face"]
        return {"front": "front", "rear": "rear", "left": "side", "right": "side"}.get(
            face, "other"
        )


class ResetTakesNothing(PursuitBefore):
    def reset(self):
        pass
'''


@pytest.fixture(scope="module", autouse=True)
def sut_module(tmp_path_factory):
    folder = tmp_path_factory.mktemp("sut")
    (folder / "old_sut.py").write_text(textwrap.dedent(SUT_OF_0_1_0))
    return folder


def spec(sut_module, name: str) -> PluginSpec:
    return PluginSpec(path=f"old_sut:{name}", search_path=[str(sut_module)])


def run(tmp_path, name, **plugins):
    config = RunConfig(
        scenario="head-on", field="none", tester="random", seed=3, episodes=8, **plugins
    )
    record_run(config, tmp_path / name)
    episodes = pd.read_parquet(tmp_path / name / "episodes.parquet")
    return episodes.drop(columns=WALL_CLOCK_COLUMNS)


def test_a_controller_of_0_1_0_plays_the_same_episodes_as_today_s_with_a_warning(
    tmp_path, sut_module
):
    with pytest.warns(ProtocolWarning, match=r"reset\(floor, route, robot\) is the protocol of"):
        before = run(tmp_path, "before", controller=spec(sut_module, "PursuitBefore"))
    today = run(
        tmp_path, "today", controller=PluginSpec(path="hazardhunt.sut.pursuit:PursuitController")
    )
    assert set(before["outcome"]) != {"sut_error"}
    pd.testing.assert_frame_equal(before, today)


def test_a_safety_layer_of_0_1_0_plays_the_same_episodes_as_today_s(tmp_path, sut_module):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ProtocolWarning)
        layer = build_safety_layer("old_sut:FieldBefore", search_path=[str(sut_module)])
        before = run(tmp_path, "before", safety_layer=spec(sut_module, "FieldBefore"))
    today = run(
        tmp_path,
        "today",
        safety_layer=PluginSpec(
            path="hazardhunt.sut.safety_layer:LaserSafetyLayer", params={"diameter": 1.25}
        ),
    )
    assert type(layer).__name__ != "FieldBefore"  # wrapped
    assert set(before["outcome"]) != {"sut_error"}
    pd.testing.assert_frame_equal(before, today)


def test_a_classifier_of_0_1_0_gets_the_diameter_and_plain_rows(tmp_path, sut_module):
    with pytest.warns(ProtocolWarning, match=r"classes_for\(field_diameter\)"):
        classifier = make_classifier(spec(sut_module, "FacesBefore"))
    assert classifier.name == "faces"
    assert classifier.classes_for(FIELD_SETTINGS["1.25m"]) == ("front", "side", "rear", "other")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ProtocolWarning)
        run(
            tmp_path,
            "classified",
            controller=PluginSpec(path="hazardhunt.sut.pursuit:PursuitController"),
            classifier=spec(sut_module, "FacesBefore"),
        )
    failures = pd.read_parquet(tmp_path / "classified" / "failures.parquet")
    assert len(failures) > 0
    assert set(failures["class"]) <= {"front", "side", "rear"}


def test_the_command_line_runs_a_controller_of_0_1_0_and_says_what_changed(tmp_path, sut_module):
    done = hazardhunt(
        "run", "--scenario", "crossing", "--field", "none", "--tester", "random",
        "--episodes", 3, "--out", tmp_path / "run", "--json",
        "--controller", "old_sut:PursuitBefore", "--classifier", "old_sut:FacesBefore",
        cwd=sut_module,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert '"sut_errors": 0' in done.stdout
    [warned] = [line for line in done.stderr.splitlines() if "reset(floor" in line]
    assert warned.startswith("warning: controller 'old_sut:PursuitBefore': reset(floor, route, ")
    assert "reset(floor, route, robot) is the protocol of hazardhunt 0.1.0" in warned
    assert "since 0.2.0 it is reset(floor, route, robot, params)" in warned
    assert "compat.py" not in done.stderr  # one line, not Python's with the source line below


def test_a_campaign_says_once_what_changed_not_once_per_run(tmp_path, sut_module):
    campaign = sut_module / "old.toml"
    campaign.write_text(
        'scenarios = ["crossing"]\nfields = ["none"]\ntesters = ["random"]\nseeds = [0, 1, 2]\n'
        'episodes = 2\n[controller]\npath = "old_sut:PursuitBefore"\n'
    )
    done = hazardhunt(
        "campaign", campaign, "--out", tmp_path / "out", "--workers", 2, cwd=sut_module
    )
    assert done.returncode == 0, done.stderr
    warned = [line for line in done.stderr.splitlines() if "is the protocol of" in line]
    assert len(warned) == 1
    assert warned[0].startswith("warning: controller 'old_sut:PursuitBefore': reset(floor, ")
    assert "compat.py" not in done.stderr


def test_a_method_that_fits_no_version_is_one_line_naming_the_signature(sut_module):
    with pytest.raises(PluginError) as raised:
        build_controller("old_sut:ResetTakesNothing", search_path=[str(sut_module)])
    message = str(raised.value)
    assert message == (
        "'old_sut:ResetTakesNothing': reset() does not fit the protocol: it must take "
        "(floor, route, robot, params) (since 0.2.0; before: (floor, route, robot)) "
        "(docs/plugins.md)"
    )


def test_a_benchmark_controller_named_by_its_earlier_path_still_loads():
    with pytest.warns(ProtocolWarning, match="has moved to 'hazardhunt.benchmark.conservative"):
        controller = build_controller("hazardhunt.sut.conservative:StaleTrack")
    assert type(controller).__module__ == "hazardhunt.benchmark.conservative"
