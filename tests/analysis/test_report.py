"""``hazardhunt report``: what a user finds in the report of a small campaign."""

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from PIL import Image

from hazardhunt.analysis import report as report_module
from hazardhunt.analysis.results import ResultsError, load_results
from hazardhunt.spec.failure_classes import MechanismClassifier
from hazardhunt.sut.safety_layer import FIELD_SETTINGS
from tests.helpers import hazardhunt

# Slow: a small campaign and its report, built once (about a minute); `make test-slow` runs it.
pytestmark = pytest.mark.slow

TABLES = (
    "failures_per_run",
    "classes",
    "class_discovery",
    "clusters",
    "clusters_vs_classes",
    "lesson_1",
    "lesson_2",
    "failures_per_class",
    "runtime",
    "reward_hacking",
    "representatives",
    "failure_rates",
    "runs",
    "verdict_testers",
)


def run_summaries(campaign: Path) -> dict[str, dict]:
    return {
        path.parent.name: json.loads(path.read_text())
        for path in (campaign / "runs").glob("*/summary.json")
    }


def test_every_failure_is_classified_with_a_class_of_its_field_setting(campaign):
    for run in (campaign / "runs").iterdir():
        failures = pd.read_parquet(run / "failures.parquet")
        summary = json.loads((run / "summary.json").read_text())
        allowed = MechanismClassifier().classes_for(FIELD_SETTINGS[summary["field"]])
        assert failures["class"].isin(allowed).all()
        assert summary["classes"] == [c for c in allowed if c in set(failures["class"])]


def test_the_summary_has_every_run_with_its_own_numbers(campaign, report):
    summary = json.loads((report / "summary.json").read_text())
    recorded = run_summaries(campaign)
    assert {run["run_id"] for run in summary["runs"]} == set(recorded)
    for run in summary["runs"]:
        own = recorded[run["run_id"]]
        for key in ("scenario", "field", "tester", "seed", "episodes", "failures"):
            assert run[key] == own[key]
        assert run["classes_found"] == own["classes_found"] <= run["classes_total"]
        assert run["wall_time_s"] == pytest.approx(own["wall_time_s"])
        assert run["episodes_per_s"] > 0
        assert run["source_digest"] == own["source_digest"]
        config = json.loads((campaign / "runs" / run["run_id"] / "config.json").read_text())
        assert run["blas"] == config["blas"]


def test_runs_recorded_by_different_sources_are_said_to_be(campaign, tmp_path):
    copy = tmp_path / "campaign"
    shutil.copytree(campaign, copy, ignore=shutil.ignore_patterns("report"))
    older = sorted((copy / "runs").iterdir())[0] / "summary.json"
    older.write_text(json.dumps(json.loads(older.read_text()) | {"source_digest": "0123456789ab"}))
    page = report_module._Report(tmp_path / "report")
    report_module._runs(page, load_results(copy))
    [runs] = page.sections
    said = " ".join(str(getattr(block, "text", "")) for block in runs.blocks)
    assert "These runs were recorded by 2 different hazardhunt sources (0123456789ab, " in said
    assert "BLAS kernels" not in said


def test_lesson_1_counts_match_the_runs(campaign, report):
    summary = json.loads((report / "summary.json").read_text())
    by_key = {
        (r["scenario"], r["field"], r["seed"], r["tester"]): r["failures"]
        for r in run_summaries(campaign).values()
    }
    for tester in ("ppo-acc", "ppo-max"):
        wins = sum(
            failures > by_key[(scenario, field, seed, "random")]
            for (scenario, field, seed, name), failures in by_key.items()
            if name == tester
        )
        assert summary["lesson_1"][tester] == {"more_failures_than_random": wins, "comparisons": 2}


def test_every_table_is_written_as_csv_and_markdown(report):
    for name in TABLES:
        table = pd.read_csv(report / "tables" / f"{name}.csv")
        markdown = (report / "tables" / f"{name}.md").read_text().splitlines()
        assert len(table) >= 1
        assert len(markdown) == len(table) + 2  # header and rule


def test_the_figures_are_pictures(report):
    names = {path.name for path in (report / "figures").iterdir()}
    for expected in (
        "failures_per_run.png",
        "class_discovery.png",
        "failure_clusters.png",
        "learning_curves.png",
        "failure_rates.png",
        "heat_map_overtaking.png",
        "loitering.png",
    ):
        assert expected in names
    for path in (report / "figures").iterdir():
        with Image.open(path) as image:
            assert image.width > 100
            assert image.height > 100


