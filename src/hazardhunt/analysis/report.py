"""``hazardhunt report DIR``: the study's figures and tables from a run or campaign directory.

Writes ``DIR/report/`` (into a hidden sibling first, renamed into place once complete)::

    index.html       self-contained (images inlined): opens offline, can be mailed; it opens
                     with the verdict (failures, mechanisms, the worst failure, which tester
                     found what, the commands that keep them as regression cases)
    summary.json     per run and per table, machine-readable
    tables/          every table as CSV and Markdown
    figures/         every figure as PNG, the representative failures also as GIF

Writing a report imports nothing that the results name: the failures of a run whose controller
or safety layer is a plug-in are drawn from their stored trajectories instead of re-simulated.
The page itself is a Jinja2 template (:mod:`hazardhunt.analysis.page`).

Long (over 500 lines) because it is one section-writer per section of the page, each a few
lines of prose around a table or figure that ``tables`` and ``figures`` compute.
"""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import matplotlib
import pandas as pd
from markupsafe import Markup, escape

import hazardhunt
from hazardhunt.analysis import diversity, figures, page, tables, verdict
from hazardhunt.analysis.page import (
    Commands,
    Heading,
    Prose,
    Section,
    Text,
    check_report_folder,
    markdown_table,
)
from hazardhunt.analysis.results import Results, load_results
from hazardhunt.analysis.study import STUDY_BASELINE, STUDY_REWARDS
from hazardhunt.campaign.config import file_name
from hazardhunt.campaign.lock import process_running, waiting_lock
from hazardhunt.campaign.progress import shown_scenario
from hazardhunt.campaign.replay import (
    load_run_config,
    names_sut_plugins,
    replay_actions,
)
from hazardhunt.campaign.scenario_record import played_scenario, recorded_scenario
from hazardhunt.campaign.store import (
    REQUIREMENT_COLUMN,
    left_out,
    read_trajectory,
    write_bytes_atomic,
    write_json_atomic,
)
from hazardhunt.env.rendering import RecordedEpisode, animate_episode, plot_episode, plot_frames
from hazardhunt.sim.simulation import Simulation
from hazardhunt.spec.failure_classes import FailureClassifier
from hazardhunt.spec.reward_hacking import LoiteringRule
from hazardhunt.sut.route import scenario_route
from hazardhunt.world.scenario import Scenario

RUN_COLUMNS = (
    "run_id",
    "scenario",
    "field",
    "tester",
    "seed",
    "episodes",
    "failures",
    "classes_found",
    "classes_total",
    "wall_time_s",
    "cpu_time_s",
    "episodes_per_s",
    "source_digest",
    "blas",
)
"""What ``summary.json`` says about every run (SPEC 8), and what ran it: the digest of
hazardhunt's source and numpy's BLAS kernel (``config.json``)."""

Progress = Callable[[str], None]
"""Told the name of each step of the report as it starts."""


@dataclass
class _Report:
    """What has been written so far, to assemble the HTML page from."""

    directory: Path
    sections: list[Section] = field(default_factory=list)
    tables: dict[str, pd.DataFrame] = field(default_factory=dict)
    opening: Section | None = None
    """What the page opens with, before the study's sections."""
    findings: verdict.Verdict | None = None
    scenario_files: dict[str, str] = field(default_factory=dict)
    """The scenario behind each name the page shows (see :func:`_scenarios_shown`)."""

    @property
    def figures(self) -> Path:
        return self.directory / "figures"

    def section(self, title: str, intro: str = "") -> Section:
        section = Section(title, intro)
        self.sections.append(section)
        return section

    def table(self, section: Section, name: str, table: pd.DataFrame, caption: str = "") -> None:
        """Write ``tables/<name>.csv`` and ``.md`` and show the table in ``section``."""
        self.tables[name] = table
        folder = self.directory / "tables"
        folder.mkdir(parents=True, exist_ok=True)
        table.to_csv(folder / f"{name}.csv", index=False)
        (folder / f"{name}.md").write_text(markdown_table(table) + "\n")
        section.blocks.append(page.table(name, table, caption))

    def image(self, section: Section, path: Path, caption: str) -> None:
        """Inline an image written under ``figures/`` into ``section``."""
        section.blocks.append(page.image(path, caption))


