"""What survives: two runs started on one directory, a worker process killed mid-campaign, a
damaged run directory, a full disk (docs/runs-and-campaigns.md, "Guarantees").

The machine's misbehaviour is played by testers (plug-ins) that kill their own process, wait,
or fill the disk once their episodes are played; the SUT is the cheap conservative controller.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from typing import Any

import pandas as pd
import pytest

from hazardhunt.analysis import report
from hazardhunt.analysis.report import write_report
from hazardhunt.analysis.results import run_states
from hazardhunt.campaign import ledger as ledger_module
from hazardhunt.campaign.campaign import CampaignFailed, run_campaign
from hazardhunt.campaign.config import load_campaign
from hazardhunt.campaign.run import is_complete
from tests.helpers import hazardhunt, run_tables

CONTROLLER = "hazardhunt.benchmark.conservative:ConservativeController"

MISBEHAVING = '''
    """Testers that misbehave as a machine can."""

    import errno
    import os
    import signal
    import time
    from pathlib import Path

    import pandas as pd

    from hazardhunt.testers.random_sampling import RandomTester


    class Dying(RandomTester):
        """Kills its own process in explore: the first time only, or every time."""

        def __init__(self, seed, marker, always=False):
            super().__init__(seed)
            self.marker, self.always = Path(marker), always

        def explore(self, env, episodes):
            if self.always or not self.marker.exists():
                self.marker.touch()
                os.kill(os.getpid(), signal.SIGKILL)
            super().explore(env, episodes)


    class FillingTheDisk(RandomTester):
        """Plays its episodes; then the disk is full, and every table written fails."""

        def explore(self, env, episodes):
            super().explore(env, episodes)

            def full(*args, **kwargs):
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

            pd.DataFrame.to_parquet = full


    class Waiting(RandomTester):
        """Holds its run open until the file ``release`` appears."""

        def __init__(self, seed, started, release):
            super().__init__(seed)
            self.started, self.release = Path(started), Path(release)

        def explore(self, env, episodes):
            self.started.touch()
            deadline = time.monotonic() + 120
            while not self.release.exists() and time.monotonic() < deadline:
                time.sleep(0.05)
            super().explore(env, episodes)
'''


@pytest.fixture
def plugins(tmp_path: Path) -> Path:
    """A folder holding the misbehaving testers (``misbehaving.py``), for campaign files and
    as the working directory of runs."""
    folder = tmp_path / "plugins"
    folder.mkdir()
    (folder / "misbehaving.py").write_text(textwrap.dedent(MISBEHAVING))
    return folder


def campaign_file(folder: Path, testers: dict[str, str], seeds: str = "[0]") -> Path:
    """A campaign of head-on with the 2 m field and the conservative controller, 3 episodes per
    run; ``testers`` maps each tester's name to its ``[tester.NAME]`` table ("" for random)."""
    tables = "".join(f"[tester.{name}]\n{table}\n" for name, table in testers.items() if table)
    path = folder / "campaign.toml"
    path.write_text(
        f'scenarios = ["head-on"]\nfields = ["2m"]\ntesters = {json.dumps(list(testers))}\n'
        f'seeds = {seeds}\nepisodes = 3\n[controller]\npath = "{CONTROLLER}"\n{tables}'
    )
    return path


def run_args(out: Path, seed: int = 0, tester: str = "random") -> list[object]:
    return [
        "run", "--scenario", "head-on", "--field", "2m", "--tester", tester, "--episodes", 3,
        "--seed", seed, "--controller", CONTROLLER, "--out", out,
    ]  # fmt: skip


def ledger(out: Path) -> dict[str, dict[str, object]]:
    """The campaign's summary.json, per run id its entry."""
    summary = json.loads((out / "summary.json").read_text())
    return {entry["run_id"]: entry for entry in summary["runs"]}


def run_beside_random(file: Path, out: Path, tester: str) -> tuple[Any, dict[str, Any]]:
    """Run a campaign of ``random`` beside a ``tester`` whose run fails: the campaign exits 1
    without a traceback, random's run is complete; the result and the failed run's entry."""
    result = hazardhunt("campaign", file, "--out", out, "--workers", "2")
    assert result.returncode == 1
    assert "Traceback" not in result.stdout + result.stderr
    entries = ledger(out)
    assert entries["head-on__2m__random__seed0"]["status"] == "complete"
    failed = entries[f"head-on__2m__{tester}__seed0"]
    assert failed["status"] == "failed"
    return result, failed


