"""Every recorded failure replays exactly from its record; a run directory someone sent is data:
replaying, reporting or exporting it imports no plug-in it names unless the user allows it."""

import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from PIL import Image, ImageSequence

from hazardhunt.analysis.report import write_report
from hazardhunt.campaign.config import CampaignConfig, RunConfig
from hazardhunt.campaign.plugins import UntrustedPluginError
from hazardhunt.campaign.replay import replay_failure
from hazardhunt.campaign.run import record_run
from hazardhunt.campaign.store import file_checksums, read_trajectory
from hazardhunt.cases import export_cases, regress_case
from hazardhunt.world.scenario import load_scenario
from tests.helpers import hazardhunt, hostile_plugin, marker_module


@pytest.fixture(scope="module")
def run_with_failures(tmp_path_factory):
    # Random humans often collide with the field-less robot when it overtakes them.
    directory = tmp_path_factory.mktemp("replay") / "run"
    config = RunConfig(scenario="overtaking", field="none", tester="random", seed=0, episodes=20)
    summary = record_run(config, directory)
    assert summary["failures"] >= 1, "the fixture needs a run with failures"
    return directory


def test_every_failure_replays_to_the_same_end(run_with_failures):
    failures = pd.read_parquet(run_with_failures / "failures.parquet")
    for episode in failures["episode"]:
        replay = replay_failure(run_with_failures, int(episode))
        assert replay.matches
        stored = read_trajectory(run_with_failures, int(episode))
        columns = ["time", "human_x", "human_y", "robot_x", "robot_y", "robot_speed"]
        for stored_sample, replayed_sample in zip(stored, replay.result.trajectory, strict=True):
            for column in columns:
                assert getattr(stored_sample, column) == getattr(replayed_sample, column)


def test_replay_command_confirms_and_animates(run_with_failures, tmp_path):
    episode = int(pd.read_parquet(run_with_failures / "failures.parquet")["episode"][0])
    gif = tmp_path / "failure.gif"
    done = hazardhunt("replay", run_with_failures, "--episode", episode, "--gif", gif)
    assert done.returncode == 0, done.stderr
    assert "reproduced" in done.stdout
    with Image.open(gif) as animation:
        assert animation.n_frames > 5
        frames = [
            np.asarray(frame.convert("L")) < 100 for frame in ImageSequence.Iterator(animation)
        ]
    # The floor stays put from frame to frame: the plot's frame lines lie on the same rows.
    frame_lines = {tuple(np.flatnonzero(dark.sum(axis=1) > 0.5 * dark.shape[1])) for dark in frames}
    assert len(frame_lines) == 1


def test_a_record_changed_since_the_run_is_refused_as_damaged(run_with_failures, tmp_path):
    tampered = tmp_path / "run"
    shutil.copytree(run_with_failures, tampered)
    failures = pd.read_parquet(tampered / "failures.parquet")
    episode = int(failures.loc[0, "episode"])
    standing = [[-1.0, 0.0]] * len(failures.loc[0, "actions"])
    failures["actions"] = [standing, *failures["actions"][1:]]  # the first stands still
    failures.to_parquet(tampered / "failures.parquet")
    done = hazardhunt("replay", tampered, "--episode", episode)
    assert done.returncode == 2
    assert "the run is damaged (failures.parquet does not match its checksum" in done.stderr
    assert "reproduced" not in done.stdout
    # Truncated, it is refused the same way, not a traceback.
    (tampered / "failures.parquet").write_bytes(b"PAR1")
    done = hazardhunt("replay", tampered, "--episode", episode)
    assert done.returncode == 2
    assert "the run is damaged" in done.stderr
    assert "Traceback" not in done.stderr
    # A damaged summary is damage too: nothing says "reproduced" of a run that is not whole.
    shutil.copy(run_with_failures / "failures.parquet", tampered / "failures.parquet")
    (tampered / "summary.json").write_text("{")
    done = hazardhunt("replay", tampered, "--episode", episode)
    assert done.returncode == 2
    assert "summary.json cannot be read" in done.stderr