def write_report(
    directory: Path,
    progress: Progress | None = None,
    classifier: FailureClassifier | None = None,
) -> Path:
    """Write the report of a run or campaign directory; returns the path of ``index.html``.

    With a ``classifier``, every failure is classified anew from its stored trajectory (for
    another taxonomy, or runs recorded with an older one); otherwise the recorded classes count.
    Runs whose files are damaged are left out and named in the report, and so are the runs of
    a campaign that failed, in its verdict first. The report is written into a hidden sibling of
    ``report/`` and replaces it only once complete: a report that fails (a full disk) leaves the
    previous one, if any, and nothing else.

    Raises:
        ResultsError: When the directory holds no complete run.
        RunsFailed: When no run of the campaign is complete and some failed.
    """
    tell = progress if progress is not None else (lambda step: None)
    final = directory / "report"
    check_report_folder(final)  # before the run's check, which calls any link damage
    tell("reading results")
    results, scenario_files = _scenarios_shown(load_results(directory, classifier))
    _remove_leftovers(directory)
    scratch = directory / f".report-{os.getpid()}.partial"
    shutil.rmtree(scratch, ignore_errors=True)
    try:
        report = _Report(scratch, scenario_files=scenario_files)
        report.directory.mkdir()
        # Names from the results (testers, classes) are text, never matplotlib's mathtext.
        with matplotlib.rc_context({"text.parse_math": False}):
            _write_sections(report, results, tell)
        tell("writing index.html")
        write_json_atomic(report.directory / "summary.json", _summary(results, report))
        write_bytes_atomic(report.directory / "index.html", _page(results, report).encode())
        _put_in_place(scratch, final)
    except BaseException:
        shutil.rmtree(scratch, ignore_errors=True)  # a full disk keeps no half report
        raise
    return final / "index.html"


def _scenarios_shown(results: Results) -> tuple[Results, dict[str, str]]:
    """``results`` with each scenario named as a campaign's table names it (a built-in by its
    name, a file by its path below the working directory, else by its file name), and the
    scenario behind each name. Should two files get the same name, every file keeps its path."""
    scenarios = [str(name) for name in results.runs["scenario"].unique()]
    shown = {name: shown_scenario(name) for name in scenarios}
    if len(set(shown.values())) < len(shown):
        shown = {name: name for name in scenarios}
    renamed = {
        name: table.assign(scenario=table["scenario"].map(shown))
        for name, table in [
            ("runs", results.runs),
            ("episodes", results.episodes),
            ("failures", results.failures),
            ("loitering", results.loitering),
            ("violations", results.violations),
        ]
        if "scenario" in table.columns and not table.empty
    }
    return replace(results, **renamed), {name: path for path, name in shown.items()}


def _write_sections(report: _Report, results: Results, tell: Progress) -> None:
    tell("failures per run")
    _failures_per_run(report, results)
    tell("failure classes")
    _table_sections(report, results, TABLE_SECTIONS[:1])
    tell("classes found against episodes")
    _class_discovery(report, results)
    tell("clusters of failures")
    _clusters(report, results)
    tell("quality-diversity archives")
    _archives(report, results)
    tell("lessons")
    _table_sections(report, results, TABLE_SECTIONS[1:])
    tell("reward hacking")
    _reward_hacking(report, results)
    tell("learning curves and heat maps")
    _learning_and_places(report, results)
    tell("representative failures")
    _representatives(report, results)
    tell("failure rates")
    _rates(report, results)
    _requirements(report, results)
    _runs(report, results)
    tell("verdict")
    _verdict(report, results)


def _put_in_place(written: Path, final: Path) -> None:
    """Replace the report ``final`` (if any) by the complete one ``written``. Two reports of
    one directory finishing at once take turns (a lock beside ``final``): the last one stays."""
    previous = written.with_suffix(".previous")
    with waiting_lock(final.with_name(".report.lock")):
        if final.exists():
            final.rename(previous)
        written.rename(final)
    shutil.rmtree(previous, ignore_errors=True)


def _remove_leftovers(directory: Path) -> None:
    """Remove what reports that were killed left behind (not those of a report still running)."""
    for leftover in directory.glob(".report-*.*"):
        pid = leftover.name.removeprefix(".report-").partition(".")[0]
        if pid.isdigit() and not process_running(int(pid)):
            shutil.rmtree(leftover, ignore_errors=True)