def test_each_class_found_has_a_representative_drawn_from_its_record(campaign, report):
    found = set()
    for run in (campaign / "runs").iterdir():
        found |= set(pd.read_parquet(run / "failures.parquet")["class"])
    representatives = pd.read_csv(report / "tables" / "representatives.csv")
    assert set(representatives["class"]) == found
    assert (representatives["pictures"] == "drawn as recorded").all()
    for name in found:
        stem = "class_" + "".join(c if c.isalnum() or c in "-_" else "_" for c in name)
        assert (report / "figures" / f"{stem}.png").is_file()
        assert (report / "figures" / f"{stem}.gif").is_file()


def all_failures(campaign: Path) -> pd.DataFrame:
    return pd.concat(
        pd.read_parquet(run / "failures.parquet").assign(run_id=run.name)
        for run in sorted((campaign / "runs").iterdir())
    ).reset_index(drop=True)


def test_the_verdict_counts_the_campaigns_failures_and_mechanisms(campaign, report):
    verdict = json.loads((report / "summary.json").read_text())["verdict"]
    failures = all_failures(campaign)
    runs = run_summaries(campaign).values()
    assert verdict["failures"] == sum(run["failures"] for run in runs) == len(failures) > 0
    assert verdict["episodes"] == sum(run["episodes"] for run in runs)
    assert verdict["classes"] == sorted(set(failures["class"]) - {"other"})
    assert verdict["unclassified_failures"] == int((failures["class"] == "other").sum())
    clusters = pd.read_csv(report / "tables" / "clusters.csv")
    pooled = clusters[(clusters["tester"] == "all") & (clusters["scenario"] == "all")]
    assert verdict["clusters"] == int(pooled["clusters"].iloc[0])


def test_the_verdict_says_which_tester_found_what(campaign, report):
    table = pd.read_csv(report / "tables" / "verdict_testers.csv", dtype=str).set_index("found")
    failures = all_failures(campaign)
    for tester in ("ppo-acc", "ppo-max", "random", "qd"):
        own = failures[failures["run_id"].str.contains(f"__{tester}__")]
        assert int(table.at["unsafe failures", tester]) == len(own)
        assert int(table.at["classes found", tester]) == len(set(own["class"]) - {"other"})
        for name in set(failures["class"]) - {"other"}:
            first = own[own["class"] == name]["episode"]
            expected = str(first.min()) if len(first) else "nan"
            assert str(table.at[name, tester]) == expected


def test_the_verdict_shows_the_failure_of_highest_risk_drawn(campaign, report):
    failures = all_failures(campaign).set_index(["run_id", "episode"])
    page = (report / "index.html").read_text()
    verdict = page[page.index('<section id="verdict"') : page.index("</section>")]
    shown = re.search(r'alt="Worst: ([^,]+), (\S+), episode (\d+)"', verdict)
    assert shown, "no picture of the worst failure"
    worst = failures.loc[(shown[2], int(shown[3]))]
    assert worst["class"] == shown[1]
    assert worst["max_risk"] == failures["max_risk"].max()
    assert f"risk {worst['max_risk']:.0f}" in verdict
    for suffix in ("png", "gif"):
        assert (report / "figures" / f"worst_failure.{suffix}").stat().st_size > 10_000
    assert f"hazardhunt export {campaign} --out {campaign / 'cases'}" in verdict
    assert f"hazardhunt regress {campaign / 'cases'}" in verdict


def test_the_page_has_every_section_with_its_figures_inlined(report):
    page = (report / "index.html").read_text()
    assert page.count("data:image/png;base64,") >= 7
    for title in (
        "Failures per run",
        "Table I",
        "Diversity: classes found against episodes",
        "Diversity beyond the taxonomy: clusters",
        "Lesson 1",
        "Table II",
        "reward hacking",
        "Learning curves",
        "Where failures happen",
        "representative failure",
        "Failure rates",
    ):
        assert title in page


def test_the_diversity_sections_follow_the_classes_found(report):
    page = (report / "index.html").read_text()
    order = [
        page.index("<h2>Failure classes found (Table I)"),
        page.index("<h2>Diversity: classes found against episodes"),
        page.index("<h2>Diversity beyond the taxonomy: clusters"),
        page.index("<h2>Lesson 2"),
    ]
    assert order == sorted(order)


