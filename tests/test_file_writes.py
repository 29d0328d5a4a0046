"""A full disk: each command's error names the file it could not write, and no half-written
file is left (the disk's faults injected where the file is written)."""

import errno
import os
from pathlib import Path

import pandas as pd
import pytest

from tests.helpers import hazardhunt

ROOT = Path(__file__).parents[1]
PURSUIT = "hazardhunt.sut.pursuit:PursuitController"


def full_disk(what):
    """A write of ``what`` that fails as on a full disk: the file is made, nothing gets in,
    and the error names no file (as ``write()`` raises it)."""

    def write(target, *_, **__):
        Path(target).touch()
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    return write


@pytest.fixture(scope="module")
def run_with_a_failure(tmp_path_factory):
    out = tmp_path_factory.mktemp("full-disk") / "run"
    done = hazardhunt(
        "run", "--scenario", "head-on", "--field", "none", "--tester", "random",
        "--episodes", 6, "--out", out, "--controller", PURSUIT, cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert len(pd.read_parquet(out / "failures.parquet")) > 0
    return out


def test_export_on_a_full_disk_names_the_case_file_and_leaves_none_empty(
    run_with_a_failure, tmp_path, monkeypatch
):
    from hazardhunt.cases import export_cases

    def write_text(self, *_, **__):
        full_disk("case")(self)

    monkeypatch.setattr(Path, "write_text", write_text)
    with pytest.raises(OSError, match="No space left on device") as raised:
        export_cases(run_with_a_failure, tmp_path / "cases", every_failure=True)
    assert raised.value.filename
    assert Path(raised.value.filename).parent == tmp_path / "cases"
    assert Path(raised.value.filename).suffix == ".toml"
    assert list((tmp_path / "cases").iterdir()) == []  # no 0-byte case file


def test_an_estimate_on_a_full_disk_names_its_batch_and_resumes_as_if_never_stopped(
    tmp_path, monkeypatch
):
    from hazardhunt.likelihood.estimators import EstimatorParams
    from hazardhunt.likelihood.run import EstimateConfig, EstimateRun
    from hazardhunt.likelihood.toy import ClosedFormEncounters

    config = EstimateConfig(
        episodes=200, seed=3, estimator=EstimatorParams(method="mc", batch_size=100)
    )
    toy = ClosedFormEncounters()
    with monkeypatch.context() as patched:
        patched.setattr(pd.DataFrame, "to_parquet", lambda self, path, **_: full_disk("")(path))
        with pytest.raises(OSError, match="No space left on device") as raised:
            EstimateRun(config, tmp_path / "full", source=toy).run()
    assert raised.value.filename == str(tmp_path / "full" / "batches" / "00000.parquet")
    assert not list((tmp_path / "full").rglob("*.partial"))
    resumed = EstimateRun(config, tmp_path / "full", source=toy).run()
    fresh = EstimateRun(config, tmp_path / "fresh", source=toy).run()
    pd.testing.assert_frame_equal(resumed, fresh)


def test_a_campaign_on_a_full_disk_names_the_file_it_could_not_write(tmp_path, monkeypatch):
    from hazardhunt.campaign.campaign import run_campaign
    from hazardhunt.campaign.config import load_campaign

    campaign = tmp_path / "campaign.toml"
    campaign.write_text(
        'scenarios = ["head-on"]\nfields = ["none"]\ntesters = ["random"]\nseeds = [0]\n'
        f'episodes = 2\n[controller]\npath = "{PURSUIT}"\n'
    )
    config = load_campaign(campaign)

    def fsync(descriptor):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "fsync", fsync)
    with pytest.raises(OSError, match="No space left on device") as raised:
        run_campaign(config, tmp_path / "out")
    assert raised.value.filename == str(tmp_path / "out" / "campaign.json")
    assert [p.name for p in (tmp_path / "out").iterdir() if p.name != ".lock"] == []