def leftovers(directory: Path) -> list[str]:
    """Hidden partial directories under ``directory``."""
    return sorted(p.name for p in directory.rglob("*.partial"))


# --- two runs on one directory -------------------------------------------------------------------


def test_a_second_run_into_the_same_out_is_refused_while_the_first_runs(
    plugins: Path, tmp_path: Path
) -> None:
    out, started, release = tmp_path / "run", tmp_path / "started", tmp_path / "release"
    waiting = "misbehaving:Waiting"
    parameters = [
        "--tester-param",
        f'started="{started}"',
        "--tester-param",
        f'release="{release}"',
    ]
    first = subprocess.Popen(
        [sys.executable, "-m", "hazardhunt.cli", *map(str, run_args(out, 0, waiting)), *parameters],
        cwd=plugins,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env=os.environ | {"COLUMNS": "1000"},
    )
    try:
        deadline = time.monotonic() + 60
        while not started.exists():
            assert first.poll() is None, first.stderr.read() if first.stderr else ""
            assert time.monotonic() < deadline
            time.sleep(0.05)
        second = hazardhunt(*run_args(out, 1), "--json")
        assert second.returncode == 2
        [line] = second.stderr.strip().splitlines()
        assert f"another run (pid {first.pid})" in line
        assert str(out) in line
    finally:
        release.touch()
        _, errors = first.communicate(timeout=120)
    assert first.returncode == 0, errors
    assert json.loads((out / "config.json").read_text())["run"]["seed"] == 0
    assert not leftovers(tmp_path)
    assert not (tmp_path / ".run.lock").exists()
    # The finished run is not taken for the other seed's.
    again = hazardhunt(*run_args(out, 1))
    assert again.returncode == 2
    assert "holds a finished run of another configuration (tester_plugin: there " in again.stderr


# --- a worker process killed --------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.skipif(sys.platform != "linux", reason="SIGKILL")
def test_a_run_whose_worker_is_killed_once_is_run_again_and_the_campaign_completes(
    plugins: Path, tmp_path: Path
) -> None:
    marker = tmp_path / "killed-once"
    file = campaign_file(
        plugins,
        {"random": "", "dying": f'path = "misbehaving:Dying"\nmarker = "{marker}"'},
    )
    out = tmp_path / "campaign"
    result = hazardhunt("campaign", file, "--out", out, "--workers", "2")
    assert result.returncode == 0, result.stdout + result.stderr
    assert marker.exists()
    assert "was killed by SIGKILL; starting it again (attempt 2 of 3)" in result.stdout
    entries = ledger(out)
    assert {entry["status"] for entry in entries.values()} == {"complete"}
    assert len(entries) == 2
    for run_id in entries:
        assert len(run_tables(out / "runs" / run_id)[0]) == 3
    assert not leftovers(out)


@pytest.mark.slow
@pytest.mark.skipif(sys.platform != "linux", reason="SIGKILL")
def test_a_run_whose_worker_always_dies_is_recorded_as_failed_and_the_others_complete(
    plugins: Path, tmp_path: Path
) -> None:
    file = campaign_file(
        plugins,
        {
            "random": "",
            "dying": f'path = "misbehaving:Dying"\nmarker = "{tmp_path / "m"}"\nalways = true',
        },
    )
    out = tmp_path / "campaign"
    result, failed = run_beside_random(file, out, "dying")
    assert "WorkerDied" in str(failed["error"])
    assert "killed by SIGKILL, on each of 3 attempts" in str(failed["error"])
    assert "head-on__2m__dying__seed0" in result.stdout
    assert not leftovers(out)


# --- a damaged run -------------------------------------------------------------------------------


