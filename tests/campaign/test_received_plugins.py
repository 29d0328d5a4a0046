"""Which folders are results: a module found in one is code that came with results."""

import json

import pytest

from hazardhunt.campaign.plugins import results_folder


@pytest.mark.parametrize(
    ("files", "kind"),
    [
        (["config.json", "episodes.parquet", "summary.json"], "a run folder"),
        (["campaign.json", "summary.json"], "a campaign folder"),
        (["config.json", "batches/00000.parquet"], "an estimate folder"),
        (["config.json", "estimate.json"], "an estimate folder"),
        (["case.toml"], "a folder of regression cases"),
        (["campaign.toml", "my_sut.py"], None),
        ([], None),
    ],
    ids=["run", "campaign", "estimate", "estimate-done", "cases", "own-project", "empty"],
)
def test_a_folder_hazardhunt_writes_is_told_from_ones_own(tmp_path, files, kind):
    for name in files:
        path = tmp_path / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({}))
    if "case.toml" in files:
        (tmp_path / "case.toml").write_text("format = 1\n[expected]\n[human]\nactions = []\n")
    if "campaign.toml" in files:
        (tmp_path / "campaign.toml").write_text('scenarios = ["crossing"]\n')
    assert results_folder(tmp_path) == kind