# ------------------------------------------------------------------ sections
def _failures_per_run(report: _Report, results: Results) -> None:
    section = report.section(
        "Failures per run",
        "Mean number of failures (unsafe contacts) per run by scenario and tester, for each "
        "protective-field setting; error bars are the standard deviation over seeds, dots the "
        "seeds (the study's bar chart).",
    )
    path = figures.failures_bar_chart(results.runs, report.figures / "failures_per_run.png")
    report.image(section, path, "Failures per run by scenario, tester and field setting")
    report.table(section, "failures_per_run", tables.failures_per_run(results.runs))


TableSource = Callable[[Results, dict[str, pd.DataFrame]], pd.DataFrame]
"""Computes a table from the results and the tables computed before it."""

TABLE_SECTIONS: tuple[tuple[str, str, str, TableSource], ...] = (
    (
        "Failure classes found (Table I)",
        "Distinct failure classes found over all seeds, k / K, and by each seed, beside the "
        "study's own numbers. "
        "K counts the named classes of the taxonomy (docs/failure-classes.md): 10 with a field "
        "and 8 without, where the study counted 9 and 8; failures no class fits are listed as "
        "'other' and not counted in k.",
        "classes",
        lambda results, _: tables.class_coverage(results),
    ),
    (
        "Lesson 2: diversity against random sampling",
        "In how many (scenario, field) cases each tester found more, as many or fewer "
        "distinct classes than random sampling, and how often each tester found each class "
        "(the study: RL found more failures per class, with about as many classes).",
        "lesson_2",
        lambda _, done: tables.lesson_2(done["classes"]),
    ),
    (
        "Failures per class",
        "Failures of each class found by each tester, over all scenarios, fields and seeds.",
        "failures_per_class",
        lambda results, _: tables.failures_per_class(results.failures),
    ),
    (
        "Lesson 1: does a tester find more failures than random sampling?",
        "For every (scenario, field, seed) that both testers ran, whether the tester found "
        "more failures than random sampling with the same seed (the study asked it of RL).",
        "lesson_1",
        lambda results, _: tables.lesson_1(results.runs),
    ),
    (
        "Runtime: accumulated vs maximum reward (Table II)",
        f"Mean wall time per run; the speedup of {STUDY_REWARDS[1]} is 1 - max / acc as in the "
        "study. "
        "'per 20k' scales the measured time per episode to the study's 20,000 episodes; the "
        "simulated hours per run, unlike wall times, do not depend on what else the machine ran.",
        "runtime",
        lambda results, _: tables.runtime_table(results.runs, results.episodes),
    ),
)
"""Sections that are one table each: title, explanation, table name, how to compute it (from
the results and the tables before it, by name)."""

EMPTY_TABLE_NEEDS = {
    "lesson_2": f" It needs {STUDY_BASELINE} and another tester on the same (scenario, field).",
    "lesson_1": f" It needs {STUDY_BASELINE} and another tester with the same (scenario, field, "
    "seed).",
    "runtime": f" It needs {STUDY_REWARDS[0]} and {STUDY_REWARDS[1]} on the same (scenario, "
    f"field): add the missing one to the campaign's testers.",
}
"""What a table that came out empty needs, by table name, said below it."""


def _table_sections(
    report: _Report,
    results: Results,
    sections: tuple[tuple[str, str, str, TableSource], ...],
) -> None:
    for title, intro, name, compute in sections:
        section = report.section(title, intro)
        table = compute(results, report.tables)
        if table.empty:
            needs = EMPTY_TABLE_NEEDS.get(name, "")
            section.blocks.append(Text(f"The campaign has no runs this table compares.{needs}"))
        report.table(section, name, table)


def _class_discovery(report: _Report, results: Results) -> None:
    section = report.section(
        "Diversity: classes found against episodes",
        "Distinct failure classes found against the episodes played, per tester and "
        "(scenario, field) case, seeds pooled and 'other' not counted, as in Table I: a curve "
        "that rises early found the classes early. The table gives the episode at which each "
        "tester first found each class (its index in the run, the earliest over the seeds; "
        "blank: never found).",
    )
    discovery = tables.class_discovery(results.failures)
    curves = tables.class_discovery_curves(discovery, results.runs)
    path = figures.class_discovery_figure(curves, report.figures / "class_discovery.png")
    report.image(section, path, "Distinct classes found against episodes played")
    report.table(
        section,
        "class_discovery",
        tables.class_first_found(discovery),
        "Episode at which each class was first found, per tester",
    )