def test_a_signed_record_that_does_not_replay_is_not_reproduced(run_with_failures, tmp_path):
    # A run whose checksums match, as its sender made it, but whose failure does not happen
    # again: exit 1, "NOT reproduced", and what the replay did instead.
    tampered = tmp_path / "run"
    shutil.copytree(run_with_failures, tampered)
    failures = pd.read_parquet(tampered / "failures.parquet")
    standing = [[-1.0, 0.0]] * len(failures.loc[0, "actions"])
    failures["actions"] = [standing, *failures["actions"][1:]]  # the first stands still
    failures.to_parquet(tampered / "failures.parquet")
    signed(tampered)
    done = hazardhunt("replay", tampered, "--episode", int(failures.loc[0, "episode"]))
    assert done.returncode == 1
    assert "NOT reproduced" in done.stdout
    assert "replayed None" not in done.stdout


@pytest.mark.parametrize("where", ["under a file", "a folder", "not a gif"])
def test_a_gif_that_cannot_be_written_is_one_line_before_the_replay(
    run_with_failures, tmp_path, where
):
    episode = int(pd.read_parquet(run_with_failures / "failures.parquet")["episode"][0])
    (tmp_path / "notes.txt").write_text("mine")
    gif, expected = {
        "under a file": (
            tmp_path / "notes.txt" / "failure.gif",
            f"--gif: {tmp_path / 'notes.txt'} is a file, not a directory",
        ),
        "a folder": (
            tmp_path,
            f"--gif: {tmp_path} is a folder; name a file, such as {tmp_path / 'failure.gif'}",
        ),
        "not a gif": (
            tmp_path / "out.txt",
            f"--gif: {tmp_path / 'out.txt'} does not end in .gif; the animation is a GIF, such "
            f"as {tmp_path / 'out.gif'}",
        ),
    }[where]
    done = hazardhunt("replay", run_with_failures, "--episode", episode, "--gif", gif)
    assert done.returncode == 2
    assert done.stdout == ""  # refused before replaying
    assert done.stderr.strip().splitlines() == [f"error: {expected}"]
    assert not (tmp_path / "out.txt").exists()


def test_an_unfinished_run_is_a_clear_error(run_with_failures, tmp_path):
    unfinished = tmp_path / "run"
    shutil.copytree(run_with_failures, unfinished)
    (unfinished / "summary.json").unlink()
    done = hazardhunt("replay", unfinished, "--episode", 0)
    assert done.returncode == 2
    assert "the run has not finished (no summary.json)" in done.stderr


def test_an_unknown_failure_is_a_clear_error(run_with_failures):
    failures = pd.read_parquet(run_with_failures / "failures.parquet")["episode"].tolist()
    shown = ", ".join(map(str, failures[:10])) + (" ..." if len(failures) > 10 else "")
    recorded = (
        f"1 failure, in episode {shown})"
        if len(failures) == 1
        else f"{len(failures)} failures, in episodes {shown})"
    )
    played = pd.read_parquet(run_with_failures / "episodes.parquet")
    done = hazardhunt("replay", run_with_failures, "--episode", 999_999)
    assert done.returncode == 2
    assert done.stderr.strip() == (
        f"error: {run_with_failures}: no failure in episode 999999 (the run played episodes 0 "
        f"to {len(played) - 1} and recorded {recorded}"
    )
    # An episode it played that did not fail says how it ended.
    safe = played[played["outcome"] != "failure"].iloc[0]
    done = hazardhunt("replay", run_with_failures, "--episode", int(safe["episode"]))
    assert done.returncode == 2
    assert done.stderr.strip() == (
        f"error: {run_with_failures}: no failure in episode {safe['episode']} (it ended as "
        f"{safe['outcome']!r}; the run recorded {recorded}"
    )


def received_copy(run_directory, folder, **plugins):
    """A copy of a run directory whose config.json names ``plugins`` (controller, safety_layer)
    as a stranger's could."""
    copy = folder / "run"
    shutil.copytree(run_directory, copy)
    config = json.loads((copy / "config.json").read_text())
    config["run"].update(plugins)
    (copy / "config.json").write_text(json.dumps(config))
    signed(copy)
    return copy


def signed(run_directory):
    """Record the checksums of a run's files as they are now, as a sender's would match."""
    summary = json.loads((run_directory / "summary.json").read_text())
    summary["checksums"] = file_checksums(run_directory)
    (run_directory / "summary.json").write_text(json.dumps(summary))


