"""Write the full-budget part of docs/reproduction.md from the study's committed results.

The study's grid (``campaigns/study.toml``; ``campaigns/study-search.toml`` for the searchers
beyond the study's testers, and ``campaigns/study-portfolio.toml`` for hazardhunt's default
tester) runs in slices; after each, ``hazardhunt copy`` keeps the finished runs without
trajectories under ``benchmarks/results/study/`` (and ``study-search/``,
``study-portfolio/``). This script reads them together and rewrites the part of the document
between its two markers (appended at the end the first time) with how much of the grid is
done and, over the runs done, the study's figure and tables beside ours: failures per run,
Table I, Table II, Lessons 1, 2 and 3, and the learning curves as failures per 500 episodes
(a figure under ``docs/images/study/``). A kept run whose files do not match their checksums
is left out and named, on standard error and in the document. The paragraphs that judge each
lesson stay outside the markers, written by hand.

    python scripts/reproduction.py
    python scripts/reproduction.py --results DIR [DIR ...] --doc docs/reproduction.md --images DIR
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Callable
from pathlib import Path

import pandas as pd

from hazardhunt.analysis import figures, tables
from hazardhunt.analysis.page import markdown_table
from hazardhunt.analysis.report import loitering_frames
from hazardhunt.analysis.results import Results, load_results_of
from hazardhunt.analysis.study import STUDY_EPISODES, STUDY_REWARDS
from hazardhunt.campaign.replay import load_run_config, names_sut_plugins, replay_actions
from hazardhunt.env.rendering import plot_frames

BEGIN = "<!-- full-budget results: written by scripts/reproduction.py; edits here are lost -->"
END = "<!-- end of the full-budget results -->"
STUDY_RUNS = 81
STUDY_TESTERS = ("random", "ppo-acc", "ppo-max")
CURVE_WIDTH = 500
"""Episodes per point of the learning curves."""


def section(results: Results, images: Path, doc: Path) -> str:
    """The Markdown between the markers."""
    runs = results.runs
    episodes = int(runs["episodes"].sum())
    hours = float(runs["wall_time_s"].sum()) / 3600.0
    study = runs["tester"].isin(STUDY_TESTERS)
    others = sorted(set(runs.loc[~study, "tester"]))
    beside = int((~study).sum())
    beyond = (
        f" Beside them, {beside} {'run' if beside == 1 else 'runs'} of {', '.join(others)} on "
        "the same grid."
        if others
        else ""
    )
    left = STUDY_RUNS - int(study.sum())
    done = (
        f"All {STUDY_RUNS} of the study's runs are done."
        if left == 0
        else f"{int(study.sum())} of the study's {STUDY_RUNS} runs are done "
        f"({', '.join(sorted(runs.loc[study, 'run_id']))}); "
        f"{left} {'is' if left == 1 else 'are'} left."
    )
    lines = [
        "## The full budget",
        "",
        f"{done}{beyond} In all {episodes:,} episodes in "
        f"{hours:.1f} h of run time ({episodes / max(hours, 1e-9) / 3600.0:.1f} episodes/s per "
        f"run on average); each run plays the study's {STUDY_EPISODES:,} episodes.",
        "",
        *damage_notice(results),
        "### Failures per run",
        "",
        markdown_table(tables.failures_per_run(runs)),
        "",
        *failures_chart(runs, images, doc),
    ]
    coverage = tables.class_coverage(results)
    lines += [
        "### Failure classes found (Table I)",
        "",
        markdown_table(coverage.drop(columns=["found", "total"])),
        "",
        "### Runtime (Table II)",
        "",
        "Wall times of runs that shared the machine with other work are not comparable; the "
        "simulated hours are, whatever the machine did.",
        "",
        _or_none(
            tables.runtime_table(runs, results.episodes),
            "ppo-acc and ppo-max on the same case",
            wall_times=True,
        ),
        "",
        "### Lesson 1: each tester against random sampling",
        "",
        _or_none(tables.lesson_1(runs), "random and PPO runs with the same seed"),
        "",
        *lesson_1_by_case(runs),
        "### Lesson 2: classes against random sampling, failures per class",
        "",
        _or_none(tables.lesson_2(coverage), "random and PPO runs on the same case"),
        "",
        markdown_table(tables.failures_per_class(results.failures)),
        "",
        "### Lesson 3: reward hacking",
        "",
        markdown_table(readable(tables.reward_hacking(results.episodes))),
        "",
        *loitering_episode(results, images, doc),
    ]
    budget = int(results.episodes["episode"].max()) + 1
    curves = tables.learning_curves(
        results.episodes, bins=max(1, math.ceil(budget / CURVE_WIDTH)), per=CURVE_WIDTH
    )
    picture = figures.learning_curves_figure(curves, images / "learning_curves.png")
    link = relative_link(picture, doc)
    lines += [
        "### Learning curves",
        "",
        f"Failures per {CURVE_WIDTH} episodes over the whole budget, per tester and field "
        "(mean over scenarios and seeds).",
        "",
        f"![Failures per {CURVE_WIDTH} episodes]({link})",
        "",
    ]
    return "\n".join(lines)


def relative_link(picture: Path, doc: Path) -> str:
    """``picture`` as the Markdown of ``doc`` links it."""
    return Path(os.path.relpath(picture, doc.parent)).as_posix()


def failures_chart(runs: pd.DataFrame, images: Path, doc: Path) -> list[str]:
    """The study's bar chart: failures per run, mean and spread over the seeds, on a log scale
    (the runs' counts span two orders of magnitude)."""
    picture = figures.failures_bar_chart(runs, images / "failures_per_run.png", log=True)
    link = relative_link(picture, doc)
    return [
        "Bars are the mean over the seeds kept, error bars one standard deviation, dots the "
        "seeds (log scale).",
        "",
        f"![Failures per run]({link})",
        "",
    ]


def lesson_1_by_case(runs: pd.DataFrame) -> list[str]:
    """Lesson 1 case by case, with each case's verdict over its seeds and how many hold in
    every seed."""
    table = tables.lesson_1_by_case(runs)
    if table.empty:
        return []
    held = [
        f"`{tester}` {int((group['verdict'] == 'ahead').sum())} of {len(group)}"
        for tester, group in table.groupby("tester", sort=False)
    ]
    return [
        "Case by case: the failures of each seed beside random sampling's with the same seed, "
        "and the ratio of their failure rates with its exact 95 % interval (the conditional "
        "test of two Poisson rates: given a pair's failures, the tester's share is binomial; "
        "it counts every episode as an independent trial, which a tester that learns is not, "
        "so it says what the counts allow, not more). A case is `ahead` where the interval "
        "lies above 1 in every seed kept, `behind` where it lies below 1 in every one, `mixed` "
        f"otherwise. Ahead in every seed kept: {', '.join(held)} cases.",
        "",
        markdown_table(table),
        "",
    ]


def loitering_episode(results: Results, images: Path, doc: Path) -> list[str]:
    """The most typical loitering episode of the accumulated-reward tester (of any tester
    when it has none), replayed from its actions and drawn as four frames."""
    loitering = results.loitering
    if loitering.empty:
        return ["No episode matched the loitering pattern.", ""]
    own = loitering[loitering["tester"] == STUDY_REWARDS[0]]
    typical = tables.typical_loitering(own if not own.empty else loitering)
    assert typical is not None
    config = load_run_config(results.run_directory(str(typical["run_id"])))
    about = (
        f"{typical['run_id']}, episode {int(typical['episode'])}: {typical['outcome']}, "
        f"{int(typical['emergency_stops'])} stops, {typical['time_in_field']:.1f} s in the field"
    )
    if names_sut_plugins(config):
        return [f"The most typical loitering episode ({about}) ran a plug-in; not drawn.", ""]
    simulation, _ = replay_actions(config, typical["actions"])
    times, captions = loitering_frames(simulation)
    picture = plot_frames(images / "loitering.png", simulation, times, captions)
    link = relative_link(picture, doc)
    return [
        f"The most typical loitering episode, replayed from its actions ({about}):",
        "",
        f"![The most typical loitering episode]({link})",
        "",
    ]


def readable(table: pd.DataFrame, wall_times: bool = False) -> pd.DataFrame:
    """``table`` as people read it: speedups and shares in per cent, times faster as "64x",
    and with ``wall_times`` its columns in seconds as h:mm."""
    shown = table.copy()
    for column in shown.columns:
        name = str(column)
        if "speedup" in name or "share" in name:
            shown[column] = _each(shown[column], lambda v: f"{100.0 * v:.1f} %")
        elif name.startswith("faster than"):
            shown[column] = _each(shown[column], lambda v: f"{v:.0f}x")
        elif wall_times and name.endswith("(s)"):
            shown[column] = _each(shown[column], tables.hours_minutes)
            shown = shown.rename(columns={column: name.removesuffix("(s)") + "(h:mm)"})
    return shown


def _each(values: pd.Series, show: Callable[[float], str]) -> list[str]:
    """Every number of ``values`` shown; a missing one as an empty cell."""
    return ["" if pd.isna(v) else show(float(v)) for v in values]


def _or_none(table: pd.DataFrame, needs: str, wall_times: bool = False) -> str:
    if table.empty:
        return f"Not yet: it needs {needs}."
    return markdown_table(readable(table, wall_times))


def rewrite(doc: Path, generated: str) -> None:
    """Put ``generated`` between the markers of ``doc``, or append it with them."""
    text = doc.read_text()
    block = f"{BEGIN}\n\n{generated}\n{END}"
    if BEGIN in text and END in text:
        before, _, rest = text.partition(BEGIN)
        _, _, after = rest.partition(END)
        text = before + block + after
    else:
        text = text.rstrip("\n") + "\n\n" + block + "\n"
    doc.write_text(text)


def damage_notice(results: Results) -> list[str]:
    """A paragraph naming the kept runs left out because their files do not match their
    checksums (or do not read); nothing when there are none."""
    if not results.damaged:
        return []
    named = "; ".join(f"{run_id} ({damage})" for run_id, damage in sorted(results.damaged.items()))
    return [
        f"**Left out, damaged:** {named}. Their numbers are in no table below; copy them again "
        "from the campaign that ran them (`hazardhunt copy`).",
        "",
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--results",
        type=Path,
        nargs="+",
        default=[
            Path("benchmarks/results/study"),
            Path("benchmarks/results/study-search"),
            Path("benchmarks/results/study-portfolio"),
        ],
    )
    parser.add_argument("--doc", type=Path, default=Path("docs/reproduction.md"))
    parser.add_argument("--images", type=Path, default=Path("docs/images/study"))
    args = parser.parse_args()
    present = [directory for directory in args.results if directory.exists()]
    if not present:
        raise SystemExit(f"no results yet in {', '.join(map(str, args.results))}")
    results = load_results_of(present)
    for run_id, damage in sorted(results.damaged.items()):
        print(f"{run_id}: damaged, left out ({damage})", file=sys.stderr)
    args.images.mkdir(parents=True, exist_ok=True)
    rewrite(args.doc, section(results, args.images, args.doc))
    print(f"{args.doc}: {len(results.runs)} runs written")


if __name__ == "__main__":
    main()