def _archives(report: _Report, results: Results) -> None:
    """The archive of every quality-diversity run (``tester/archive.parquet``), if any."""
    found = [
        (str(run_id), Path(directory) / "tester" / "archive.parquet")
        for run_id, directory in zip(results.runs["run_id"], results.runs["directory"], strict=True)
    ]
    archives = [(run_id, path) for run_id, path in found if path.is_file()]
    if not archives:
        return
    section = report.section(
        "Quality-diversity archives",
        "The archive each quality-diversity run kept (docs/search-methods.md), over its "
        "first two measures (by default the bearing of the contact or closest approach "
        "around the robot and the robot's speed there): in every cell the largest risk an "
        "episode reached (over the archive's other axes); framed cells hold a failure. Empty "
        "cells were never reached.",
    )
    for run_id, path in archives:
        picture = figures.archive_heat_map(
            pd.read_parquet(path), report.figures / f"archive_{file_name(run_id)}.png", run_id
        )
        report.image(section, picture, f"The archive of {run_id}")


def _clusters(report: _Report, results: Results) -> None:
    section = report.section(
        "Diversity beyond the taxonomy: clusters",
        "Failures clustered on features of their trajectories alone (where around the robot "
        "the contact was, the face touched, the human's velocity relative to the robot, the "
        "robot's speed, the safety layer's stops and releases, the time and place of the "
        "contact; standardised), with HDBSCAN, each (scenario, field) case on its own, testers "
        "and seeds pooled (docs/failure-classes.md). The first table counts the clusters "
        "beside the classes ('other' included); a tester's row counts the clusters of its "
        "case its failures fall in; 'unclustered' failures fit no cluster. The adjusted Rand "
        "index is 1 when clusters and classes split the clustered failures alike and about 0 "
        "when they are unrelated. The second table counts the failures of each class in each "
        "cluster: a class spread over several clusters holds failures the data tells apart; "
        "a cluster spread over several classes was split by the taxonomy only.",
    )
    features = diversity.failure_features(results)
    if features.empty:
        recorded = not results.failures.empty
        section.blocks.append(
            Prose(
                Markup(
                    "No failure's trajectory is stored (a copy made by <code>hazardhunt copy"
                    "</code> leaves them out): the clusters need them."
                )
            )
            if recorded
            else Text("No failure was recorded.")
        )
        return
    clustered = diversity.embed(diversity.cluster_failures(features))
    path = figures.failure_clusters_figure(clustered, report.figures / "failure_clusters.png")
    report.image(
        section,
        path,
        "Failures in the plane of the first two principal components of their features, "
        "coloured by class; the marker and the number show the cluster, a cross: unclustered",
    )
    report.table(
        section,
        "clusters",
        diversity.clusters_against_classes(features),
        "Clusters beside classes, per case and tester",
    )
    report.table(
        section,
        "clusters_vs_classes",
        diversity.contingency_table(clustered),
        "Failures of each class (row) in each cluster (column) of its case",
    )


def _reward_hacking(report: _Report, results: Results) -> None:
    rule = LoiteringRule().describe()
    section = report.section(
        "Lesson 3: reward hacking, measured",
        "Per tester: the human's time inside the protective field and the emergency stops per "
        "episode, the share of stalls and timeouts, the risk summed over episodes without a "
        "failure (the return the accumulated reward pays for them), and the episodes flagged "
        f"as loitering ({rule}).",
    )
    report.table(section, "reward_hacking", tables.reward_hacking(results.episodes))
    typical = tables.typical_loitering(results.loitering)
    if typical is None:
        section.blocks.append(Text("No episode matched the loitering pattern."))
        return
    directory = results.run_directory(str(typical["run_id"]))
    config = load_run_config(directory)
    if names_sut_plugins(config):
        section.blocks.append(
            Text(
                f"The most typical loitering episode ({typical['run_id']}, episode "
                f"{int(typical['episode'])}) ran a plug-in controller or safety layer, which the "
                "report does not import: it is not re-simulated."
            )
        )
        return
    simulation, _ = replay_actions(
        config, typical["actions"], scenario=recorded_scenario(directory)
    )
    times, captions = loitering_frames(simulation)
    path = plot_frames(report.figures / "loitering.png", simulation, times, captions)
    report.image(
        section,
        path,
        f"The most typical loitering episode: {typical['run_id']}, episode "
        f"{int(typical['episode'])} ({typical['outcome']}, "
        f"{int(typical['emergency_stops'])} stops, {typical['time_in_field']:.1f} s in the field)",
    )