def test_the_quality_diversity_archives_are_drawn(campaign, report):
    page = (report / "index.html").read_text()
    assert "Quality-diversity archives" in page
    for field in ("none", "2m"):
        picture = report / "figures" / f"archive_overtaking__{field}__qd__seed0.png"
        assert picture.stat().st_size > 10_000
        assert f"The archive of overtaking__{field}__qd__seed0" in page


def test_the_cluster_tables_count_every_failure_once(campaign, report):
    failures = load_results(campaign).failures
    per_case = failures.groupby(["scenario", "field"]).size()
    clusters = pd.read_csv(report / "tables" / "clusters.csv")
    everyone = clusters[(clusters["tester"] == "all") & (clusters["scenario"] != "all")]
    assert everyone.set_index(["scenario", "field"])["failures"].to_dict() == per_case.to_dict()
    contingency = pd.read_csv(report / "tables" / "clusters_vs_classes.csv")
    cells = contingency.set_index(["scenario", "field", "class"]).fillna(0).sum(axis=1)
    per_class = failures.groupby(["scenario", "field", "class"]).size()
    assert cells.astype(int).to_dict() == per_class.to_dict()


def test_a_partly_finished_campaign_reports_its_finished_runs(campaign, tmp_path):
    copy = tmp_path / "campaign"
    shutil.copytree(campaign, copy, ignore=shutil.ignore_patterns("report"))
    unfinished = sorted((copy / "runs").iterdir())[0]
    (unfinished / "summary.json").unlink()
    results = load_results(copy)
    assert results.unfinished == [unfinished.name]
    assert len(results.runs) == len(list((copy / "runs").iterdir())) - 1
    assert unfinished.name not in set(results.episodes["run_id"])
    page = report_module._Report(tmp_path / "report")
    report_module._runs(page, results)
    said = " ".join(str(getattr(block, "text", "")) for block in page.sections[0].blocks)
    assert f"1 run of the campaign has not finished and is left out: {unfinished.name}." in said


def test_reclassifying_from_the_stored_trajectories_gives_the_recorded_classes(campaign):
    recorded = load_results(campaign).failures
    anew = load_results(campaign, MechanismClassifier()).failures
    assert len(recorded) > 0
    assert anew["class"].tolist() == recorded["class"].tolist()


def test_a_run_directory_is_read_as_a_one_run_result(campaign):
    run = sorted((campaign / "runs").iterdir())[0]
    results = load_results(run)
    assert results.runs["run_id"].tolist() == [run.name]
    assert len(results.episodes) == json.loads((run / "summary.json").read_text())["episodes"]


def test_a_directory_without_results_is_a_clear_error(tmp_path):
    result = hazardhunt("report", tmp_path)
    assert result.returncode == 2
    assert result.stderr.strip() == (
        f"error: {tmp_path}: not a run or campaign directory (no config.json or campaign.json)"
    )
    with pytest.raises(ResultsError, match="no such directory"):
        load_results(tmp_path / "missing")


def test_the_report_is_readable_as_the_umask_allows(report):
    mask = os.umask(0)
    os.umask(mask)
    for name in ("index.html", "summary.json"):
        assert (report / name).stat().st_mode & 0o777 == 0o666 & ~mask


def test_a_table_the_campaign_cannot_fill_says_which_testers_it_needs(campaign, tmp_path):
    copy = tmp_path / "campaign"
    leave_out = shutil.ignore_patterns("report", "*ppo-acc*", "*random*")
    shutil.copytree(campaign, copy, ignore=leave_out)
    page = report_module._Report(tmp_path / "report")
    report_module._table_sections(page, load_results(copy), report_module.TABLE_SECTIONS)
    said = {
        section.title: " ".join(str(getattr(block, "text", "")) for block in section.blocks)
        for section in page.sections
    }
    runtime = said["Runtime: accumulated vs maximum reward (Table II)"]
    assert "It needs ppo-acc and ppo-max on the same (scenario, field)" in runtime
    lesson_1 = said["Lesson 1: does a tester find more failures than random sampling?"]
    assert "It needs random and another tester with the same (scenario, field, seed)" in lesson_1


