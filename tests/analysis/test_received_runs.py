"""Runs received from someone else, made to match their checksums: trajectories that no floor
holds, episodes numbered twice, names of megabytes, control characters and HTML in names, a
``report`` that is a symbolic link. Each is named in one line or shown harmless, never a
traceback, a hang or raw text on the terminal."""

import json
import shutil
from pathlib import Path

import pandas as pd
import pytest

from hazardhunt.campaign.store import file_checksums
from tests.helpers import hazardhunt

ROOT = Path(__file__).parents[2]
PURSUIT = "hazardhunt.sut.pursuit:PursuitController"


@pytest.fixture(scope="module")
def pursuit_run(tmp_path_factory):
    """A finished run with a failure and its trajectory (a cheap controller, 6 episodes)."""
    out = tmp_path_factory.mktemp("received") / "run"
    done = hazardhunt(
        "run", "--scenario", "head-on", "--field", "none", "--tester", "random",
        "--episodes", 6, "--out", out, "--controller", PURSUIT, cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert len(pd.read_parquet(out / "failures.parquet")) >= 1
    return out


def forged(run: Path, into: Path, summary_changes: dict | None = None, **tables) -> Path:
    """A copy of ``run`` in ``into`` whose tables ``tables`` (``failures=change``, with
    ``trajectories`` for the stored trajectories) are changed by ``change(frame)``, and whose
    ``summary.json`` gets ``summary_changes``, its checksums made anew: as whoever made it
    would send it."""
    received = into / "received"
    shutil.copytree(run, received)
    for name, change in tables.items():
        if name == "trajectories":
            parts = sorted((received / "trajectories").glob("*.parquet"))
            table = pd.concat([pd.read_parquet(part) for part in parts], ignore_index=True)
            for part in parts:
                part.unlink()
            path = received / "trajectories" / "part-00000.parquet"
        else:
            path = received / f"{name}.parquet"
            table = pd.read_parquet(path)
        change(table).to_parquet(path, index=False)
    summary = json.loads((received / "summary.json").read_text())
    summary |= summary_changes or {}
    summary["checksums"] = file_checksums(received)
    (received / "summary.json").write_text(json.dumps(summary))
    return received


@pytest.mark.parametrize(
    ("value", "column"),
    [(1e308, "human_x"), (float("nan"), "robot_y")],
)
def test_a_trajectory_no_floor_holds_is_named_damaged(pursuit_run, tmp_path, value, column):
    received = forged(pursuit_run, tmp_path, trajectories=lambda t: t.assign(**{column: value}))
    commands = [["report", received], ["export", received, "--out", tmp_path / "cases"]]
    for command in commands[: 2 if value > 0 else 1]:  # export once: it reads as report does
        done = hazardhunt(*command)
        assert done.returncode == 2, done.stderr
        assert done.stderr.strip() == (
            f"error: {received}: the run is damaged (trajectories/part-00000.parquet: {column} "
            "holds a value that is not a finite number of at most 1e+06 in size); run it again"
        )
    assert not (tmp_path / "cases").exists()


def test_episodes_all_numbered_0_are_named_damaged(pursuit_run, tmp_path):
    received = forged(pursuit_run, tmp_path, episodes=lambda e: e.assign(episode=0))
    done = hazardhunt("report", received)
    assert done.returncode == 2
    rows = len(pd.read_parquet(received / "episodes.parquet"))
    assert done.stderr.strip() == (
        f"error: {received}: the run is damaged (episodes.parquet: episode 0 has {rows} rows, "
        "not one); run it again"
    )


HOSTILE = "<script>alert(1)</script>\x1b[31m"
"""Text a stranger's run may hold: HTML, and an escape sequence that turns a terminal red."""


def test_names_of_megabytes_are_read_shortened_with_a_digest(pursuit_run, tmp_path):
    from hazardhunt.analysis.results import load_results

    long_class, long_tester = HOSTILE + "x" * 5_000_000, "t" * 2_000_000
    received = forged(
        pursuit_run,
        tmp_path,
        summary_changes={"tester": long_tester},
        failures=lambda f: f.assign(**{"class": long_class}),
    )
    results = load_results(received)
    (shown,) = set(results.failures["class"])
    assert len(shown) == 1000
    assert shown.startswith(HOSTILE + "xxx")
    assert shown[-13] == "…"  # then 12 hex digits of the whole name's digest
    assert {len(name) for name in results.runs["tester"]} == {1000}
    assert set(results.episodes["tester"]) == set(results.runs["tester"])


def test_a_warning_that_quotes_a_received_file_writes_its_control_characters_out():
    import warnings

    import hazardhunt
    from hazardhunt.warning_lines import show_warnings_in_one_line

    own, others = [], []
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.showwarning = lambda message, *rest: others.append(str(message))
        show_warnings_in_one_line(own.append)
        warnings.warn_explicit(f"class {HOSTILE}", UserWarning, hazardhunt.__file__, 1)
        warnings.warn_explicit("Glyph 27 (\x1b) missing", UserWarning, "matplotlib/text.py", 1)
    assert own == ["class <script>alert(1)</script>\\x1b[31m"]
    assert others == ["Glyph 27 (\\x1b) missing"]


def test_a_markdown_table_holds_names_as_text():
    from hazardhunt.analysis.page import markdown_table

    table = pd.DataFrame({"<b>tester</b>": [HOSTILE + "|\nnext"], "failures": [1.0]})
    assert markdown_table(table).splitlines() == [
        "| &lt;b&gt;tester&lt;/b&gt; | failures |",
        "|---|---|",
        "| &lt;script&gt;alert(1)&lt;/script&gt;\\x1b[31m\\|\\nnext | 1 |",
    ]


@pytest.fixture(scope="module")
def hostile_report(pursuit_run, tmp_path_factory):
    """``hazardhunt report`` of a received run whose failure's class is ``HOSTILE`` and 5 MB
    more, its tester ``<b>me</b>``: the run's folder and what the command printed."""
    received = forged(
        pursuit_run,
        tmp_path_factory.mktemp("hostile"),
        summary_changes={"tester": "<b>me</b>"},
        failures=lambda f: f.assign(**{"class": HOSTILE + "x" * 5_000_000}),
    )
    done = hazardhunt("report", received, timeout=120)
    assert done.returncode == 0, done.stderr[:2000]
    return received, done


@pytest.mark.slow  # a report: 20-40 s
def test_a_class_name_of_megabytes_is_shortened_in_the_report(hostile_report):
    received, _ = hostile_report
    table = (received / "report" / "tables" / "failures_per_class.md").read_text()
    (row,) = [line for line in table.splitlines() if "xxxx" in line]
    assert 1000 <= len(row) < 1200
    assert all(len(path.name) <= 130 for path in (received / "report" / "figures").iterdir())


@pytest.mark.slow  # a report: 20-40 s
def test_control_characters_in_a_name_reach_no_warning_line(hostile_report):
    _, done = hostile_report
    assert "Glyph 27 (\\x1b) missing" in done.stderr  # written out, not sent to the terminal
    assert "\x1b" not in done.stderr + done.stdout


@pytest.mark.slow  # a report: 20-40 s
def test_html_in_names_is_text_in_the_markdown_tables(hostile_report):
    received, _ = hostile_report
    tables = {path.name: path.read_text() for path in (received / "report" / "tables").glob("*.md")}
    assert not [name for name, text in tables.items() if "<script>" in text or "<b>" in text]
    assert "&lt;script&gt;alert(1)&lt;/script&gt;\\x1b[31m" in tables["failures_per_class.md"]
    assert "&lt;b&gt;me&lt;/b&gt;" in tables["failures_per_run.md"]


def test_a_report_link_in_a_received_run_is_named_and_not_followed(pursuit_run, tmp_path):
    received, elsewhere = tmp_path / "received", tmp_path / "elsewhere"
    shutil.copytree(pursuit_run, received)
    elsewhere.mkdir()
    (received / "report").symlink_to(elsewhere)
    done = hazardhunt("report", received)
    assert done.returncode == 2
    assert done.stderr.strip() == (
        f"error: {received / 'report'}: a symbolic link, where the report's own folder goes; a "
        "report never writes through one: remove the link (nothing was written)"
    )
    assert not any(elsewhere.iterdir())


@pytest.mark.slow  # an estimate of 100 episodes first: 10-15 s
def test_a_report_link_in_a_received_estimate_is_named(tmp_path):
    estimate, elsewhere = tmp_path / "estimate", tmp_path / "elsewhere"
    done = hazardhunt(
        "estimate", "--scenario", "head-on", "--field", "none", "--method", "mc",
        "--episodes", 100, "--batch-size", 50, "--out", estimate,
        "--controller", "hazardhunt.benchmark.conservative:ConservativeController",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    elsewhere.mkdir()
    (estimate / "report").symlink_to(elsewhere)
    done = hazardhunt("report", estimate)
    assert done.returncode == 2
    assert done.stderr.strip().startswith(f"error: {estimate / 'report'}: a symbolic link")
    assert not any(elsewhere.iterdir())


def test_copy_to_an_out_that_is_a_link_is_named(pursuit_run, tmp_path):
    out, elsewhere = tmp_path / "copy", tmp_path / "elsewhere"
    elsewhere.mkdir()
    out.symlink_to(elsewhere)
    done = hazardhunt("copy", pursuit_run, "--out", out)
    assert done.returncode == 2
    assert done.stderr.strip() == (
        f"error: --out: {out} is a symbolic link; copy writes a folder of its own, never through "
        "a link: name the folder itself, or another"
    )
    assert not any(elsewhere.iterdir())