def loitering_frames(simulation: Simulation) -> tuple[list[float], list[str]]:
    """Four instants that tell a loitering episode: approach, stop, release, next stop (or,
    without a release, the stop held until the end)."""
    rows = simulation.trajectory()
    stops = [row.emergency_stop for row in rows]
    times = [row.time for row in rows]
    first = stops.index(True) if True in stops else 0
    release = next((i for i in range(first, len(rows)) if not stops[i]), None)
    again = (
        next((i for i in range(release, len(rows)) if stops[i]), None)
        if release is not None
        else None
    )
    approach = max(0.0, times[first] - 1.0)
    if release is not None and again is not None:
        return (
            [approach, times[first], times[release], times[again]],
            ["walks in front", "field triggers a stop", "leaves, robot restarts", "another stop"],
        )
    middle = times[first] + (times[-1] - times[first]) / 2
    return (
        [approach, times[first], middle, times[-1]],
        ["walks in front", "field triggers a stop", "stays in the field", "end"],
    )


def _learning_and_places(report: _Report, results: Results) -> None:
    section = report.section(
        "Learning curves",
        "Failures per 100 episodes over the course of the runs (mean over scenarios and seeds).",
    )
    curves = tables.learning_curves(results.episodes)
    path = figures.learning_curves_figure(curves, report.figures / "learning_curves.png")
    report.image(section, path, "Failures per 100 episodes over the runs")
    places = report.section(
        "Where failures happen", "The human's position at each failure's contact, per tester."
    )
    failures = results.failures
    if failures.empty or "contact_x" not in failures:
        places.blocks.append(Text("No failure was recorded."))
        return
    for scenario in sorted(results.runs["scenario"].unique()):
        chosen = failures[failures["scenario"] == scenario]
        name = file_name(f"heat_map_{scenario}")
        played = _played_scenario(results, scenario, report.scenario_files[scenario])
        path = figures.failure_heat_map(chosen, played, report.figures / f"{name}.png")
        report.image(places, path, f"Failures on the floor: {scenario}")


def _played_scenario(results: Results, shown: str, scenario: str) -> Scenario:
    """The scenario shown as ``shown`` (``scenario``, a built-in name or file), as its first
    run played it."""
    run_id = results.runs.loc[results.runs["scenario"] == shown, "run_id"].iloc[0]
    return played_scenario(results.run_directory(str(run_id)), scenario)


def _representatives(report: _Report, results: Results) -> None:
    section = report.section(
        "A representative failure per class",
        "For every class found, the failure whose time to contact is the class's median, drawn "
        "from its stored trajectory: its tracks and an animation of its last seconds "
        "(hazardhunt replay plays it again and says whether it reproduces).",
    )
    chosen = tables.representatives(results.failures)
    if chosen.empty:
        section.blocks.append(Text("No failure was recorded."))
        return
    rows = []
    for _, row in chosen.iterrows():
        run_id, episode, name = str(row["run_id"]), int(row["episode"]), str(row["class"])
        title = f"{name}: {run_id}, episode {episode}"
        drawn = _failure_pictures(report, section, results, row, f"class_{name}", title)
        rows.append(
            {
                "class": name,
                "run_id": run_id,
                "episode": episode,
                "sim_time": row["sim_time"],
                "contact_face": row["contact_face"],
                "pictures": drawn,
            }
        )
    report.table(
        section, "representatives", pd.DataFrame(rows), "hazardhunt replay RUN --episode EPISODE"
    )


def _failure_pictures(
    report: _Report, section: Section, results: Results, row: pd.Series, stem: str, title: str
) -> str:
    """Draw the failure ``row`` into ``section`` (files named after ``stem``) from its stored
    trajectory, its tracks and an animation of its last seconds; no SUT is built. Returns how
    it was drawn."""
    run_id, episode = str(row["run_id"]), int(row["episode"])
    directory = results.run_directory(run_id)
    if "trajectories" in left_out(directory):
        return "not drawn: a copy without trajectories (hazardhunt replay draws it)"
    config = load_run_config(directory)
    scenario = played_scenario(directory, config.scenario)
    robot = config.env.robot
    recorded = RecordedEpisode(
        scenario,
        scenario_route(scenario, robot.width),
        results.field_shape(str(row["field"]), str(row["scenario"])),
        robot,
        tuple(read_trajectory(directory, episode)),
    )
    stem = file_name(stem)
    picture = plot_episode(
        report.figures / f"{stem}.png",
        recorded.scenario,
        recorded.route,
        recorded.samples,
        recorded.field,
        title,
        str(row["outcome"]),
        robot,
    )
    name = str(row["class"])
    animation = animate_episode(
        report.figures / f"{stem}.gif", recorded, title=name, fps=5, last_seconds=6.0, size=4.5
    )
    report.image(section, picture, title)
    report.image(section, animation, f"{name}: the last 6 s")
    return "drawn as recorded"


