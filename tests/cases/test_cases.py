"""Failures as regression cases: export from a run, re-run against the same and a changed SUT."""

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import tomli_w

from hazardhunt.campaign.store import file_checksums
from hazardhunt.cases import CaseError, regress_case
from tests.helpers import hazardhunt, hostile_plugin, marker_module

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

EXAMPLE = Path(__file__).parents[2] / "examples" / "pure_pursuit"
SIDE_BANDS = [
    "--safety-layer", "hazardhunt.sut.safety_layer:LaserSafetyLayer",
    "--safety-layer-param", "diameter=1.25", "--safety-layer-param", "side_margin=0.4",
]  # fmt: skip
"""The study's 1.25 m field plus 0.4 m bands along the robot's sides."""


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """The example controller with the 1.25 m field: the field stops front contacts, so the
    failures found are mostly at the unguarded sides."""
    out = tmp_path_factory.mktemp("cases") / "run"
    done = hazardhunt(
        "run", "--scenario", "crossing", "--field", "1.25m", "--tester", "random",
        "--episodes", 300, "--seed", 0, "--out", out, "--controller",
        "cautious_pursuit:CautiousPursuit", cwd=EXAMPLE,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    return out


@pytest.fixture(scope="module")
def cases(run):
    out = run.parent / "cases"
    done = hazardhunt("export", run, "--out", out)
    assert done.returncode == 0, done.stderr
    return out


def regress(cases, *args):
    """``regress --json`` from the example's folder, trusting the cases' own plug-ins."""
    done = hazardhunt("regress", cases, "--json", "--trust-plugins", *args, cwd=EXAMPLE)
    return done.returncode, json.loads(done.stdout)


def test_export_writes_one_readable_case_per_class(run, cases):
    files = sorted(cases.glob("*.toml"))
    classes = [tomllib.loads(f.read_text())["expected"]["class"] for f in files]
    failures = pd.read_parquet(run / "failures.parquet")
    assert sorted(classes) == sorted(set(failures["class"]))
    case = tomllib.loads(files[0].read_text())
    assert case["sut"]["controller"]["path"] == "cautious_pursuit:CautiousPursuit"
    assert case["environment"]["field"] == "1.25m"
    assert case["scenario"]["name"] == "crossing"
    assert isinstance(case["scenario"]["map"], dict)  # the map travels with the case
    assert case["expected"]["outcome"] == "failure"
    assert files[0].read_text().startswith("# A failure hazardhunt found")
    every = run.parent / "every"
    assert hazardhunt("export", run, "--out", every, "--all").returncode == 0
    assert len(list(every.glob("*.toml"))) == len(failures)


def test_the_unchanged_sut_still_fails_every_case(cases):
    code, report = regress(cases)
    assert code == 1
    assert {case["verdict"] for case in report["cases"]} == {"still fails"}
    assert report["counts"]["still fails"] == len(list(cases.glob("*.toml")))


def test_a_field_that_also_covers_the_sides_fixes_the_side_gap_cases(cases):
    code, report = regress(cases, *SIDE_BANDS)
    side = [c for c in report["cases"] if c["expected_class"].startswith("side-")]
    assert side, "the run should have found failures at the robot's sides"
    assert {c["verdict"] for c in side} == {"fixed"}
    assert code == (1 if report["counts"]["still fails"] + report["counts"]["changed"] else 0)


def test_a_broken_case_file_names_the_file_and_key(cases, tmp_path):
    text = next(cases.glob("*.toml")).read_text()
    broken = tmp_path / "broken.toml"
    broken.write_text(text.replace("decision_period = ", "decision_periods = "))
    # The misspelt key first: it is what the user wrote, and says what was meant.
    named = (
        "broken.toml: environment.decision_periods: unknown key (did you mean "
        "decision_period?) (and 1 more problem)"
    )
    with pytest.raises(CaseError, match=re.escape(named)):
        regress_case(broken)
    done = hazardhunt("regress", broken)
    assert done.returncode == 2
    assert named in " ".join(done.stderr.split())


def test_a_case_file_that_is_not_text_is_a_clear_error(tmp_path):
    binary = tmp_path / "binary.toml"
    binary.write_bytes(b"format = 1\n\xff\xfe\x00garbage")
    done = hazardhunt("regress", binary)
    assert done.returncode == 2
    assert "binary.toml: not a text file" in done.stderr
    assert "Traceback" not in done.stderr


def drop(table, key):
    del table[key]


@pytest.mark.parametrize(
    ("break_case", "message"),
    [
        pytest.param(lambda case: drop(case, "human"), "human: missing", id="missing-table"),
        pytest.param(
            lambda case: case.__setitem__("human", [[0.5, 0.0]]),
            "human: must be a table",
            id="not-a-table",
        ),
        pytest.param(
            lambda case: case["human"]["actions"].__setitem__(1, [0.5, 0.0, 1.0]),
            "human.actions.1: must have at most 2 items",
            id="three-numbers-in-an-action",
        ),
        pytest.param(
            lambda case: case["human"]["actions"][0].__setitem__(1, "left"),
            'human.actions.0.1: must be a number, not "left"',
            id="text-in-an-action",
        ),
        pytest.param(
            lambda case: case["human"].__setitem__("actions", []),
            "human.actions: must not be empty",
            id="no-actions",
        ),
        pytest.param(
            lambda case: case["environment"].__setitem__("seed", "zero"),
            'environment.seed: must be a whole number, not "zero"',
            id="bad-seed",
        ),
        pytest.param(
            lambda case: case["environment"].__setitem__("seed", -4),
            "environment.seed: must be greater than or equal to 0",
            id="negative-seed",
        ),
        pytest.param(
            lambda case: case["environment"].__setitem__("seed", True),
            "environment.seed: must be a whole number, not true",
            id="boolean-seed",
        ),
        pytest.param(
            lambda case: case["environment"].__setitem__("robot", {"max_speed": True}),
            "environment.robot.max_speed: must be a number, not true",
            id="boolean-robot-speed",
        ),
        pytest.param(
            lambda case: case["environment"].__setitem__("episode_duration", "30"),
            'environment.episode_duration: must be a number, not "30"',
            id="duration-as-text",
        ),
        pytest.param(
            lambda case: case["expected"].__setitem__("sim_time", -5),
            "expected.sim_time: must be greater than or equal to 0",
            id="negative-time",
        ),
        pytest.param(
            lambda case: case["expected"].__setitem__("outcome", "explode"),
            "expected.outcome: unknown outcome 'explode': use one of goal, failure",
            id="unknown-outcome",
        ),
        pytest.param(
            lambda case: case["expected"].__setitem__("sim_time", "7.2"),
            'expected.sim_time: must be a number, not "7.2"',
            id="time-as-text",
        ),
        pytest.param(
            lambda case: case["expected"].__setitem__("class", ["side-left/no-stop"]),
            'expected.class: must be text, not ["side-left/no-stop"]',
            id="class-not-text",
        ),
        pytest.param(
            lambda case: case["environment"].__setitem__("decision_period", -2.0),
            "environment.decision_period: must be greater than 0",
            id="negative-decision-period",
        ),
        pytest.param(
            lambda case: case["environment"].__setitem__("episode_lenght", 30.0),
            "environment.episode_lenght: unknown key (did you mean episode_duration?)",
            id="unknown-key",
        ),
        pytest.param(
            lambda case: drop(case["sut"]["controller"], "path"),
            "sut.controller.path: missing",
            id="plugin-without-path",
        ),
        pytest.param(
            lambda case: case.__setitem__("format", 2),
            "format: expected 1, found 2",
            id="other-format",
        ),
        pytest.param(
            lambda case: drop(case["scenario"]["robot"], "goal"),
            "[scenario]: robot.goal: missing",
            id="scenario-without-goal",
        ),
    ],
)
def test_a_malformed_case_file_names_the_file_and_key(cases, tmp_path, break_case, message):
    case = tomllib.loads(next(cases.glob("*.toml")).read_text())
    break_case(case)
    broken = tmp_path / "broken.toml"
    broken.write_text(tomli_w.dumps(case))
    with pytest.raises(CaseError) as error:
        regress_case(broken)
    assert str(error.value).startswith(str(broken))
    assert message in str(error.value)


def test_actions_a_tester_recorded_beyond_the_bounds_are_exported_as_played(run, tmp_path):
    # A searcher may hand the simulation actions outside [-1, 1] (which it clips) and they
    # are recorded as given: the case holds them as played, and still replays the failure.
    beyond = tmp_path / "run"
    shutil.copytree(run, beyond)
    failures = pd.read_parquet(beyond / "failures.parquet")
    actions = [
        np.asarray(list(a), dtype=np.float32).reshape(-1, 2).tolist() for a in failures["actions"]
    ]
    actions[0].append([5.0, -5.0])  # after the failure: never played
    failures["actions"] = actions
    failures.to_parquet(beyond / "failures.parquet")
    summary = json.loads((beyond / "summary.json").read_text())
    summary["checksums"] = file_checksums(beyond)  # as the tester's run wrote it
    (beyond / "summary.json").write_text(json.dumps(summary))
    out = tmp_path / "cases"
    done = hazardhunt("export", beyond, "--out", out, "--all")
    assert done.returncode == 0, done.stderr
    [case] = [
        file
        for file in out.glob("*.toml")
        if tomllib.loads(file.read_text())["found"]["episode"] == failures.at[0, "episode"]
    ]
    assert tomllib.loads(case.read_text())["human"]["actions"][-1] == [1.0, -1.0]
    code, report = regress(case)
    assert (code, [c["verdict"] for c in report["cases"]]) == (1, ["still fails"])


def test_a_case_with_actions_beyond_the_bounds_is_played_clipped_and_says_so(cases, tmp_path):
    # As cases exported before export clipped them hold, or as a hand edit could make them.
    case = tomllib.loads(sorted(cases.glob("*.toml"))[0].read_text())
    case["human"]["actions"][2] = [5.0, 0.0]
    case["human"]["actions"][0] = [0.0, -1.5]
    edited = tmp_path / "edited.toml"
    edited.write_text(tomli_w.dumps(case))
    done = hazardhunt("regress", edited, "--json", "--trust-plugins", cwd=EXAMPLE)
    assert done.returncode in (0, 1), done.stderr  # played, whatever it does now
    assert (
        f"warning: {edited}: human.actions.0.1 (-1.5) and 1 more lie outside [-1, 1]: played "
        "clipped to it, as every action is"
    ) in " ".join(done.stderr.split())


def test_the_pytest_module_fails_while_the_cases_still_fail(run, tmp_path):
    out = tmp_path / "cases"
    done = hazardhunt("export", run, "--out", out, "--pytest", "--trust-plugins")
    assert done.returncode == 0, done.stderr
    assert "TRUST_PLUGINS = True" in (out / "test_hazardhunt_cases.py").read_text()
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(out)],
        capture_output=True,
        text=True,
        cwd=EXAMPLE,
        check=False,
    )
    count = len(list(out.glob("*.toml")))
    assert done.returncode == 1, done.stdout
    assert f"{count} failed" in done.stdout
    assert ": still fails (" in done.stdout  # the SUT fails them, not the module
    assert "UntrustedPluginError" not in done.stdout


