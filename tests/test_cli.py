"""The `hazardhunt` command itself: its version, and the starting point for your own SUT."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest

import hazardhunt
from tests.helpers import hazardhunt as command

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

PYPROJECT = Path(__file__).parents[1] / "pyproject.toml"


def test_version_prints_the_package_version() -> None:
    result = command("--version")
    assert result.returncode == 0, result.stderr
    packaged = tomllib.loads(PYPROJECT.read_text())["project"]["version"]
    assert result.stdout == f"hazardhunt {packaged}\n"
    assert hazardhunt.__version__ == packaged


@pytest.mark.parametrize(
    ("subcommand", "shown"),
    [
        ("run", "Budget of episodes [default: 20,000"),
        ("estimate", "package.module:Class [default: the built-in shop-floor walkers]"),
        ("estimate", "or none [default: the built-in ones]"),
    ],
)
def test_help_shows_the_defaults_written_in_brackets(subcommand: str, shown: str) -> None:
    # Rich reads an unescaped "[default: ...]" as markup and drops it from the help.
    result = command(subcommand, "--help")
    assert result.returncode == 0, result.stderr
    assert shown in " ".join(result.stdout.split())


@pytest.mark.parametrize(
    ("subcommand", "replaced"),
    [
        ("run", "the built-in NMPC"),
        ("estimate", "the built-in NMPC"),
        ("regress", "the case's own"),
    ],
)
def test_help_says_what_a_controller_of_ones_own_replaces_there(subcommand, replaced):
    result = command(subcommand, "--help")
    assert result.returncode == 0, result.stderr
    text = " ".join(result.stdout.replace("│", " ").split())
    assert "package.module:Class" in text
    assert f"instead of {replaced}." in text
    assert "regress" not in text or subcommand == "regress"
    assert "for campaign" not in text  # the classifier's help said what it does in campaign


def test_campaign_help_says_its_classifier_replaces_the_campaign_files():
    result = command("campaign", "--help")
    assert result.returncode == 0, result.stderr
    text = " ".join(result.stdout.replace("│", " ").split())
    assert "instead of the campaign file's [classifier] table or the built-in one." in text


@pytest.mark.parametrize("subcommand", ["--help", "run", "export", "regress", "campaign"])
def test_help_shows_no_value_for_a_flag_and_what_a_repeated_option_takes(subcommand: str) -> None:
    result = command(*([subcommand] if subcommand == "--help" else [subcommand, "--help"]))
    assert result.returncode == 0, result.stderr
    rows = {line.split()[1]: line for line in result.stdout.splitlines() if "│  " in line[:6]}
    rows |= {line.split()[2]: line for line in result.stdout.splitlines() if "│ *" in line[:4]}
    assert "<bool>" not in result.stdout  # a flag takes no value
    assert "list[" not in result.stdout
    if subcommand == "run":
        assert "KEY=VALUE" in rows["--tester-param"]
        assert "NAME" in rows["--requirement"]
    if subcommand == "campaign":
        assert "PATTERN" in rows["--runs"]


@pytest.mark.parametrize(
    ("subcommand", "usage"),
    [
        ("report", "report [OPTIONS] DIRECTORY"),
        ("replay", "replay [OPTIONS] RUN_DIRECTORY"),
        ("scenarios", "scenarios [OPTIONS] [NAMES]..."),
    ],
)
def test_the_usage_line_names_the_arguments_as_the_help_does(subcommand: str, usage: str) -> None:
    result = command(subcommand, "--help")
    assert result.returncode == 0, result.stderr
    assert f" {usage} " in " ".join(result.stdout.split())


def test_run_help_gives_tester_parameters_of_the_default_tester() -> None:
    result = command("run", "--help")
    assert result.returncode == 0, result.stderr
    text = " ".join(result.stdout.replace("│", " ").split())
    assert "e.g. workers=2 (portfolio, cem, qd)" in text


def test_the_list_of_commands_shows_each_summary_whole_on_its_row() -> None:
    result = command("--help")
    assert result.returncode == 0, result.stderr
    rows = {line.split()[1]: line for line in result.stdout.splitlines() if line.startswith("│ ")}
    assert "DIRECTORY/report (for an estimate: its probabilities, convergence" in rows["report"]
    assert "a floor map and a scenario to edit, a campaign file" in rows["new-sut"]


def test_new_sut_writes_a_starting_point_and_refuses_a_folder_in_use(tmp_path: Path) -> None:
    folder = tmp_path / "my_robot"
    result = command("new-sut", folder)
    assert result.returncode == 0, result.stderr
    assert sorted(p.name for p in folder.iterdir()) == [
        "README.md",
        "campaign.toml",
        "my_controller.py",
        "my_floor.toml",
        "my_scenario.toml",
    ]
    readme = (folder / "README.md").read_text()
    for step in ("hazardhunt campaign campaign.toml", "hazardhunt report", "hazardhunt regress"):
        assert step in readme
    before = (folder / "my_controller.py").read_text()
    again = command("new-sut", folder)
    assert again.returncode == 2
    assert again.stderr.strip().splitlines() == [
        f"error: {folder}: exists and is not empty; name a new folder"
    ]
    assert (folder / "my_controller.py").read_text() == before


@pytest.mark.parametrize(
    ("arguments", "option"),
    [
        (["new-sut", "{out}"], "DIRECTORY"),
        (["scenarios", "head-on", "--out", "{out}"], "--out"),
        (["export", "{run}", "--out", "{out}"], "--out"),
    ],
)
def test_an_output_folder_under_a_file_is_one_line_and_exit_2(
    tmp_path: Path, arguments: list[str], option: str
) -> None:
    (tmp_path / "notes.txt").write_text("mine")
    run = tmp_path / "run"
    if "{run}" in arguments:
        made = command(
            "run", "--scenario", "head-on", "--field", "none", "--tester", "random",
            "--episodes", 2, "--out", run,
        )  # fmt: skip
        assert made.returncode == 0, made.stderr
    out = tmp_path / "notes.txt" / "folder"
    done = command(*(a.format(out=out, run=run) for a in arguments))
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        f"error: {option}: {tmp_path / 'notes.txt'} is a file, not a directory"
    ]
    assert (tmp_path / "notes.txt").read_text() == "mine"


def test_the_new_controller_drives_its_scenario_and_meets_the_robot_it_is_given(
    tmp_path: Path,
) -> None:
    """The generated controller and scenario in a short run, with a slower robot than the
    default: the controller takes its speed limit from the robot it is given."""
    folder = tmp_path / "my_robot"
    assert command("new-sut", folder).returncode == 0
    spec = importlib.util.spec_from_file_location("my_controller", folder / "my_controller.py")
    assert spec is not None
    assert spec.loader is not None
    generated = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(generated)  # the generated file, unmodified
    from hazardhunt.sim import Simulation
    from hazardhunt.world.bodies import RobotParams

    standing = np.zeros((15, 2))
    standing[:, 0] = -1.0  # the human stands still where it starts, out of the robot's way
    for robot in (RobotParams(), RobotParams(max_speed=0.6)):
        simulation = Simulation.build(
            str(folder / "my_scenario.toml"),
            "sides",
            controller=generated.MyController(),
            robot=robot,
        )
        result = simulation.simulate(standing)
        assert result.summary.outcome == "goal"
        top_speed = max(sample.robot_speed for sample in result.trajectory)
        assert robot.max_speed - 0.05 < top_speed <= robot.max_speed + 1e-9


@pytest.mark.slow
def test_the_new_sut_folder_runs_its_readme_commands_unmodified(tmp_path: Path) -> None:
    folder = tmp_path / "my_robot"
    assert command("new-sut", folder).returncode == 0
    # The README's commands, from the folder, as a user types them.
    campaign = command(
        "campaign", "campaign.toml", "--out", "results", "--workers", "2", cwd=folder, timeout=600
    )
    assert campaign.returncode == 0, campaign.stderr
    summary = json.loads((folder / "results" / "summary.json").read_text())
    assert summary["runs_complete"] == summary["runs_total"] == 4
    for entry in summary["runs"]:
        config = json.loads(
            (folder / "results" / "runs" / entry["run_id"] / "config.json").read_text()
        )
        assert config["run"]["controller"]["path"] == "my_controller:MyController"
    found = {(e["field"], e["tester"]): e["failures"] for e in summary["runs"]}
    assert found[("none", "portfolio")] > found[("none", "random")]
    report = command("report", "results", cwd=folder)
    assert report.returncode == 0, report.stderr
    page = (folder / "results" / "report" / "index.html").read_text()
    # The scenario named as the campaign's table names it, not by where the folder lies.
    assert "my_scenario.toml" in page
    assert str(folder / "my_scenario.toml") not in page
    exported = command("export", "results", "--out", "cases", cwd=folder)
    assert exported.returncode == 0, exported.stderr
    cases = len(list((folder / "cases").glob("*.toml")))
    assert f"{cases} cases written to " in exported.stdout
    regress = command("regress", "cases", "--controller", "my_controller:MyController", cwd=folder)
    assert regress.returncode == 1, regress.stderr  # the failures are still there
    assert f"{cases} cases: still fails: {cases}, changed: 0, error: 0, fixed: 0" in regress.stdout