@pytest.fixture
def received(run_with_failures, tmp_path):
    """A run directory as a stranger could send it: its controller runs a shell command when
    built, its safety layer is a module (in the working directory and in the directory the
    file names) that notes its own import."""
    here = tmp_path / "here"
    here.mkdir()
    evidence = {"pwned": tmp_path / "PWNED", "imported": tmp_path / "imported"}
    layer = marker_module(here, evidence["imported"])
    run = received_copy(
        run_with_failures,
        tmp_path,
        controller=hostile_plugin(evidence["pwned"]),
        safety_layer={"path": layer, "params": {}, "search_path": [str(here)]},
    )
    episode = int(pd.read_parquet(run / "failures.parquet")["episode"][0])
    return run, episode, here, evidence


def test_replaying_a_received_run_imports_nothing_it_names(received):
    run, episode, here, evidence = received
    done = hazardhunt("replay", run, "--episode", episode, cwd=here)
    assert done.returncode == 2
    [line] = done.stderr.strip().splitlines()
    assert line.startswith(f"error: {run / 'config.json'}: run.controller: names the plug-in ")
    assert "'os:system'" in line
    assert "(--controller package.module:Class)" in line  # one's own, not the run's
    assert "--controller os:system" not in line
    assert "(--trust-plugins)" in line
    # Naming another controller is not enough: the safety layer is the run's too.
    done = hazardhunt(
        "replay", run, "--episode", episode, "--controller",
        "hazardhunt.sut.pursuit:PursuitController", cwd=here,
    )  # fmt: skip
    assert done.returncode == 2
    assert "run.safety_layer: names the plug-in 'marker_sut:Controller'" in done.stderr
    assert not evidence["pwned"].exists()
    assert not evidence["imported"].exists()


def test_reporting_and_exporting_a_received_run_imports_nothing(received):
    run, _, here, evidence = received
    report = hazardhunt("report", run, cwd=here)
    assert report.returncode == 0, report.stderr
    representatives = pd.read_csv(run / "report" / "tables" / "representatives.csv")
    assert set(representatives["pictures"]) == {"drawn as recorded"}
    # Its advice never trusts the run's plug-ins wholesale, nor names them as what to type.
    page = (run / "report" / "index.html").read_text()
    assert "--trust-plugins" not in page
    assert "os:system" not in page
    assert "--controller package.module:Class --safety-layer package.module:Class" in page
    assert "The runs name plug-ins of their own (--controller, --safety-layer)" in page
    for name in representatives["class"]:  # drawn from the record: no SUT is built
        stem = run / "report" / "figures" / f"class_{name.replace('/', '_')}"
        assert stem.with_suffix(".png").is_file()
        assert stem.with_suffix(".gif").is_file()
    cases = here / "cases"
    export = hazardhunt("export", run, "--out", cases, "--pytest", cwd=here)
    assert export.returncode == 0, export.stderr
    assert all('path = "os:system"' in case.read_text() for case in cases.glob("*.toml"))
    assert "TRUST_PLUGINS = False" in (cases / "test_hazardhunt_cases.py").read_text()
    regress = hazardhunt("regress", cases, cwd=here)
    assert regress.returncode == 2
    assert "names the plug-in 'os:system'" in regress.stderr
    assert not evidence["pwned"].exists()
    assert not evidence["imported"].exists()


def test_reporting_and_exporting_a_received_campaign_imports_nothing(
    received, tmp_path, monkeypatch
):
    run, _, here, evidence = received
    monkeypatch.chdir(here)
    stored = json.loads((run / "config.json").read_text())["run"]
    config = CampaignConfig(
        scenarios=["overtaking"],
        fields=["none"],
        testers=["random"],
        seeds=[0],
        episodes=stored["episodes"],
        controller=stored["controller"],
        safety_layer=stored["safety_layer"],
    )
    campaign = tmp_path / "campaign"
    (campaign / "runs").mkdir(parents=True)
    (campaign / "campaign.json").write_text(json.dumps(config.model_dump(mode="json")))
    shutil.copytree(run, campaign / "runs" / config.runs()[0].run_id)
    write_report(campaign)
    cases = export_cases(campaign, tmp_path / "cases")
    assert cases
    with pytest.raises(UntrustedPluginError, match="names the plug-in 'os:system'"):
        regress_case(cases[0])
    assert not evidence["pwned"].exists()
    assert not evidence["imported"].exists()
    assert "marker_sut" not in sys.modules