@pytest.fixture
def campaign(plugins: Path, tmp_path: Path) -> tuple[Path, Path]:
    """A complete campaign of two runs: its file and its directory."""
    file = campaign_file(plugins, {"random": ""}, seeds="[0, 1]")
    out = tmp_path / "campaign"
    result = hazardhunt("campaign", file, "--out", out)
    assert result.returncode == 0, result.stdout + result.stderr
    return file, out


def truncate(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def test_a_truncated_table_is_named_by_report_and_export_and_redone_by_resume(
    campaign: tuple[Path, Path], tmp_path: Path
) -> None:
    file, out = campaign
    damaged = "head-on__2m__random__seed1"
    episodes = out / "runs" / damaged / "episodes.parquet"
    expected = run_tables(out / "runs" / damaged)[0]
    truncate(episodes)

    reported = hazardhunt("report", out)
    assert reported.returncode == 0, reported.stderr
    assert "Traceback" not in reported.stderr
    assert f"run {damaged} is damaged (episodes.parquet does not match" in reported.stderr
    summary = json.loads((out / "report" / "summary.json").read_text())
    assert list(summary["damaged_runs"]) == [damaged]
    assert [run["run_id"] for run in summary["runs"]] == ["head-on__2m__random__seed0"]
    assert f"Run {damaged} is damaged" in (out / "report" / "index.html").read_text()

    exported = hazardhunt("export", out, "--out", tmp_path / "cases")
    assert exported.returncode == 0, exported.stderr
    assert f"run {damaged} is damaged" in exported.stderr

    resumed = hazardhunt("campaign", file, "--out", out)
    assert resumed.returncode == 0, resumed.stdout + resumed.stderr
    assert f"run {damaged} is damaged" in resumed.stdout
    pd.testing.assert_frame_equal(run_tables(out / "runs" / damaged)[0], expected)
    assert {entry["status"] for entry in ledger(out).values()} == {"complete"}
    assert run_states(out).damaged == {}


def test_a_damaged_run_directory_is_a_one_line_error_for_report_and_is_redone_by_run(
    tmp_path: Path,
) -> None:
    out = tmp_path / "run"
    assert hazardhunt(*run_args(out)).returncode == 0
    expected = run_tables(out)[0]
    truncate(out / "episodes.parquet")
    reported = hazardhunt("report", out)
    assert reported.returncode == 2
    [line] = reported.stderr.strip().splitlines()
    assert "the run is damaged (episodes.parquet does not match its checksum" in line
    assert not (out / "report").exists()
    redone = hazardhunt(*run_args(out))
    assert redone.returncode == 0, redone.stderr
    assert "damaged" in redone.stderr
    pd.testing.assert_frame_equal(run_tables(out)[0], expected)


@pytest.mark.parametrize(
    ("key", "value", "problem"),
    [
        ("scenario", None, "summary.json: scenario: must be text"),
        ("seed", "0", "summary.json: seed: must be a whole number"),
        ("classes", ["left/moving", 3], "summary.json: classes.1: must be text"),
        ("run_id", ..., "summary.json: run_id: missing"),
    ],
)
def test_a_summary_of_the_wrong_shape_is_damage_for_every_command_not_a_traceback(
    tmp_path: Path, key: str, value: object, problem: str
) -> None:
    # summary.json holds the run's checksums, so no checksum covers it: its keys are checked.
    out = tmp_path / "run"
    assert hazardhunt(*run_args(out)).returncode == 0
    summary = json.loads((out / "summary.json").read_text())
    if value is ...:
        del summary[key]
    else:
        summary[key] = value
    (out / "summary.json").write_text(json.dumps(summary))
    for command in (
        ("report", out),
        ("export", out, "--out", tmp_path / "cases"),
        ("replay", out, "--episode", 0),
        ("copy", out, "--out", tmp_path / "copy"),
    ):
        done = hazardhunt(*command)
        assert done.returncode == 2, (command, done.stderr)
        [line] = done.stderr.strip().splitlines()
        assert f"the run is damaged ({problem}" in line, line
    assert not (tmp_path / "cases").exists()


def test_a_run_forged_with_fresh_checksums_is_named_not_a_traceback(tmp_path: Path) -> None:
    # Checksums catch damage, not a sender who writes them anew: what is read is checked too.
    out = tmp_path / "run"
    assert hazardhunt(*run_args(out)).returncode == 0
    summary = json.loads((out / "summary.json").read_text())
    config = json.loads((out / "config.json").read_text())
    (out / "config.json").write_text(json.dumps(config | {"run": "crossing"}))
    summary["checksums"]["config.json"] = hashlib.sha256(
        (out / "config.json").read_bytes()
    ).hexdigest()
    (out / "summary.json").write_text(json.dumps(summary))
    for command in (("report", out), ("export", out, "--out", tmp_path / "cases")):
        done = hazardhunt(*command)
        assert done.returncode == 2, (command, done.stderr)
        [line] = done.stderr.strip().splitlines()
        assert line == f"error: {out / 'config.json'}: not a run's configuration (no run table)"

    (out / "config.json").write_text(json.dumps(config))
    summary["checksums"]["config.json"] = hashlib.sha256(
        (out / "config.json").read_bytes()
    ).hexdigest()
    (out / "summary.json").write_text(json.dumps(summary | {"field_shape": {"radius": 2.0}}))
    done = hazardhunt("report", out)
    assert done.returncode == 2, done.stderr
    [line] = done.stderr.strip().splitlines()
    assert "the run is damaged (summary.json: field_shape: " in line
    assert "radius" in line


# --- a full disk ---------------------------------------------------------------------------------


def test_a_run_that_cannot_write_its_results_says_so_and_leaves_nothing(
    plugins: Path, tmp_path: Path
) -> None:
    out = tmp_path / "run"
    result = hazardhunt(*run_args(out, tester="misbehaving:FillingTheDisk"), cwd=plugins)
    assert result.returncode == 1
    [line] = result.stderr.strip().splitlines()[-1:]
    assert "Traceback" not in result.stderr
    assert "No space left on device" in line
    assert str(out) in line
    assert not out.exists()
    assert not leftovers(tmp_path)


def test_a_campaign_records_a_run_that_could_not_write_its_results(
    plugins: Path, tmp_path: Path
) -> None:
    file = campaign_file(plugins, {"random": "", "full": 'path = "misbehaving:FillingTheDisk"'})
    out = tmp_path / "campaign"
    _, failed = run_beside_random(file, out, "full")
    assert "No space left on device" in str(failed["error"])
    assert not leftovers(out)
    assert not (out / "runs" / "head-on__2m__full__seed0").exists()


def test_a_campaign_whose_summary_cannot_be_written_finishes_its_runs_and_says_so(
    plugins: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    config = load_campaign(campaign_file(plugins, {"random": ""}))
    out = tmp_path / "campaign"
    written = ledger_module.write_json_atomic

    def full_for_the_ledger(path: Path, data: object) -> None:
        if path.name == "summary.json":
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        written(path, data)

    monkeypatch.setattr(ledger_module, "write_json_atomic", full_for_the_ledger)
    with pytest.raises(CampaignFailed, match=r"summary\.json: could not be written"):
        run_campaign(config, out)
    assert is_complete(out / "runs" / "head-on__2m__random__seed0")
    monkeypatch.undo()
    assert run_campaign(config, out)["runs_complete"] == 1
    assert ledger(out)["head-on__2m__random__seed0"]["status"] == "complete"


def test_a_report_that_cannot_be_written_leaves_the_previous_one_and_nothing_else(
    campaign: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    _, out = campaign

    def disk_full(*args: object, **kwargs: object) -> Path:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    def report_on_a_full_disk() -> None:
        with monkeypatch.context() as patched:
            patched.setattr(report.figures, "failure_rates_figure", disk_full)
            with pytest.raises(OSError, match="No space left on device"):
                write_report(out)

    report_on_a_full_disk()
    assert sorted(p.name for p in out.iterdir() if p.name.startswith((".report", "report"))) == []
    index = write_report(out)
    before = {p: p.read_bytes() for p in (out / "report").rglob("*") if p.is_file()}
    report_on_a_full_disk()
    assert index.is_file()
    assert {p: p.read_bytes() for p in (out / "report").rglob("*") if p.is_file()} == before
    # Nothing of the failed report is left, nor of the lock under which reports take turns.
    assert sorted(p.name for p in out.iterdir() if p.name.startswith(".report")) == []
