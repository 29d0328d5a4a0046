"""A campaign runs its whole grid, survives a kill, and refuses what it cannot use."""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from hazardhunt.campaign import config as config_module
from hazardhunt.campaign.config import load_campaign
from hazardhunt.campaign.progress import shown_scenario
from hazardhunt.world.scenario import Scenario, load_scenario
from tests.helpers import hazardhunt, run_tables

EPISODES = 6
GRID = f"""\
scenarios = ["head-on", "overtaking"]
fields = ["2m"]
testers = ["random"]
seeds = [0, 1]
episodes = {EPISODES}
"""
"""Four short runs; overtaking with the 2 m field yields failures within them."""


def episodes_table(run_directory: Path) -> pd.DataFrame:
    return run_tables(run_directory)[0]


def assert_same_runs(campaign: Path, reference: Path, run_ids: list[str] | None = None) -> None:
    """Every run of ``campaign`` recorded what the reference recorded, episode for episode."""
    run_ids = run_ids or sorted(p.name for p in (reference / "runs").iterdir())
    assert sorted(p.name for p in (campaign / "runs").iterdir()) == sorted(run_ids)
    for run_id in run_ids:
        run, expected = campaign / "runs" / run_id, reference / "runs" / run_id
        episodes = episodes_table(run)
        assert episodes["episode"].tolist() == list(range(EPISODES)), run_id
        pd.testing.assert_frame_equal(episodes, episodes_table(expected))
        pd.testing.assert_frame_equal(
            pd.read_parquet(run / "failures.parquet"),
            pd.read_parquet(expected / "failures.parquet"),
        )


def snapshot(directory: Path) -> dict[str, tuple[int, int]]:
    """Every file under ``directory`` with its size and modification time."""
    return {
        str(path.relative_to(directory)): (path.stat().st_size, path.stat().st_mtime_ns)
        for path in directory.rglob("*")
        if path.is_file()
    }


@pytest.fixture(scope="module")
def campaign_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("files") / "grid.toml"
    path.write_text(GRID)
    return path