def test_no_command_builds_the_tester_a_received_run_names(run_with_failures, tmp_path):
    # A portfolio's arm of one's own is an import path in the run's tester settings.
    here = tmp_path / "here"
    here.mkdir()
    marker = tmp_path / "imported"
    arm = {"name": "theirs", "method": marker_module(here, marker)}
    run = received_copy(
        run_with_failures, tmp_path, tester="portfolio", tester_params={"arms": [arm]}
    )
    episode = int(pd.read_parquet(run / "failures.parquet")["episode"][0])
    replay = hazardhunt("replay", run, "--episode", episode, cwd=here)
    assert replay.returncode == 0, replay.stderr
    assert "reproduced" in replay.stdout
    assert hazardhunt("report", run, cwd=here).returncode == 0
    assert hazardhunt("export", run, "--out", here / "cases", cwd=here).returncode == 0
    again = hazardhunt(
        "run", "--out", run, "--scenario", "overtaking", "--field", "none", "--tester",
        "random", "--episodes", 20, cwd=here,
    )  # fmt: skip
    assert again.returncode == 2
    assert "holds a finished run of another configuration (tester: there 'portfolio'" in (
        again.stderr
    )
    # The same settings in a received campaign's record.
    config = CampaignConfig(
        scenarios=["overtaking"], fields=["none"], testers=["portfolio"], seeds=[0], episodes=20
    )
    campaign = tmp_path / "campaign"
    (campaign / "runs").mkdir(parents=True)
    stored = {**config.model_dump(mode="json"), "tester": {"portfolio": {"arms": [arm]}}}
    (campaign / "campaign.json").write_text(json.dumps(stored))
    shutil.copytree(run, campaign / "runs" / config.runs()[0].run_id)
    for command in (
        ["report"],
        ["export", "--out", here / "cases-2"],
        ["copy", "--out", here / "c"],
    ):
        done = hazardhunt(command[0], campaign, *command[1:], cwd=here)
        assert done.returncode == 0, (command, done.stderr)
    assert not marker.exists()