def test_case_files_hold_the_recorded_actions_and_times_bit_for_bit(run, cases):
    failures = pd.read_parquet(run / "failures.parquet").set_index("episode")
    for file in sorted(cases.glob("*.toml")):
        case = tomllib.loads(file.read_text())
        recorded = failures.loc[case["found"]["episode"]]
        actions = np.asarray(case["human"]["actions"], dtype=np.float64)
        as_recorded = np.asarray(list(recorded["actions"]), dtype=np.float32).reshape(-1, 2)
        # float32 actions written as Python floats read back as the same float32 values
        assert actions.astype(np.float32).tobytes() == as_recorded.tobytes()
        assert np.array_equal(actions, as_recorded.astype(np.float64))
        assert case["expected"]["sim_time"] == recorded["sim_time"]


def test_a_controller_that_raises_instead_leaves_every_case_untested(cases, tmp_path):
    (tmp_path / "crashing.py").write_text(
        "class Crashing:\n"
        "    control_period = 0.2\n"
        "    def reset(self, floor, route, robot, params):\n"
        "        pass\n"
        "    def control(self, time, robot, human):\n"
        "        raise RuntimeError('no route')\n"
    )
    done = hazardhunt("regress", cases, "--json", "--controller", "crashing:Crashing", cwd=tmp_path)
    assert done.returncode == 3  # neither "fixed" (0) nor "still fails" (1)
    report = json.loads(done.stdout)
    assert {c["verdict"] for c in report["cases"]} == {"error"}
    assert {c["outcome"] for c in report["cases"]} == {"sut_error"}
    assert {c["error"] for c in report["cases"]} == {"controller: RuntimeError: no route"}
    shown = hazardhunt("regress", cases, "--controller", "crashing:Crashing", cwd=tmp_path)
    assert shown.returncode == 3
    assert "error" in shown.stdout
    assert "the SUT erred and the case tested nothing" in shown.stderr