@pytest.fixture(scope="module")
def reference(campaign_file: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The grid run uninterrupted with one worker."""
    out = tmp_path_factory.mktemp("reference") / "campaign"
    result = hazardhunt("campaign", campaign_file, "--out", out, "--workers", "1")
    assert result.returncode == 0, result.stderr
    return out


def test_two_workers_record_the_same_episodes_as_one(
    campaign_file: Path, reference: Path, tmp_path: Path
) -> None:
    out = tmp_path / "campaign"
    result = hazardhunt("campaign", campaign_file, "--out", out, "--workers", "2")
    assert result.returncode == 0, result.stderr
    assert_same_runs(out, reference)
    summary = json.loads((out / "summary.json").read_text())
    assert (summary["runs_total"], summary["runs_complete"], summary["episodes"]) == (4, 4, 24)
    assert summary["failures"] > 0
    assert json.loads((out / "campaign.json").read_text())["seeds"] == [0, 1]
    assert str(out.resolve()) in result.stdout


def test_a_campaign_run_in_slices_ends_as_the_whole_campaign_run_at_once(
    campaign_file: Path, reference: Path, tmp_path: Path
) -> None:
    out = tmp_path / "campaign"
    first = hazardhunt("campaign", campaign_file, "--out", out, "--runs", "overtaking__*__seed0")
    assert first.returncode == 0, first.stderr
    said = " ".join(first.stdout.split())
    assert "3 runs not run yet (the table leaves out 1 scenario x field x tester group" in said
    assert "│ overtaking │" in first.stdout
    assert "│ head-on" not in first.stdout
    summary = json.loads((out / "summary.json").read_text())
    assert (summary["runs_complete"], summary["runs_pending"]) == (1, 3)
    assert_same_runs(out, reference, ["overtaking__2m__random__seed0"])
    rest = hazardhunt(
        "campaign", campaign_file, "--out", out, "--runs", "*seed1", "--runs", "head-on*"
    )
    assert rest.returncode == 0, rest.stderr
    assert "not run yet" not in rest.stdout
    assert_same_runs(out, reference)


def test_a_slice_that_matches_no_run_is_one_line_and_writes_nothing(
    campaign_file: Path, tmp_path: Path
) -> None:
    out = tmp_path / "campaign"
    result = hazardhunt("campaign", campaign_file, "--out", out, "--runs", "crossing*")
    assert result.returncode == 2
    assert result.stderr.strip() == (
        "error: --runs: 'crossing*' matches no run of the campaign; its run ids look like "
        "'head-on__2m__random__seed0' (scenario__field__tester__seedN)"
    )
    assert not out.exists()


def live_processes_in_group(group: int) -> list[int]:
    """Processes of a process group that still run (zombies are dead, merely unreaped)."""
    alive = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
        except OSError:
            continue
        state, _, process_group = text[text.rindex(")") + 2 :].split()[:3]
        if int(process_group) == group and state not in ("Z", "X"):
            alive.append(int(stat.parent.name))
    return alive


@pytest.mark.skipif(sys.platform != "linux", reason="workers die with the campaign on Linux")
@pytest.mark.slow
def test_a_killed_campaign_leaves_no_worker_and_resumes_to_the_same_results(
    campaign_file: Path, reference: Path, tmp_path: Path
) -> None:
    out = tmp_path / "campaign"
    command = [sys.executable, "-m", "hazardhunt.cli", "campaign", str(campaign_file)]
    command += ["--out", str(out), "--workers", "2"]
    campaign = subprocess.Popen(
        command,
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=os.environ | {"COLUMNS": "1000"},
    )
    runs = out / "runs"
    try:
        deadline = time.monotonic() + 60
        while not (
            runs.is_dir()
            and any(p.is_dir() and not p.name.startswith(".") for p in runs.iterdir())
            and any(runs.glob(".*.partial"))
        ):
            assert campaign.poll() is None, "the campaign ended before it could be killed"
            assert time.monotonic() < deadline
            time.sleep(0.02)
        # Only the campaign process: its workers must follow it by themselves.
        os.kill(campaign.pid, signal.SIGKILL)
        campaign.wait()
        deadline = time.monotonic() + 5
        while live_processes_in_group(campaign.pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert live_processes_in_group(campaign.pid) == []
        before = snapshot(out)
        time.sleep(1)
        assert snapshot(out) == before, "something still writes after the campaign died"
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(campaign.pid, signal.SIGKILL)
    complete = [p for p in runs.iterdir() if p.is_dir() and not p.name.startswith(".")]
    if len(complete) == 4:  # the last run finished between the check and the kill
        pytest.skip("the campaign finished before the kill landed; nothing to resume")
    result = hazardhunt("campaign", campaign_file, "--out", out, "--workers", "2")
    assert result.returncode == 0, result.stderr
    assert not list(runs.glob(".*"))
    assert_same_runs(out, reference)
    assert json.loads((out / "summary.json").read_text())["runs_complete"] == 4


def test_running_a_complete_campaign_again_changes_no_run(
    campaign_file: Path, reference: Path
) -> None:
    before = snapshot(reference / "runs")
    result = hazardhunt("campaign", campaign_file, "--out", reference)
    assert result.returncode == 0, result.stderr
    assert snapshot(reference / "runs") == before


def test_the_end_of_run_table_counts_failures_in_whole_numbers(tmp_path: Path) -> None:
    file, out = tmp_path / "one-seed.toml", tmp_path / "campaign"
    file.write_text(GRID.replace("seeds = [0, 1]", "seeds = [0]"))
    result = hazardhunt("campaign", file, "--out", out)
    assert result.returncode == 0, result.stderr
    rows = {
        cells[0]: cells
        for line in result.stdout.splitlines()
        if line.startswith("│")
        for cells in [[cell.strip() for cell in line.strip("│").split("│")]]
    }
    recorded = json.loads((out / "summary.json").read_text())["runs"]
    assert {entry["scenario"]: entry["failures"] for entry in recorded}["overtaking"] > 0
    for entry in recorded:
        assert rows[entry["scenario"]][4] == str(entry["failures"])  # 4, not 4.0


def test_a_campaign_written_to_a_log_file_says_how_far_it_is(tmp_path: Path) -> None:
    # Progress bars do not show in a file: each run that ends writes a line instead, whole
    # however narrow the terminal the command was started from.
    file, out = tmp_path / "one-seed.toml", tmp_path / "campaign"
    file.write_text(GRID.replace("seeds = [0, 1]", "seeds = [0]"))
    result = subprocess.run(
        [sys.executable, "-m", "hazardhunt.cli", "campaign", str(file), "--out", str(out)],
        capture_output=True,
        text=True,
        env=os.environ | {"COLUMNS": "40"},
        check=False,
    )
    assert result.returncode == 0, result.stderr
    lines = [line for line in result.stdout.splitlines() if line.startswith("run ")]
    assert sorted(line.split()[1] for line in lines) == [
        "head-on__2m__random__seed0",
        "overtaking__2m__random__seed0",
    ]
    assert all(" complete: " in line for line in lines)
    total = 2 * EPISODES
    assert lines[-1].endswith(f"2 of 2 runs ended, {total:,} of {total:,} episodes (100%)")
    # No progress bar either, cut off at the end of the log.
    bars = [line for line in result.stdout.splitlines() if line.lstrip().startswith("runs ━")]
    assert bars == []


def test_settings_of_a_tester_the_campaign_does_not_run_are_pointed_out(tmp_path: Path) -> None:
    file, out = tmp_path / "one-seed.toml", tmp_path / "campaign"
    settings = '[tester.qd]\nemitters = 2\n[tester.cem-aim]\nmethod = "cem"\n'
    file.write_text(GRID.replace("seeds = [0, 1]", "seeds = [0]") + settings)
    result = hazardhunt("campaign", file, "--out", out)
    assert result.returncode == 0, result.stderr
    warnings = [line for line in result.stderr.splitlines() if line.startswith("warning:")]
    assert warnings == [
        f"warning: {file}: [tester.{name}] is not run (testers = ['random']): its settings "
        "are not used"
        for name in ("qd", "cem-aim")
    ]


def test_a_slice_written_to_a_log_file_counts_its_own_runs(tmp_path: Path) -> None:
    file, out = tmp_path / "two-seeds.toml", tmp_path / "campaign"
    file.write_text(GRID)
    first = hazardhunt("campaign", file, "--out", out, "--runs", "head-on__*__seed0")
    assert first.returncode == 0, first.stderr
    assert first.stdout.splitlines()[0].startswith("run head-on__2m__random__seed0 complete: ")
    assert f"1 of 1 runs ended, {EPISODES:,} of {EPISODES:,} episodes (100%)" in first.stdout
    second = hazardhunt("campaign", file, "--out", out, "--runs", "*__seed1")
    assert second.returncode == 0, second.stderr
    total = 3 * EPISODES
    assert f"3 of 3 runs ended, {total:,} of {total:,} episodes (100%)" in second.stdout


@pytest.mark.slow
def test_ray_records_the_same_episodes_as_local(
    campaign_file: Path, reference: Path, tmp_path: Path
) -> None:
    file = tmp_path / "two-runs.toml"
    file.write_text(GRID.replace("seeds = [0, 1]", "seeds = [1]"))
    out = tmp_path / "campaign"
    result = hazardhunt(
        "campaign", file, "--out", out, "--executor", "ray", "--workers", "2", timeout=300
    )
    assert result.returncode == 0, result.stderr
    assert_same_runs(
        out, reference, ["head-on__2m__random__seed1", "overtaking__2m__random__seed1"]
    )
    assert not list((out / "runs").glob(".*"))


@pytest.mark.parametrize(
    ("text", "field"),
    [
        pytest.param("scenarios = [", "TOML", id="malformed"),
        pytest.param(GRID + "budget = 3\n", "budget", id="unknown-key"),
        pytest.param(
            GRID.replace("episodes =", "episods ="),
            "episods: unknown key (did you mean episodes?) (and 1 more problem)",
            id="misspelt-key",
        ),
        pytest.param(GRID.replace('"head-on"', '"roundabout"'), "scenarios", id="scenario"),
        pytest.param(GRID.replace('"random"', '"greedy"'), "testers", id="tester"),
        pytest.param(GRID.replace('"2m"', '"3m"'), "fields", id="field"),
        pytest.param(
            GRID + "[tester.greedy]\nn_steps = 8\n", "tester.greedy: unknown", id="tester-table"
        ),
        pytest.param(
            GRID + "[tester.ppo-max]\nn_step = 8\n",
            "tester.ppo-max.n_step: unknown parameter",
            id="tester-parameter",
        ),
        pytest.param(GRID.replace(f"= {EPISODES}", "= 0"), "episodes", id="no-episodes"),
        pytest.param(GRID.replace("[0, 1]", "[]"), "seeds", id="no-seeds"),
        pytest.param(None, "no such campaign file", id="missing-file"),
        # Settings that passed the first check and failed once the runs had started.
        pytest.param(
            GRID + "[env]\ndecision_period = 0.3\n",
            "env.decision_period: 0.3 s is not a whole multiple of the controller's period",
            id="decision-period",
        ),
        pytest.param(
            GRID + "[env]\ndecision_period = inf\n",
            "env.decision_period: must be a finite number",
            id="infinite-decision-period",
        ),
        pytest.param(
            GRID + "[env]\ndecision_period = 1e9\n",
            "env.decision_period: 1e+09 s is longer than an episode",
            id="huge-decision-period",
        ),
        pytest.param(
            GRID + "[env]\nepisode_duration = nan\n",
            "env.episode_duration: must be a finite number",
            id="nan-duration",
        ),
        pytest.param(
            GRID + "[tester.random]\nattemps = 3\n",
            "tester.random.attemps: unknown parameter; the tester takes attempts",
            id="random-parameter",
        ),
        pytest.param(
            GRID + "[tester.ppo-max]\nlearning_rate = -1\n",
            "tester.ppo-max.learning_rate: must be a number in (0, 1], not -1",
            id="learning-rate",
        ),
        pytest.param(
            GRID + "[tester.ppo-max]\nn_steps = 1\n",
            "tester.ppo-max.n_steps: n_steps x n_envs (1) must be from 2",
            id="one-step",
        ),
        pytest.param(
            GRID + "[tester.ppo-acc]\nbatch_size = 0\n",
            "tester.ppo-acc.batch_size: must be a whole number >= 2, not 0",
            id="batch-size",
        ),
        pytest.param(
            GRID + "[tester.ppo-max]\ngamma = 5\n",
            "tester.ppo-max.gamma: must be a number in (0, 1], not 5",
            id="gamma",
        ),
        pytest.param(
            GRID + "[tester.ppo-max]\nn_envs = 1000\n",
            "tester.ppo-max.n_envs: must be a whole number from 1 to 64, not 1000",
            id="n-envs",
        ),
        # Values of another type are refused, not coerced.
        pytest.param(
            GRID.replace(f"= {EPISODES}", "= true"),
            "episodes: must be a whole number, not true",
            id="boolean-episodes",
        ),
        pytest.param(
            GRID.replace("[0, 1]", '["0", "1"]'),
            'seeds.0: must be a whole number, not "0"',
            id="string-seeds",
        ),
        pytest.param(
            GRID + "[env.robot]\nmax_speed = true\n",
            "env.robot.max_speed: must be a number, not true",
            id="boolean-robot-speed",
        ),
        pytest.param(
            GRID + '[env.robot]\nmax_speed = "1.1"\n',
            'env.robot.max_speed: must be a number, not "1.1"',
            id="string-robot-speed",
        ),
        pytest.param(
            GRID + "[env.robot]\nmax_sped = 1.1\n",
            "env.robot.max_sped: unknown key (did you mean max_speed?)",
            id="unknown-robot-key",
        ),
        pytest.param(
            GRID + "[env]\ncontroller_timeout = true\n",
            "env.controller_timeout: must be a number, not true",
            id="boolean-timeout",
        ),
        pytest.param(
            GRID + '[env]\ncontroller_timeout = "5"\n',
            'env.controller_timeout: must be a number, not "5"',
            id="string-timeout",
        ),
        pytest.param(
            GRID.replace("[0, 1]", "[0, 5000000000]"),
            "seeds.1: must be less than or equal to 4294967295",
            id="seed-a-case-cannot-hold",
        ),
    ],
)
def test_bad_input_is_one_line_naming_file_and_field(
    text: str | None, field: str, tmp_path: Path
) -> None:
    file, out = tmp_path / "campaign.toml", tmp_path / "out"
    if text is not None:
        file.write_text(text)
    result = hazardhunt("campaign", file, "--out", out)
    assert result.returncode == 2
    [line] = result.stderr.strip().splitlines()
    assert str(file) in line
    assert field in line
    assert not out.exists()


def test_another_campaign_in_the_same_directory_is_refused(
    campaign_file: Path, reference: Path, tmp_path: Path
) -> None:
    other = tmp_path / "other.toml"
    other.write_text(GRID.replace("seeds = [0, 1]", "seeds = [0, 1, 2]"))
    before = snapshot(reference)
    result = hazardhunt("campaign", other, "--out", reference)
    assert result.returncode == 2
    [line] = result.stderr.strip().splitlines()
    assert "different campaign" in line
    assert "seeds" in line
    assert snapshot(reference) == before


def test_two_campaigns_never_write_one_directory(campaign_file: Path, reference: Path) -> None:
    before = snapshot(reference)
    with open(reference / ".lock", "a+") as lock:
        fcntl.flock(lock.fileno(), fcntl.LOCK_EX)
        result = hazardhunt("campaign", campaign_file, "--out", reference)
    (reference / ".lock").unlink()
    assert result.returncode == 2
    assert "another campaign" in result.stderr
    assert snapshot(reference) == before


def test_a_scenario_file_that_does_not_load_stops_the_campaign_before_it_starts(
    tmp_path: Path,
) -> None:
    broken = tmp_path / "broken.toml"
    broken.write_text("this is = not a scenario\n")
    file = tmp_path / "campaign.toml"
    file.write_text(
        f'scenarios = ["head-on", "{broken}"]\nfields = ["2m"]\ntesters = ["random"]\n'
        "seeds = [0]\nepisodes = 3\n"
    )
    out = tmp_path / "campaign"
    result = hazardhunt("campaign", file, "--out", out)
    assert result.returncode == 2
    [line] = result.stderr.strip().splitlines()
    assert "broken.toml: not valid TOML" in line
    assert not out.exists()


RAISING_TESTER = """\
class Raising:
    name = "raising"

    def __init__(self, seed):
        self.seed = seed

    def explore(self, env, episodes):
        raise RuntimeError("this tester gives up")

    def save(self, directory):
        pass
"""


def test_a_run_that_raises_is_recorded_and_the_others_complete(tmp_path: Path) -> None:
    (tmp_path / "raising_tester.py").write_text(RAISING_TESTER)
    file = tmp_path / "campaign.toml"
    file.write_text(
        'scenarios = ["head-on"]\nfields = ["2m"]\ntesters = ["random", "raising"]\n'
        'seeds = [0]\nepisodes = 3\n[tester.raising]\npath = "raising_tester:Raising"\n'
    )
    out = tmp_path / "campaign"
    result = hazardhunt("campaign", file, "--out", out, "--workers", "2")
    assert result.returncode == 1
    assert "Traceback" not in result.stderr
    summary = json.loads((out / "summary.json").read_text())
    statuses = {run["run_id"]: run["status"] for run in summary["runs"]}
    assert statuses == {
        "head-on__2m__random__seed0": "complete",
        "head-on__2m__raising__seed0": "failed",
    }
    [failed] = [run for run in summary["runs"] if run["status"] == "failed"]
    assert "this tester gives up" in failed["error"]
    assert "failed" in result.stdout
    assert (out / "runs" / "head-on__2m__random__seed0" / "summary.json").is_file()


def test_runs_made_by_other_code_are_pointed_out_on_resume(
    campaign_file: Path, reference: Path, tmp_path: Path
) -> None:
    out = tmp_path / "campaign"
    shutil.copytree(reference, out)
    run_id = "head-on__2m__random__seed1"
    summary_file = out / "runs" / run_id / "summary.json"
    summary_file.write_text(
        json.dumps(json.loads(summary_file.read_text()) | {"source_digest": "0123456789ab"})
    )
    result = hazardhunt("campaign", campaign_file, "--out", out)
    assert result.returncode == 0, result.stderr
    assert "1 complete runs were made by other hazardhunt code" in result.stdout
    assert run_id in result.stdout
    again = hazardhunt("campaign", campaign_file, "--out", reference)
    assert "other hazardhunt code" not in again.stdout


def test_scenario_files_are_found_next_to_the_campaign_file(tmp_path: Path) -> None:
    builtin = Path(load_scenario("head-on").source)
    mine = tmp_path / "files" / "mine.toml"
    mine.parent.mkdir()
    mine.write_text(
        builtin.read_text().replace(
            'map = "shopfloor.toml"', f'map = "{builtin.parent / "shopfloor.toml"}"'
        )
    )
    file = mine.parent / "grid.toml"
    file.write_text(GRID.replace('"head-on", "overtaking"', '"mine.toml"'))
    config = load_campaign(file)
    assert config.scenarios == [str(mine)]
    assert config.runs()[0].run_id == "mine__2m__random__seed0"


def test_a_campaign_file_that_is_a_directory_is_one_line(tmp_path: Path) -> None:
    file, out = tmp_path / "campaign.toml", tmp_path / "out"
    file.mkdir()
    result = hazardhunt("campaign", file, "--out", out)
    assert result.returncode == 2
    [line] = result.stderr.strip().splitlines()
    assert f"{file}: is a directory, not a campaign file" in line
    assert not out.exists()


def test_a_campaign_resumed_after_a_scenario_file_changed_plays_its_runs_again(
    tmp_path: Path,
) -> None:
    builtin = Path(load_scenario("head-on").source)
    mine = tmp_path / "mine.toml"
    text = builtin.read_text().replace(
        'map = "shopfloor.toml"', f'map = "{builtin.parent / "shopfloor.toml"}"'
    )
    mine.write_text(text)
    file, out = tmp_path / "grid.toml", tmp_path / "campaign"
    file.write_text(GRID.replace('"head-on", "overtaking"', '"mine.toml"').replace("0, 1", "0"))
    assert hazardhunt("campaign", file, "--out", out).returncode == 0
    run = out / "runs" / "mine__2m__random__seed0"
    played = json.loads((run / "scenario.json").read_text())["human"]["start"]
    # Moved 1 m along the aisle: the run made before was not played on this floor.
    mine.write_text(text.replace(f"x = {played['x']:.1f}", f"x = {played['x'] - 1:.1f}"))
    result = hazardhunt("campaign", file, "--out", out)
    assert result.returncode == 0, result.stderr
    assert (
        f"run mine__2m__random__seed0 was played on {mine} before the file changed; running it "
        "again" in " ".join(result.stdout.split())
    )
    assert "damaged" not in result.stdout
    again = json.loads((run / "scenario.json").read_text())["human"]["start"]
    assert again["x"] == played["x"] - 1
    # Sent elsewhere without its scenario file, the campaign reports and copies all the same.
    mine.unlink()
    for command in (("report", out), ("copy", out, "--out", tmp_path / "copy")):
        done = hazardhunt(*command)
        assert done.returncode == 0, done.stderr


def test_an_out_under_a_file_is_one_line(campaign_file: Path, tmp_path: Path) -> None:
    (tmp_path / "notes.txt").write_text("mine")
    result = hazardhunt("campaign", campaign_file, "--out", tmp_path / "notes.txt" / "out")
    assert result.returncode == 2
    [line] = result.stderr.strip().splitlines()
    assert f"--out: {tmp_path / 'notes.txt'} is a file, not a directory" in line


def test_an_unreachable_goal_stops_the_campaign_before_it_starts(tmp_path: Path) -> None:
    builtin = Path(load_scenario("head-on").source)
    unreachable = tmp_path / "unreachable.toml"
    unreachable.write_text(
        builtin.read_text()
        .replace('map = "shopfloor.toml"', f'map = "{builtin.parent / "shopfloor.toml"}"')
        .replace("goal = { x = 18.0, y = 10.0 }", "goal = { x = 5.0, y = 8.8 }")
    )
    file = tmp_path / "campaign.toml"
    file.write_text(GRID.replace('"overtaking"', '"unreachable.toml"'))
    out = tmp_path / "campaign"
    result = hazardhunt("campaign", file, "--out", out)
    assert result.returncode == 2
    [line] = result.stderr.strip().splitlines()
    assert str(file) in line
    assert f"scenarios.1: {unreachable}: robot.goal: the robot cannot get there" in line
    assert not out.exists()


def test_a_campaign_file_fixed_after_its_runs_failed_runs_with_the_same_command(
    tmp_path: Path,
) -> None:
    (tmp_path / "raising_tester.py").write_text(RAISING_TESTER)
    file, out = tmp_path / "campaign.toml", tmp_path / "campaign"
    file.write_text(
        'scenarios = ["head-on"]\nfields = ["2m"]\ntesters = ["raising"]\nseeds = [0]\n'
        'episodes = 3\n[tester.raising]\npath = "raising_tester:Raising"\n'
    )
    assert hazardhunt("campaign", file, "--out", out).returncode == 1
    file.write_text(GRID.replace("seeds = [0, 1]", "seeds = [0]").replace("= 6", "= 3"))
    result = hazardhunt("campaign", file, "--out", out)
    assert result.returncode == 0, result.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert (summary["runs_complete"], summary["runs_failed"]) == (2, 0)
    assert json.loads((out / "campaign.json").read_text())["testers"] == ["random"]


def scenario_with_fields(path: Path, *fields: str) -> Path:
    """The built-in overtaking scenario as a file that defines ``fields`` (each the 2 m one)."""
    builtin = Path(load_scenario("overtaking").source)
    text = builtin.read_text().replace(
        'map = "shopfloor.toml"', f'map = "{builtin.parent / "shopfloor.toml"}"'
    )
    path.write_text(text + "".join(f'[fields."{f}"]\ndiameter = 2.0\n' for f in fields))
    return path


def test_a_field_named_like_a_path_stays_inside_the_campaign_and_exports(tmp_path: Path) -> None:
    field = "x/../../../../ESCAPED"
    home = tmp_path / "a" / "b" / "c"
    home.mkdir(parents=True)
    scenario_with_fields(home / "mine.toml", field)
    file = home / "campaign.toml"
    file.write_text(
        f'scenarios = ["mine.toml"]\nfields = ["{field}"]\ntesters = ["random"]\n'
        f"seeds = [0]\nepisodes = {EPISODES}\n"
    )
    out = home / "campaign"
    result = hazardhunt("campaign", file, "--out", out)
    assert result.returncode == 0, result.stderr
    # the table names the scenario file as the user wrote it, not by its absolute path
    assert "│ mine.toml " in result.stdout
    assert str(home / "mine.toml") not in result.stdout
    [run] = (out / "runs").iterdir()
    assert run.name == "mine__x_.._.._.._.._ESCAPED__random__seed0"
    assert [p for p in tmp_path.rglob("*ESCAPED*") if out not in p.parents] == []
    exported = hazardhunt("export", out, "--out", home / "cases")
    assert exported.returncode == 0, exported.stderr
    assert [p.name for p in (home / "cases").iterdir()] == [f"{run.name}__episode5.toml"]


def test_names_that_give_one_run_directory_name_the_key_and_the_file(tmp_path: Path) -> None:
    scenario_with_fields(tmp_path / "mine.toml", "a/b", "a_b")
    file = tmp_path / "campaign.toml"
    file.write_text(
        'scenarios = ["mine.toml"]\nfields = ["a/b", "a_b"]\ntesters = ["random"]\n'
        "seeds = [0]\nepisodes = 3\n"
    )
    out = tmp_path / "campaign"
    result = hazardhunt("campaign", file, "--out", out)
    assert result.returncode == 2
    [line] = result.stderr.strip().splitlines()
    assert f"{file}: fields: 'a/b' and 'a_b' give the same run directory" in line
    assert not out.exists()


def test_a_campaign_loads_each_scenario_file_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    loads: list[str] = []

    def counted(name: str) -> Scenario:
        loads.append(Path(name).name)
        return load_scenario(name)

    monkeypatch.setattr(config_module, "load_scenario", counted)
    for name in ("one.toml", "two.toml"):
        scenario_with_fields(tmp_path / name, "wide")
    file = tmp_path / "campaign.toml"
    file.write_text(
        'scenarios = ["one.toml", "two.toml"]\nfields = ["2m", "wide"]\n'
        'testers = ["random", "cem"]\nseeds = [0, 1, 2]\nepisodes = 3\n'
    )
    runs = load_campaign(file).runs()
    assert len(runs) == 24
    assert sorted(loads) == ["one.toml", "two.toml"]


def test_the_table_shows_a_scenario_file_relative_to_where_the_user_is(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "floors").mkdir()
    monkeypatch.chdir(tmp_path)
    assert shown_scenario(str(tmp_path / "floors" / "mine.toml")) == "floors/mine.toml"
    assert shown_scenario("/elsewhere/theirs.toml") == "theirs.toml"
    assert shown_scenario("crossing") == "crossing"


def with_a_stranger(reference: Path, out: Path, run_id: str) -> None:
    """A copy of the reference campaign in ``out`` whose folder ``run_id`` holds a run of
    another configuration: crossing without a field, seed 3."""
    shutil.copytree(reference, out)
    stranger = out.parent / "stranger"
    made = hazardhunt(
        "run", "--scenario", "crossing", "--field", "none", "--tester", "random",
        "--episodes", EPISODES, "--seed", 3, "--out", stranger,
    )  # fmt: skip
    assert made.returncode == 0, made.stderr
    shutil.rmtree(out / "runs" / run_id)
    shutil.copytree(stranger, out / "runs" / run_id)


def test_a_run_folder_of_another_configuration_is_named_and_redone_never_counted(
    campaign_file: Path, reference: Path, tmp_path: Path
) -> None:
    out, run_id = tmp_path / "campaign", "head-on__2m__random__seed1"
    with_a_stranger(reference, out, run_id)
    unfinished = "overtaking__2m__random__seed0"
    (out / "runs" / unfinished / "summary.json").unlink()
    result = hazardhunt("campaign", campaign_file, "--out", out)
    assert result.returncode == 0, result.stderr
    assert f"run {run_id} is damaged (it holds a run of another configuration " in result.stdout
    assert f"run {unfinished} is damaged (it holds no summary.json" in result.stdout
    assert_same_runs(out, reference)
    rows = json.loads((out / "summary.json").read_text())["runs"]
    assert {(row["run_id"], row["scenario"]) for row in rows if row["run_id"] == run_id} == {
        (run_id, "head-on")
    }


def test_report_export_and_copy_leave_out_a_run_folder_of_another_configuration(
    campaign_file: Path, reference: Path, tmp_path: Path
) -> None:
    out, run_id = tmp_path / "campaign", "head-on__2m__random__seed1"
    with_a_stranger(reference, out, run_id)
    said = (
        f"run {run_id} is damaged (it holds a run of another configuration (scenario: there "
        "'crossing', here 'head-on'))"
    )
    report = hazardhunt("report", out)
    assert report.returncode == 0, report.stderr
    assert said in " ".join(report.stderr.split())
    runs = pd.read_csv(out / "report" / "tables" / "runs.csv")
    assert set(runs["run_id"]) == {p.name for p in (reference / "runs").iterdir()} - {run_id}
    assert "crossing" not in set(runs["scenario"])
    cases = hazardhunt("export", out, "--out", tmp_path / "cases")
    assert cases.returncode == 0, cases.stderr
    assert said in " ".join(cases.stderr.split())
    copied = hazardhunt("copy", out, "--out", tmp_path / "copy")
    assert copied.returncode == 0, copied.stderr
    assert not (tmp_path / "copy" / "runs" / run_id).exists()


def test_a_campaign_json_that_does_not_read_is_one_line_for_report_and_export(
    reference: Path, tmp_path: Path
) -> None:
    out = tmp_path / "campaign"
    shutil.copytree(reference, out)
    stored = json.loads((out / "campaign.json").read_text())
    (out / "campaign.json").write_text(json.dumps(stored | {"episodes": "many"}))
    for command in (("report", out), ("export", out, "--out", tmp_path / "cases")):
        done = hazardhunt(*command)
        assert done.returncode == 2
        [line] = done.stderr.strip().splitlines()
        assert f"{out / 'campaign.json'}: not a campaign configuration: episodes: must be" in line


def test_run_refuses_to_write_into_a_campaign_s_run_folder(reference: Path) -> None:
    done = hazardhunt(
        "run", "--scenario", "crossing", "--field", "none", "--tester", "random",
        "--episodes", EPISODES, "--out", reference / "runs" / "head-on__2m__random__seed0",
    )  # fmt: skip
    assert done.returncode == 2
    assert "a run folder of the campaign in" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