def _rates(report: _Report, results: Results) -> None:
    section = report.section(
        "Failure rates",
        "Failures per episode by scenario, field and tester (seeds pooled) with the exact 95 % "
        "Clopper-Pearson interval.",
    )
    rates = tables.failure_rates(results.runs)
    path = figures.failure_rates_figure(rates, report.figures / "failure_rates.png")
    report.image(section, path, "Failure rate with its 95 % confidence interval")
    report.table(section, "failure_rates", rates)


def _requirements(report: _Report, results: Results) -> None:
    """Violations and robustness of the requirements beyond the contact rule, when the runs
    judged their episodes by any (``docs/requirements.md``)."""
    columns = [c for c in results.episodes.columns if str(c).startswith(REQUIREMENT_COLUMN)]
    if not columns:
        return
    section = report.section(
        "Requirements beyond the contact rule",
        "Every episode's robustness for each requirement the runs judged it by: the margin by "
        "which it kept the requirement, negative when it violated it (docs/requirements.md).",
    )
    keys = ["scenario", "field", "tester"]
    long = results.episodes.melt(
        id_vars=keys, value_vars=columns, var_name="requirement", value_name="robustness"
    ).dropna(subset=["robustness"])
    long["requirement"] = long["requirement"].str.removeprefix(REQUIREMENT_COLUMN)
    path = figures.robustness_figure(long, report.figures / "robustness.png")
    report.image(section, path, "Robustness per requirement and tester (seeds pooled)")
    grouped = long.groupby([*keys, "requirement"], sort=False)["robustness"]
    table = grouped.agg(
        episodes="size",
        violations=lambda r: int((r < 0).sum()),
        lowest_robustness="min",
    ).reset_index()
    table["decided_by"] = [_decided_by(results.runs, row) for row in table.itertuples()]
    report.table(section, "requirements", table)


def _decided_by(runs: pd.DataFrame, row: Any) -> str:
    """The signals that decided a requirement's violations in the runs of ``row``'s case and
    tester, with their counts (from the runs' summaries)."""
    counts: dict[str, int] = {}
    mine = runs[
        (runs["scenario"] == row.scenario)
        & (runs["field"] == row.field)
        & (runs["tester"] == row.tester)
    ]
    for requirements in mine.get("requirements", pd.Series(dtype=object)):
        if not isinstance(requirements, dict):
            continue
        decided = (requirements.get(row.requirement) or {}).get("decided_by") or {}
        for signals, count in decided.items():
            counts[signals] = counts.get(signals, 0) + int(count)
    return "; ".join(f"{signals}: {count}" for signals, count in counts.items())


def _runs(report: _Report, results: Results) -> None:
    section = report.section(
        "Runs",
        "Every finished run, with the digest of the hazardhunt source that ran it and numpy's "
        "BLAS kernel (blank: not recorded).",
    )
    report.table(section, "runs", results.runs[[c for c in RUN_COLUMNS if c in results.runs]])
    for column, what in (("source_digest", "hazardhunt sources"), ("blas", "BLAS kernels")):
        kinds = results.runs[column].dropna().unique() if column in results.runs else []
        if len(kinds) > 1:
            section.blocks.append(
                Text(
                    f"These runs were recorded by {len(kinds)} different {what} "
                    f"({', '.join(sorted(map(str, kinds)))}): a run reproduces exactly only "
                    "with its own (docs/design.md, Determinism)."
                )
            )
    if unfinished := len(results.unfinished):
        one = unfinished == 1
        section.blocks.append(
            Text(
                f"{unfinished} run{_s(unfinished)} of the campaign {'has' if one else 'have'} not "
                f"finished and {'is' if one else 'are'} left out: {', '.join(results.unfinished)}."
                + "".join(
                    f" Some may have failed: the campaign's ledger cannot tell ({problem})."
                    for problem in results.ledger_problems
                ),
                "warning",
            )
        )
    for run_id, error in results.failed.items():
        section.blocks.append(
            Text(
                f"Run {run_id} failed and is left out: {error}. Running the campaign again "
                "retries it.",
                "warning",
            )
        )
    for run_id, damage in results.damaged.items():
        section.blocks.append(
            Text(
                f"Run {run_id} is damaged and left out: {damage}. Running the campaign again "
                "redoes it.",
                "warning",
            )
        )