def test_a_replay_whose_controller_hangs_ends_within_the_limit_given(run_with_failures, tmp_path):
    (tmp_path / "hanging.py").write_text(
        "import time\n"
        "from hazardhunt.sut.pursuit import PursuitController\n"
        "class Hanging(PursuitController):\n"
        "    def control(self, time_s, robot, human):\n"
        "        time.sleep(30)\n"
    )
    episode = int(pd.read_parquet(run_with_failures / "failures.parquet")["episode"][0])
    done = hazardhunt(
        "replay", run_with_failures, "--episode", episode, "--controller", "hanging:Hanging",
        "--controller-timeout", 0.5, cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 1
    assert "NOT reproduced: the SUT erred" in done.stdout
    assert "time limit of 0.5 s" in done.stdout + done.stderr


def test_replay_imports_a_stored_plug_in_when_allowed_and_says_which(run_with_failures, tmp_path):
    marker = tmp_path / "imported"
    controller = marker_module(tmp_path, marker)
    run = received_copy(run_with_failures, tmp_path, controller={"path": controller})
    episode = int(pd.read_parquet(run / "failures.parquet")["episode"][0])
    for option in (["--trust-plugins"], ["--controller", controller]):
        marker.unlink(missing_ok=True)
        done = hazardhunt("replay", run, "--episode", episode, *option, cwd=tmp_path)
        assert done.returncode in (0, 1), done.stderr  # another SUT need not reproduce it
        assert f"episode {episode}: recorded failure" in done.stdout
        assert "importing module 'marker_sut'" in done.stderr
        assert marker.exists()


def test_a_trusted_plug_in_is_not_looked_for_where_the_file_says(run_with_failures, tmp_path):
    elsewhere, here = tmp_path / "elsewhere", tmp_path / "here"
    elsewhere.mkdir(), here.mkdir()
    marker = tmp_path / "imported"
    controller = marker_module(elsewhere, marker)
    run = received_copy(
        run_with_failures,
        tmp_path,
        controller={"path": controller, "params": {}, "search_path": [str(elsewhere)]},
    )
    episode = int(pd.read_parquet(run / "failures.parquet")["episode"][0])
    done = hazardhunt("replay", run, "--episode", episode, "--trust-plugins", cwd=here)
    assert done.returncode == 2
    assert "cannot import module 'marker_sut'" in done.stderr
    assert not marker.exists()


def test_a_requirements_violation_replays_by_the_formula_recorded_with_it(tmp_path):
    mine = tmp_path / "mine.toml"
    mine.write_text('[requirements.wide-berth]\nformula = "always(clearance >= 1.5)"\n')
    directory = tmp_path / "run"
    config = RunConfig(
        scenario="crossing",
        field="2m",
        tester="random",
        seed=0,
        episodes=12,
        requirements=[str(mine)],
    )
    record_run(config, directory)
    mine.unlink()  # the run's file is gone: the formula recorded with the violation judges
    violations = pd.read_parquet(directory / "violations.parquet")
    failures = set(pd.read_parquet(directory / "failures.parquet")["episode"])
    kept_apart = violations[~violations["episode"].isin(failures)]
    assert not kept_apart.empty, "the fixture needs a violation without a contact"
    row = kept_apart.iloc[0]
    replay = replay_failure(directory, int(row["episode"]))
    assert replay.matches
    assert replay.result.verdicts["wide-berth"].robustness == row["robustness"]
    done = hazardhunt("replay", directory, "--episode", int(row["episode"]))
    assert done.returncode == 0, done.stderr
    assert "reproduced" in done.stdout
    assert f"requirement wide-berth: recorded robustness {row['robustness']:.6g}" in done.stdout
    # A violation whose record says another robustness is not reproduced.
    violations.loc[violations.index == row.name, "robustness"] = row["robustness"] - 0.1
    violations.to_parquet(directory / "violations.parquet")
    signed(directory)
    assert not replay_failure(directory, int(row["episode"])).matches


def test_a_run_replays_and_exports_the_scenario_it_played_after_its_file_changed(tmp_path):
    built_in = Path(load_scenario("overtaking").source)
    shutil.copy(built_in.parent / "shopfloor.toml", tmp_path / "shopfloor.toml")
    mine = tmp_path / "mine.toml"
    mine.write_text(built_in.read_text())
    directory = tmp_path / "run"
    config = RunConfig(scenario=str(mine), field="none", tester="random", seed=0, episodes=20)
    assert record_run(config, directory)["failures"] >= 1, "the fixture needs failures"
    failures = pd.read_parquet(directory / "failures.parquet")
    # The user moves the human 1 m back in the file: the run's episodes were not played so.
    mine.write_text(built_in.read_text().replace("x = 5.0, y = 10.0", "x = 4.0, y = 10.0"))
    for episode in failures["episode"]:
        assert replay_failure(directory, int(episode)).matches
    episode = int(failures["episode"].iloc[0])
    done = hazardhunt("replay", directory, "--episode", episode)
    assert done.returncode == 0, done.stderr
    assert "reproduced" in done.stdout
    assert f"{mine}: has changed or gone since the run; replayed on the scenario" in done.stderr
    cases = export_cases(directory, tmp_path / "cases")
    assert cases
    for case in cases:
        assert "x = 5.0" in case.read_text()  # the human where the run had it
        assert regress_case(case).verdict == "still fails"
    # Run again into the same folder, the run made on the old file is played anew on the new.
    again = hazardhunt(
        "run", "--scenario", mine, "--field", "none", "--tester", "random", "--seed", 0,
        "--episodes", 20, "--out", directory,
    )  # fmt: skip
    assert again.returncode == 0, again.stderr
    assert f"played on {mine} before the file changed; running it again" in again.stderr
    assert json.loads((directory / "scenario.json").read_text())["human"]["start"]["x"] == 4.0
    # Sent elsewhere without its scenario file, the run replays, reports and exports all the same.
    mine.unlink()
    [episode, *_] = pd.read_parquet(directory / "failures.parquet")["episode"]
    assert replay_failure(directory, int(episode)).matches
    assert hazardhunt("report", directory).returncode == 0
    assert export_cases(directory, tmp_path / "cases elsewhere")
