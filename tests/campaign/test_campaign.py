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

from hazardhunt.campaign.config import load_campaign
from hazardhunt.world.scenario import load_scenario
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
    assert any(runs.glob(".*.partial"))
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
        pytest.param(GRID.replace('"head-on"', '"roundabout"'), "scenarios", id="scenario"),
        pytest.param(GRID.replace('"random"', '"greedy"'), "testers", id="tester"),
        pytest.param(GRID.replace('"2m"', '"3m"'), "fields", id="field"),
        pytest.param(
            GRID + "[tester.greedy]\nn_steps = 8\n", "tester.greedy: unknown", id="tester-table"
        ),
        pytest.param(
            GRID + "[tester.ppo-max]\nn_step = 8\n",
            "tester: tester 'ppo-max': unknown parameter 'n_step'",
            id="tester-parameter",
        ),
        pytest.param(GRID.replace(f"= {EPISODES}", "= 0"), "episodes", id="no-episodes"),
        pytest.param(GRID.replace("[0, 1]", "[]"), "seeds", id="no-seeds"),
        pytest.param(None, "no such campaign file", id="missing-file"),
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


def test_a_run_that_raises_is_recorded_and_the_others_complete(tmp_path: Path) -> None:
    # The file loads, but its goal lies too close to a shelf for any route: the run raises.
    builtin = load_scenario("head-on")
    broken = tmp_path / "broken.toml"
    broken.write_text(
        Path(builtin.source)
        .read_text()
        .replace(
            'map = "shopfloor.toml"', f'map = "{Path(builtin.source).parent / "shopfloor.toml"}"'
        )
        .replace("goal = { x = 18.0, y = 10.0 }", "goal = { x = 5.0, y = 8.8 }")
    )
    file = tmp_path / "campaign.toml"
    file.write_text(
        f'scenarios = ["head-on", "{broken}"]\nfields = ["2m"]\ntesters = ["random"]\n'
        "seeds = [0]\nepisodes = 3\n"
    )
    out = tmp_path / "campaign"
    result = hazardhunt("campaign", file, "--out", out, "--workers", "2")
    assert result.returncode == 1
    assert "Traceback" not in result.stderr
    summary = json.loads((out / "summary.json").read_text())
    statuses = {run["run_id"]: run["status"] for run in summary["runs"]}
    assert statuses == {
        "head-on__2m__random__seed0": "complete",
        "broken__2m__random__seed0": "failed",
    }
    [failed] = [run for run in summary["runs"] if run["status"] == "failed"]
    assert "broken.toml" in failed["error"]
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