def _verdict(report: _Report, results: Results) -> None:
    """The page's first section: what the campaign found, the worst failure, which tester found
    what and how to keep the failures as regression cases."""
    findings = verdict.verdict(results, report.tables.get("clusters"))
    report.findings = findings
    section = Section("Verdict")
    report.opening = section
    section.blocks.append(Prose(verdict_headline(findings), "headline"))
    if results.failed:
        section.blocks.append(Text(_why_runs_failed(results.failed), "warning"))
    worst = verdict.worst_failure(results.failures)
    if worst is not None:
        section.blocks.append(Heading("The worst failure"))
        section.blocks.append(Text(f"{_worst_facts(worst)} Worst means {verdict.WORST_RULE}."))
        title = f"Worst: {worst['class']}, {worst['run_id']}, episode {int(worst['episode'])}"
        _failure_pictures(report, section, results, worst, "worst_failure", title)
    section.blocks.append(Heading("Which tester found what"))
    report.table(
        section,
        "verdict_testers",
        verdict.testers_found(results),
        "Per tester: its unsafe failures, the distinct classes it found, and the episode (its "
        "index in the run, the earliest over cases and seeds) of its first failure and of the "
        "first failure of each class; blank: never.",
    )
    arms = verdict.arms_found(results)
    if not arms.empty:
        report.table(
            section,
            "verdict_arms",
            arms,
            "Per portfolio run and class: the episode of its first failure of that class and "
            "the arm of the portfolio that played it (docs/search-methods.md).",
        )
    if findings.failures:
        _regression_commands(section, results)
    _incomplete_runs(section, results)


def verdict_headline(findings: verdict.Verdict) -> Markup:
    """The verdict in one sentence or two, numbers in bold (the only text in it, the class
    names, escaped), after the runs that failed, if any: what it says does not cover them."""
    failed = findings.failed_runs
    if failed:
        one = failed == 1
        return Markup(
            f'<strong class="warning">{failed} run{_s(failed)} of the campaign failed</strong> '
            f"and {'is' if one else 'are'} not in this verdict: nothing of "
            f"{'it' if one else 'them'} was kept (why below). "
        ) + verdict_headline(replace(findings, failed_runs=0))
    played = f"in {findings.episodes} episodes of {findings.runs} run{_s(findings.runs)}"
    untested = ""
    if findings.sut_errors:
        share = findings.sut_errors / max(findings.episodes, 1)
        untested = (
            f' <strong class="warning">{findings.sut_errors} of these episodes ({share:.0%}) '
            "ended in a SUT error and tested nothing</strong> (the controller or safety layer "
            "raised, hung or returned something unusable; the runs' episode tables name each "
            "error)."
        )
    if not findings.failures:
        if findings.sut_errors >= findings.episodes:
            return Markup(f"<strong>Nothing was tested</strong> {played}.{untested}")
        return Markup(
            f"<strong>No unsafe failure</strong> {played}: {escape(verdict.NOT_A_PASS)}. "
            "Among the episodes these testers chose the failure rate is below "
            f"{findings.rate_bound:.2g} per tested episode (95 % confidence, Clopper-Pearson); "
            "how likely a failure is with real people is another question "
            "(<code>hazardhunt estimate</code>, docs/risk.md), and "
            f"{escape(verdict.SLOW_TO_FIND)}.{untested}"
        )
    classes = len(findings.classes)
    text = (
        f"<strong>{findings.failures} unsafe failure{_s(findings.failures)}</strong> {played}, "
        f"<strong>{classes} distinct mechanism{_s(classes)}</strong> (failure classes"
        f"{': ' + escape(', '.join(findings.classes)) if classes else ''})"
    )
    if findings.unclassified:
        text += f"; {findings.unclassified} failure{_s(findings.unclassified)} fit no class"
    if findings.clusters is not None:
        text += (
            f"; their trajectories form <strong>{findings.clusters} "
            f"cluster{_s(findings.clusters)}</strong>"
        )
    return Markup(text + "." + untested)