def test_a_copy_without_trajectories_reports_the_same_failures_and_says_they_are_not_drawn(
    campaign, report, tmp_path
):
    copy = tmp_path / "kept"
    assert hazardhunt("copy", campaign, "--out", copy).returncode == 0
    assert not list(copy.rglob("trajectories"))
    result = hazardhunt("report", copy)
    assert result.returncode == 0, result.stderr
    for table in ("failures_per_run", "classes", "representatives"):
        pd.testing.assert_frame_equal(
            pd.read_csv(copy / "report" / "tables" / f"{table}.csv").drop(
                columns="pictures", errors="ignore"
            ),
            pd.read_csv(report / "tables" / f"{table}.csv").drop(
                columns="pictures", errors="ignore"
            ),
        )
    kept = pd.read_csv(copy / "report" / "tables" / "representatives.csv")
    assert kept["pictures"].str.startswith("not drawn: a copy without trajectories").all()


def test_the_reproduction_document_is_rewritten_from_kept_results(campaign, tmp_path):
    # The study's testers and the searchers kept apart, as two campaigns would be.
    study, search = tmp_path / "study", tmp_path / "study-search"
    for kept, leave in ((study, "*__qd__*"), (search, "*__ppo-*")):
        assert hazardhunt("copy", campaign, "--out", kept).returncode == 0
        for run in (kept / "runs").glob(leave):
            shutil.rmtree(run)
        for run in (kept / "runs").glob("*__random__*") if kept is search else ():
            shutil.rmtree(run)
    doc = tmp_path / "docs" / "reproduction.md"
    doc.parent.mkdir()
    doc.write_text("# Reproducing the study\n\nWritten by hand.\n")
    command = [
        sys.executable, "scripts/reproduction.py", "--results", study, search,
        tmp_path / "not-yet", "--doc", doc, "--images", doc.parent / "images" / "study",
    ]  # fmt: skip
    for _ in range(2):  # the second time replaces the first, the hand-written part stays
        done = subprocess.run(command, capture_output=True, text=True, check=False)
        assert done.returncode == 0, done.stderr
    text = doc.read_text()
    assert text.startswith("# Reproducing the study\n\nWritten by hand.\n")
    assert text.count("## The full budget") == 1
    assert "6 of the study's 81 runs are done" in text
    assert "Beside them, 2 runs of qd on the same grid." in text
    for heading in ("Table I", "Table II", "Lesson 1", "Lesson 2", "Lesson 3", "Learning"):
        assert heading in text
    assert "| qd |" in text  # the searchers' rows beside the study's testers
    assert "![Failures per 500 episodes](images/study/learning_curves.png)" in text
    assert Image.open(doc.parent / "images" / "study" / "learning_curves.png").size[0] > 0
    # Table II as people read it: wall times in h:mm, speedups in per cent.
    assert re.search(r"\| \d+:\d\d \| \d+:\d\d \| -?\d+\.\d % \|", text)
    # The 2 m field's loitering, replayed from its actions and drawn.
    assert "The most typical loitering episode, replayed from its actions (" in text
    assert Image.open(doc.parent / "images" / "study" / "loitering.png").size[0] > 0


def test_a_kept_run_that_does_not_match_its_checksums_is_named_and_left_out(campaign, tmp_path):
    kept = tmp_path / "kept"
    assert hazardhunt("copy", campaign, "--out", kept).returncode == 0
    damaged = sorted((kept / "runs").iterdir())[0]
    with (damaged / "episodes.parquet").open("ab") as file:
        file.write(b"\0")
    doc = tmp_path / "reproduction.md"
    doc.write_text("# Reproducing the study\n")
    command = [
        sys.executable, "scripts/reproduction.py", "--results", kept, "--doc", doc,
        "--images", tmp_path / "images",
    ]  # fmt: skip
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    assert f"{damaged.name}: damaged, left out (episodes.parquet" in done.stderr
    text = doc.read_text()
    assert f"**Left out, damaged:** {damaged.name} (episodes.parquet" in text
    runs = len(list((kept / "runs").iterdir()))
    assert f"{runs - 1} runs written" in done.stdout


def test_the_numbers_behind_the_lessons_are_printed_per_run(campaign, tmp_path):
    kept = tmp_path / "kept"
    assert hazardhunt("copy", campaign, "--out", kept).returncode == 0
    command = [sys.executable, "scripts/study_numbers.py", "--results", kept, "--block", "4"]
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    for run in (kept / "runs").iterdir():
        summary = json.loads((run / "summary.json").read_text())
        block = done.stdout.split(run.name + "\n", 1)[1]
        assert block.startswith(f"  failures {summary['failures']}, first at episode ")
        per_block = re.search(r"failures per 4: \[([\d, ]*)\]", block)
        assert per_block is not None
        assert sum(map(int, per_block.group(1).split(","))) == summary["failures"]
