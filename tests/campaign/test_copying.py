"""``hazardhunt copy``: results without trajectories, which report and export still read."""

import json
import shutil
from pathlib import Path

import pandas as pd
import pytest

from hazardhunt.analysis.results import load_results
from hazardhunt.campaign.store import find_damage
from tests.helpers import hazardhunt

CAMPAIGN = """\
scenarios = ["overtaking"]
fields = ["2m"]
testers = ["random"]
seeds = [0, 1]
episodes = 6
"""
"""Two short runs with failures (overtaking behind the 2 m field)."""


@pytest.fixture(scope="module")
def campaign(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The campaign with only its seed-0 run finished (a first slice)."""
    folder = tmp_path_factory.mktemp("copy")
    (folder / "campaign.toml").write_text(CAMPAIGN)
    out = folder / "campaign"
    result = hazardhunt("campaign", folder / "campaign.toml", "--out", out, "--runs", "*seed0")
    assert result.returncode == 0, result.stderr
    return out


def sizes(directory: Path) -> int:
    return sum(path.stat().st_size for path in directory.rglob("*") if path.is_file())


def test_a_copy_leaves_the_trajectories_out_and_reads_as_the_original(
    campaign: Path, tmp_path: Path
) -> None:
    copy = tmp_path / "kept"
    result = hazardhunt("copy", campaign, "--out", copy)
    assert result.returncode == 0, result.stderr
    assert "1 run copied, 0 already there, 1 not finished yet" in result.stdout
    [run] = (copy / "runs").iterdir()
    assert not (run / "trajectories").exists()
    assert (campaign / "runs" / run.name / "trajectories").is_dir()
    assert sizes(copy) < sizes(campaign) / 2
    assert find_damage(run) is None
    original, copied = load_results(campaign), load_results(copy)
    assert len(copied.failures) > 0
    for table in ("episodes", "failures"):
        pd.testing.assert_frame_equal(
            getattr(original, table).drop(columns="directory", errors="ignore"),
            getattr(copied, table).drop(columns="directory", errors="ignore"),
        )
    exported = hazardhunt("export", copy, "--out", tmp_path / "cases")
    assert exported.returncode == 0, exported.stderr
    assert list((tmp_path / "cases").glob("*.toml"))


def test_copying_after_the_next_slice_adds_only_its_runs(campaign: Path, tmp_path: Path) -> None:
    mine = tmp_path / "campaign"
    shutil.copytree(campaign, mine)
    copy = tmp_path / "kept"
    assert hazardhunt("copy", mine, "--out", copy).returncode == 0
    first = {str(p.relative_to(copy)): p.stat().st_mtime_ns for p in (copy / "runs").rglob("*")}
    rest = hazardhunt("campaign", campaign.parent / "campaign.toml", "--out", mine)
    assert rest.returncode == 0, rest.stderr
    again = hazardhunt("copy", mine, "--out", copy)
    assert "1 run copied, 1 already there, 0 not finished yet" in again.stdout
    after = {str(p.relative_to(copy)): p.stat().st_mtime_ns for p in (copy / "runs").rglob("*")}
    assert {name: after[name] for name in first} == first
    assert json.loads((copy / "summary.json").read_text())["runs_complete"] == 2


def test_a_slice_run_in_a_new_campaign_directory_adds_to_the_copy(
    campaign: Path, tmp_path: Path
) -> None:
    # The directory of the first slice is gone (another machine); the next slice starts afresh.
    copy = tmp_path / "kept"
    assert hazardhunt("copy", campaign, "--out", copy).returncode == 0
    fresh = tmp_path / "fresh"
    file = campaign.parent / "campaign.toml"
    assert hazardhunt("campaign", file, "--out", fresh, "--runs", "*seed1").returncode == 0
    again = hazardhunt("copy", fresh, "--out", copy)
    assert "1 run copied, 0 already there, 1 not finished yet" in again.stdout
    summary = json.loads((copy / "summary.json").read_text())
    assert [e["status"] for e in summary["runs"]] == ["complete", "complete"]
    assert summary["runs_complete"] == 2
    assert summary["runs_pending"] == 0
    assert summary["episodes"] == 12
    assert summary["failures"] == sum(e["failures"] for e in summary["runs"])
    assert len(load_results(copy).runs) == 2


def test_a_copy_made_by_an_earlier_version_takes_the_runs_of_the_same_campaign(
    campaign: Path, tmp_path: Path
) -> None:
    # An earlier version wrote campaign.json without the settings added since.
    mine = tmp_path / "campaign"
    shutil.copytree(campaign, mine)
    copy = tmp_path / "kept"
    assert hazardhunt("copy", mine, "--out", copy).returncode == 0
    stored = json.loads((copy / "campaign.json").read_text())
    for added in ("sut_error_limit", "requirements", "search_on"):
        del stored[added]
    (copy / "campaign.json").write_text(json.dumps(stored))
    rest = hazardhunt("campaign", campaign.parent / "campaign.toml", "--out", mine)
    assert rest.returncode == 0, rest.stderr
    again = hazardhunt("copy", mine, "--out", copy)
    assert again.returncode == 0, again.stderr
    assert "1 run copied, 1 already there, 0 not finished yet" in again.stdout


def test_a_file_missing_from_a_copy_is_still_damage(campaign: Path, tmp_path: Path) -> None:
    copy = tmp_path / "kept"
    assert hazardhunt("copy", campaign, "--out", copy).returncode == 0
    [run, *_] = sorted((copy / "runs").iterdir())
    (run / "failures.parquet").unlink()
    assert find_damage(run) == "failures.parquet is missing"


def test_a_copy_cannot_be_classified_anew_and_says_why(campaign: Path, tmp_path: Path) -> None:
    copy = tmp_path / "kept"
    assert hazardhunt("copy", campaign, "--out", copy).returncode == 0
    result = hazardhunt("report", copy, "--reclassify")
    assert result.returncode == 2
    [line] = result.stderr.strip().splitlines()
    assert "a copy without the failures' trajectories, which classifying anew needs" in line


def test_a_copy_into_other_results_or_into_the_source_is_refused(
    campaign: Path, tmp_path: Path
) -> None:
    other = tmp_path / "other"
    (other / "campaign.json").parent.mkdir()
    (other / "campaign.json").write_text('{"scenarios": ["crossing"]}')
    refused = hazardhunt("copy", campaign, "--out", other)
    assert refused.returncode == 2
    assert refused.stderr.strip() == f"error: {other}: holds the copy of another campaign"
    crossing = json.loads((campaign / "campaign.json").read_text()) | {"scenarios": ["crossing"]}
    (other / "campaign.json").write_text(json.dumps(crossing))
    refused = hazardhunt("copy", campaign, "--out", other)
    assert refused.returncode == 2
    assert refused.stderr.strip() == (
        f"error: {other}: holds the copy of another campaign "
        "(scenarios: there ['crossing'], here ['overtaking'])"
    )
    [run, *_] = sorted((campaign / "runs").iterdir())
    (tmp_path / "mine" / "notes.txt").parent.mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("keep me")
    kept = hazardhunt("copy", run, "--out", tmp_path / "mine")
    assert kept.returncode == 2
    assert "exists and holds something else than this run" in kept.stderr
    assert (tmp_path / "mine" / "notes.txt").read_text() == "keep me"
    inside = hazardhunt("copy", campaign, "--out", campaign / "kept")
    assert inside.returncode == 2
    assert "inside the results it would copy" in inside.stderr


def test_a_campaign_whose_configuration_is_damaged_is_refused_by_name(tmp_path: Path) -> None:
    damaged = tmp_path / "received"
    (damaged / "runs").mkdir(parents=True)
    (damaged / "campaign.json").write_text('{"scenarios": 3}')
    refused = hazardhunt("copy", damaged, "--out", tmp_path / "kept")
    assert refused.returncode == 2
    assert refused.stderr.strip() == (
        f"error: {damaged / 'campaign.json'}: not a campaign configuration"
    )
    assert not (tmp_path / "kept").exists()


def test_a_single_run_copies_and_copies_again_as_already_there(
    campaign: Path, tmp_path: Path
) -> None:
    [run, *_] = sorted((campaign / "runs").iterdir())
    first = hazardhunt("copy", run, "--out", tmp_path / "run")
    assert "1 run copied" in first.stdout, first.stderr
    assert find_damage(tmp_path / "run") is None
    assert not (tmp_path / "run" / "trajectories").exists()
    again = hazardhunt("copy", run, "--out", tmp_path / "run")
    assert "0 runs copied, 1 already there" in again.stdout
    # A copy whose summary.json no longer reads is copied anew, not a traceback.
    (tmp_path / "run" / "summary.json").write_bytes(b"\xff{")
    mended = hazardhunt("copy", run, "--out", tmp_path / "run")
    assert mended.returncode == 0, mended.stderr
    assert "1 run copied" in mended.stdout
    assert find_damage(tmp_path / "run") is None


def test_a_received_run_with_a_symbolic_link_is_not_copied_nor_followed(
    campaign: Path, tmp_path: Path
) -> None:
    secret = tmp_path / "home" / ".ssh"
    secret.mkdir(parents=True)
    (secret / "id_ed25519").write_text("PRIVATE KEY")
    run = next(p for p in (campaign / "runs").iterdir() if p.is_dir())
    received = tmp_path / "received"
    shutil.copytree(run, received)
    shutil.rmtree(received / "tester")
    (received / "tester").symlink_to(secret)
    summary = json.loads((received / "summary.json").read_text())
    del summary["checksums"]  # as for a run recorded before checksums
    (received / "summary.json").write_text(json.dumps(summary))
    kept = tmp_path / "kept"
    done = hazardhunt("copy", received, "--out", kept)
    assert done.returncode == 2
    assert "tester is a symbolic link" in done.stderr
    assert not kept.exists() or not list(kept.rglob("id_ed25519"))
    assert find_damage(received) == (
        "tester is a symbolic link (a run holds none; it is not followed)"
    )