def _why_runs_failed(failed: dict[str, str]) -> str:
    """The error of the run that failed, or of the first of those that failed."""
    first, error = next(iter(failed.items()))
    if len(failed) == 1:
        return f"Run {first} failed: {error}. Running the campaign again retries it."
    return (
        f"{len(failed)} runs failed; the first, {first}: {error}. Runs lists each with its "
        "error; running the campaign again retries them."
    )


def _worst_facts(worst: pd.Series) -> str:
    field = "no protective field" if worst["field"] == "none" else f"the {worst['field']} field"
    return (
        f"{worst['class']} in {worst['scenario']} with {field}, found by {worst['tester']} "
        f"(seed {int(worst['seed'])}, episode {int(worst['episode'])}): the human touched the "
        f"robot's {worst['contact_face']} face at {float(worst['sim_time']):.1f} s, risk "
        f"{float(worst['max_risk']):.0f}."
    )


def _regression_commands(section: Section, results: Results) -> None:
    plugins: dict[str, list[str]] = {"--controller": [], "--safety-layer": []}
    for directory in results.runs["directory"]:
        config = load_run_config(Path(directory))
        for option, spec in (
            ("--controller", config.controller),
            ("--safety-layer", config.safety_layer),
        ):
            if spec is not None and spec.path not in plugins[option]:
                plugins[option].append(spec.path)
    commands = verdict.regression_commands(results.directory, plugins)
    section.blocks.append(Heading("Keep them as regression cases"))
    section.blocks.append(Commands(tuple(commands)))
    named = [option for option, paths in plugins.items() if paths]
    if named:
        section.blocks.append(
            Text(
                f"The runs name plug-ins of their own ({', '.join(named)}): code that came "
                "with the results, which regress does not import. Put the import path of your "
                "own in the command (package.module:Class, found in the working directory), "
                "or read the runs' code before you trust it.",
                "warning",
            )
        )
    section.blocks.append(
        Text(
            "export writes one case file per class, scenario and field (--all: one per failure; "
            "--pytest: also a pytest module); regress re-runs every case against the system "
            "under test and exits with 1 while any still fails (3 while any could not be "
            "tested), so that it can gate a CI job."
        )
    )


def _incomplete_runs(section: Section, results: Results) -> None:
    missing = len(results.unfinished) + len(results.damaged)
    if missing:
        section.blocks.append(
            Text(
                f"{missing} run{_s(missing)} of the campaign {'is' if missing == 1 else 'are'} "
                "unfinished or damaged and left out (see Runs).",
                "warning",
            )
        )


def _s(count: int) -> str:
    return "" if count == 1 else "s"


# ------------------------------------------------------------------ outputs
def _summary(results: Results, report: _Report) -> dict[str, Any]:
    def records(table: pd.DataFrame) -> list[dict[str, Any]]:
        return list(json.loads(table.to_json(orient="records")))

    lesson = report.tables["lesson_1"]
    return {
        "directory": str(results.directory),
        "generated_at": datetime.now(timezone.utc).isoformat(),
        "hazardhunt_version": hazardhunt.__version__,
        "runs": records(report.tables["runs"]),
        "unfinished_runs": results.unfinished,
        "failed_runs": results.failed,
        "damaged_runs": results.damaged,
        "lesson_1": {
            str(row["tester"]): {
                "more_failures_than_random": int(row[f"more failures than {STUDY_BASELINE}"]),
                "comparisons": int(row["comparisons"]),
            }
            for _, row in lesson.iterrows()
        },
        "verdict": _verdict_summary(report),
        "tables": {name: records(table) for name, table in report.tables.items()},
    }


def _verdict_summary(report: _Report) -> dict[str, Any] | None:
    findings = report.findings
    if findings is None:
        return None
    return {
        "failures": findings.failures,
        "episodes": findings.episodes,
        "classes": list(findings.classes),
        "unclassified_failures": findings.unclassified,
        "clusters": findings.clusters,
        "failure_rate_upper_bound": findings.rate_bound,
        "sut_errors": findings.sut_errors,
        "failed_runs": findings.failed_runs,
    }


def _page(results: Results, report: _Report) -> str:
    runs = results.runs
    facts = (
        f"{len(runs)} runs, {int(runs['episodes'].sum())} episodes, "
        f"{int(runs['failures'].sum())} failures; "
        f"hazardhunt {hazardhunt.__version__}, "
        f"{datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC"
    )
    return page.render_page(results.directory, report.opening, report.sections, facts)