def test_a_controller_that_hangs_is_an_error_within_the_limit_given(cases, tmp_path):
    (tmp_path / "hanging.py").write_text(
        "import time\n"
        "class Hanging:\n"
        "    control_period = 0.2\n"
        "    def reset(self, floor, route, robot, params):\n"
        "        pass\n"
        "    def control(self, time_s, robot, human):\n"
        "        time.sleep(30)\n"
    )
    case = sorted(cases.glob("*.toml"))[0]
    done = hazardhunt(
        "regress", case, "--json", "--controller", "hanging:Hanging", "--controller-timeout",
        0.5, cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 3, done.stderr
    [result] = json.loads(done.stdout)["cases"]
    assert result["verdict"] == "error"
    assert "0.5 s" in result["error"]
    refused = hazardhunt("regress", case, "--controller-timeout", 0, cwd=tmp_path)
    assert refused.returncode == 2
    assert refused.stderr.strip() == "error: controller_timeout: must be greater than 0"


def case_file(folder: Path, controller: dict[str, object], name: str = "received") -> Path:
    """A valid case on the crossing whose SUT's controller is ``controller``."""
    from hazardhunt.world.scenario import scenario_data

    case = {
        "format": 1,
        "environment": {
            "field": "none",
            "seed": 0,
            "decision_period": 2.0,
            "episode_duration": 30.0,
            "stall_duration": 10.0,
        },
        "expected": {"class": "front/moving"},
        "sut": {"controller": controller},
        "human": {"actions": [[0.0, 0.0]] * 15},
        "scenario": scenario_data("crossing"),
    }
    path = folder / f"{name}.toml"
    path.write_text(tomli_w.dumps(case))
    return path


def test_regress_on_a_received_case_imports_nothing_it_names(tmp_path):
    received, here = tmp_path / "received", tmp_path / "here"
    received.mkdir(), here.mkdir()
    pwned, marker = tmp_path / "PWNED", tmp_path / "imported"
    case = case_file(received, hostile_plugin(pwned))
    # A module a case names sits in the case folder and in the working directory.
    marker_module(received, marker)
    marker_module(here, marker)
    other = case_file(received, {"path": "marker_sut:Controller"}, "other")
    for target, path in ((case, "os:system"), (other, "marker_sut:Controller"), (received, None)):
        done = hazardhunt("regress", target, cwd=here)
        assert done.returncode == 2, done.stdout
        [line] = done.stderr.strip().splitlines()
        assert line.startswith("error: ")
        assert ": sut.controller: names the plug-in " in line
        assert "--trust-plugins" in line
        if path is not None:
            assert f"error: {target}: sut.controller: names the plug-in {path!r}" in line
            assert "(--controller package.module:Class)" in line  # one's own, not the case's
            assert f"--controller {path}" not in line
    assert not pwned.exists()
    assert not marker.exists()


def test_regress_never_imports_from_the_case_folder(tmp_path):
    received, here = tmp_path / "received", tmp_path / "here"
    received.mkdir(), here.mkdir()
    marker = tmp_path / "imported"
    path = marker_module(received, marker)  # only next to the case
    case_file(received, {"path": path})
    for option in (["--trust-plugins"], ["--controller", path]):
        done = hazardhunt("regress", received, *option, cwd=here)
        assert done.returncode == 2
        assert "cannot import module 'marker_sut'" in done.stderr
    assert not marker.exists()


@pytest.mark.parametrize(
    "option",
    [["--trust-plugins"], ["--controller", "marker_sut:Controller"]],
    ids=["trusted", "named"],
)
def test_regress_imports_a_case_plug_in_when_allowed_and_says_which(tmp_path, option):
    marker = tmp_path / "imported"
    path = marker_module(tmp_path, marker)
    case = case_file(tmp_path, {"path": path, "params": {"cruise_speed": 0.5}})
    done = hazardhunt("regress", case, "--json", *option, cwd=tmp_path)
    assert done.returncode in (0, 1), done.stderr
    assert "importing module 'marker_sut'" in done.stderr
    assert marker.exists()
    [result] = json.loads(done.stdout)["cases"]
    assert result["outcome"] != "sut_error"


def test_a_received_case_whose_formula_would_take_hours_is_refused_in_one_line(tmp_path):
    case = case_file(tmp_path, {"path": "hazardhunt.benchmark.conservative:ConservativeController"})
    nested = "always[0:3600](" * 40 + "clearance > 0" + ")" * 40
    read = tomllib.loads(case.read_text())
    read["requirement"] = {"name": "gap", "formula": nested}
    read["expected"]["class"] = "gap/clearance"
    case.write_text(tomli_w.dumps(read))
    done = hazardhunt("regress", case, "--trust-plugins", timeout=60)
    assert done.returncode == 2
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith(f"error: {case} [requirement]: requirement 'gap': formula: too costly")


@pytest.mark.parametrize("run_id", ["../../../../ESCAPED", "/tmp/ABSOLUTE"])
def test_a_received_run_id_never_takes_export_outside_its_folder(run, tmp_path, run_id):
    from hazardhunt.campaign.store import file_checksums

    received = tmp_path / "deep" / "er" / "still" / "received"
    shutil.copytree(run, received)
    summary_file = received / "summary.json"
    summary = json.loads(summary_file.read_text())
    summary["run_id"] = run_id
    summary["checksums"] = file_checksums(received)  # as a careful forger would
    summary_file.write_text(json.dumps(summary))
    out = tmp_path / "deep" / "er" / "still" / "cases"
    done = hazardhunt("export", received, "--out", out)
    assert done.returncode == 0, done.stderr
    written = sorted(p for p in tmp_path.rglob("*.toml"))
    assert written
    assert all(path.parent == out for path in written)
    assert not list(Path("/tmp").glob("ABSOLUTE*"))


def test_text_from_a_case_file_reaches_the_terminal_as_text(cases, tmp_path):
    import tomllib

    source = next(cases.glob("*.toml"))
    case = tomllib.loads(source.read_text())
    case["expected"]["class"] = "side\x1b[2J[red]forged[/red]"
    (tmp_path / "forged.toml").write_text(tomli_w.dumps(case))
    done = hazardhunt("regress", tmp_path / "forged.toml", "--trust-plugins", cwd=EXAMPLE)
    assert "\x1b" not in done.stdout + done.stderr
    assert "side\\x1b[2J[red]forged[/red]" in done.stdout


def test_episodes_the_sut_could_not_play_are_not_exported_as_cases(tmp_path):
    from tests.campaign.test_nothing_tested import recorded_as_before_0_2, run_that_wears_out

    run, _ = run_that_wears_out(tmp_path)
    # As versions before 0.2.0 recorded it: the 5 episodes that ended in a SUT error with the
    # violations of the first episode.
    recorded_as_before_0_2(run)
    done = hazardhunt("export", run, "--out", tmp_path / "cases", "--all")
    assert done.returncode == 0, done.stderr
    cases = [tomllib.loads(f.read_text()) for f in (tmp_path / "cases").glob("*.toml")]
    assert f"{len(cases)} cases written" in done.stdout
    assert {case["found"]["episode"] for case in cases} == {0, 1, 2}
    assert all(case["expected"]["outcome"] != "sut_error" for case in cases)


def test_a_requirements_violations_export_as_cases_that_regress_checks_against_it(tmp_path):
    mine = tmp_path / "mine.toml"
    mine.write_text('[requirements.wide-berth]\nformula = "always(clearance >= 1.5)"\n')
    done = hazardhunt(
        "run", "--scenario", "crossing", "--field", "2m", "--tester", "random",
        "--episodes", 12, "--decision-period", 0.2, "--out", tmp_path / "run",
        "--requirement", "separation", "--requirement", mine, "--json",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    counted = json.loads(done.stdout)["requirements"]
    assert counted["wide-berth"]["violations"] > 0
    assert counted["separation"]["violations"] > 0
    violations = pd.read_parquet(tmp_path / "run" / "violations.parquet")
    for name, count in counted.items():
        assert (violations["requirement"] == name).sum() == count["violations"]
    exported = hazardhunt("export", tmp_path / "run", "--out", tmp_path / "cases")
    assert exported.returncode == 0, exported.stderr
    # One case per requirement and the signals that decided its violations, beside the
    # failures' cases, each with its formula inlined.
    read = {f: tomllib.loads(f.read_text()) for f in (tmp_path / "cases").glob("*.toml")}
    judged = {f: case for f, case in read.items() if "requirement" in case}
    expected = {f"{name}/{signals}" for name, c in counted.items() for signals in c["decided_by"]}
    assert {case["expected"]["class"] for case in judged.values()} == expected
    berth = next(case for case in judged.values() if case["requirement"]["name"] == "wide-berth")
    assert berth["requirement"]["formula"] == "always(clearance >= 1.5)"
    regressed = hazardhunt("regress", tmp_path / "cases", "--json")
    code, result = regressed.returncode, json.loads(regressed.stdout)
    assert code == 1  # some case still fails
    by_case = {case["case"]: case for case in result["cases"]}
    for path in judged:
        assert by_case[path.name]["verdict"] == "still fails"
        assert by_case[path.name]["failure_class"] == read[path]["expected"]["class"]
        assert by_case[path.name]["sim_time"] == pytest.approx(read[path]["expected"]["sim_time"])
    # A case whose requirement asks less is fixed; one whose formula does not parse is an error
    # naming the file.
    path = next(p for p, case in judged.items() if case["requirement"]["name"] == "wide-berth")
    lax = read[path] | {"requirement": {"name": "wide-berth", "formula": "always(clearance >= -9)"}}
    path.write_text(tomli_w.dumps(lax))
    assert regress_case(path).verdict == "fixed"
    path.write_text(
        tomli_w.dumps(lax | {"requirement": {"name": "x", "formula": "always(gap > 1)"}})
    )
    with pytest.raises(CaseError, match=rf"{path.name} \[requirement\]: requirement 'x'.*gap"):
        regress_case(path)


@pytest.mark.parametrize(
    "option",
    [["--trust-plugins"], ["--controller", "marker_sut:Controller"]],
    ids=["trusted", "named"],
)
def test_a_plug_in_imported_from_inside_a_received_folder_is_warned_of_first(tmp_path, option):
    received = tmp_path / "received"
    received.mkdir()
    marker = tmp_path / "imported"
    case_file(received, {"path": marker_module(received, marker)})  # shipped beside the case
    done = hazardhunt("regress", received, *option, cwd=received)
    lines = done.stderr.splitlines()
    assert lines[0].startswith(
        f"warning: module 'marker_sut' is imported from {received}, a folder of regression "
        "cases: code that came with results, not code of your own ("
    )
    assert lines[1].startswith("importing module 'marker_sut' (")
    assert marker.exists()


def test_a_plug_in_of_ones_own_beside_a_campaign_file_is_imported_without_a_warning(tmp_path):
    marker = tmp_path / "imported"
    path = marker_module(tmp_path, marker)
    (tmp_path / "campaign.toml").write_text(
        'scenarios = ["head-on"]\nfields = ["none"]\ntesters = ["random"]\nseeds = [0]\n'
        f'episodes = 2\n[controller]\npath = "{path}"\n'
    )
    done = hazardhunt(
        "run", "--scenario", "head-on", "--field", "none", "--episodes", 2,
        "--controller", path, "--out", tmp_path / "run", cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "warning" not in done.stderr
    assert marker.exists()
