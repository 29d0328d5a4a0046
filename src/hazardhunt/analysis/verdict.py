"""The verdict a report opens with: what a campaign found, how, and the worst of it."""

from __future__ import annotations

import shlex
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from hazardhunt.analysis import tables
from hazardhunt.analysis.diversity import ALL
from hazardhunt.analysis.results import Results
from hazardhunt.spec.failure_classes import OTHER

WORST_RULE = (
    "the highest risk at contact, 100 x (1 + human speed x robot speed / 1.8) (SPEC 4): the "
    "hardest impact; ties go to the first in run order"
)
"""How the report picks the worst failure, as it tells the reader."""

NOT_A_PASS = "none in this budget, not a proof of safety"
"""What finding no unsafe failure means, as a run's summary and the report's verdict say it."""

SLOW_TO_FIND = (
    "failures a search has to aim for can take it thousands of episodes, behind a protective "
    'field above all (docs/search-methods.md, "A fifth held-out set")'
)
"""Why a search may have found none yet, as both say it."""


@dataclass(frozen=True)
class Verdict:
    """The campaign's findings in a few numbers."""

    runs: int
    episodes: int
    failures: int
    classes: tuple[str, ...]
    """The distinct named classes found, over every case (``other`` not counted)."""
    unclassified: int
    """Failures no class fits (``other``)."""
    clusters: int | None
    """Clusters of all failures' trajectories together (None: no failure's trajectory is
    stored)."""
    rate_bound: float
    """Upper end of the 95 % Clopper-Pearson interval of the failure rate, all runs pooled,
    over the episodes that tested the system (``sut_error`` episodes left out)."""
    sut_errors: int = 0
    """Episodes that ended in ``sut_error``: the controller or safety layer raised, hung or
    returned something unusable, so they tested nothing."""
    failed_runs: int = 0
    """Runs of the campaign that failed (tested nothing, or raised): none of the numbers
    above counts them."""


def verdict(results: Results, clusters: pd.DataFrame | None) -> Verdict:
    """The verdict on ``results``; ``clusters`` is the clusters-beside-classes table
    (:func:`hazardhunt.analysis.diversity.clusters_against_classes`), if there is one."""
    runs, failures = results.runs, results.failures
    found = set(failures["class"]) if "class" in failures else set()
    episodes = int(runs["episodes"].sum())
    count = int(runs["failures"].sum())
    sut_errors = int(runs["sut_errors"].fillna(0).sum()) if "sut_errors" in runs else 0
    return Verdict(
        runs=len(runs),
        episodes=episodes,
        failures=count,
        classes=tuple(sorted(found - {OTHER})),
        unclassified=int((failures["class"] == OTHER).sum()) if "class" in failures else 0,
        clusters=_all_clusters(clusters),
        rate_bound=tables.clopper_pearson(count, episodes - sut_errors)[1],
        sut_errors=sut_errors,
        failed_runs=len(results.failed),
    )


def _all_clusters(clusters: pd.DataFrame | None) -> int | None:
    """The clusters of every failure, from the clusters table: its pooled row when the failures
    span several cases, else its one case's row."""
    if clusters is None or clusters.empty:
        return None
    everyone = clusters[clusters["tester"] == ALL]
    pooled = everyone[everyone["scenario"] == ALL]
    row = pooled if not pooled.empty else everyone
    return int(row["clusters"].iloc[0])


def worst_failure(failures: pd.DataFrame) -> pd.Series | None:
    """The failure with the highest risk at contact (:data:`WORST_RULE`); None without one."""
    if failures.empty or "max_risk" not in failures:
        return None
    return failures.loc[failures["max_risk"].astype(float).idxmax()]


def testers_found(results: Results) -> pd.DataFrame:
    """Which tester found what: one column per tester (in tester order), one row each for its
    unsafe failures, the distinct classes it found, its first failure's episode, and then one
    row per class found by any tester, with the episode at which the tester first found it
    (its index in the run, the earliest over cases and seeds; blank: never)."""
    runs, failures = results.runs, results.failures
    testers = list(dict.fromkeys(runs["tester"]))
    discovery = tables.class_discovery(failures)
    named = discovery[discovery["class"] != OTHER]
    order = list(dict.fromkeys(named.sort_values("episode", kind="stable")["class"]))
    rows: dict[str, list[object]] = {"unsafe failures": [], "classes found": []}
    rows["first failure (episode)"] = []
    for name in order:
        rows[name] = []
    for tester in testers:
        own_runs = runs[runs["tester"] == tester]
        own = named[named["tester"] == tester]
        first = discovery[discovery["tester"] == tester]["episode"]
        rows["unsafe failures"].append(int(own_runs["failures"].sum()))
        rows["classes found"].append(int(own["class"].nunique()))
        rows["first failure (episode)"].append(int(first.min()) if len(first) else "")
        earliest = own.groupby("class")["episode"].min()
        for name in order:
            rows[name].append(int(earliest[name]) if name in earliest else "")
    table = pd.DataFrame.from_dict(rows, orient="index", columns=testers)
    return table.rename_axis("found").reset_index()


ARMS_FILE = Path("tester") / "arms.csv"
"""Where a portfolio run records which arm played each episode."""


def arms_found(results: Results) -> pd.DataFrame:
    """For every run that recorded which arm of its portfolio played each episode
    (``tester/arms.csv``, read as data): per class it found, the episode of its first failure
    of that class and the arm that played it. Empty when no run did; a run whose file does not
    read or does not cover its failures shows its arm as ``unknown``."""
    columns = ["scenario", "field", "seed", "tester", "class", "episode", "arm"]
    failures = results.failures
    rows = []
    for run_id, directory in zip(results.runs["run_id"], results.runs["directory"], strict=True):
        path = Path(directory) / ARMS_FILE
        if not path.is_file():
            continue
        arms = episode_arms(path)
        own = failures[(failures["run_id"] == run_id) & (failures["class"] != OTHER)]
        first = own.sort_values("episode", kind="stable").drop_duplicates("class")
        for failure in first.to_dict("records"):
            arm = arms.get(int(failure["episode"]), "unknown")
            rows.append([*(failure[key] for key in columns[:-1]), arm])
    return pd.DataFrame(rows, columns=columns)


def episode_arms(path: Path) -> dict[int, str]:
    """Episode -> arm from a run's ``arms.csv``; empty if it does not read as one."""
    try:
        table = pd.read_csv(path, dtype={"arm": str})
        return {int(e): str(a) for e, a in zip(table["episode"], table["arm"], strict=True)}
    except (OSError, ValueError, KeyError, TypeError, pd.errors.ParserError):
        return {}


def regression_commands(
    directory: Path, plugins: Mapping[str, Sequence[str]] | None = None
) -> list[str]:
    """The commands that turn a campaign's failures into regression cases and re-run them.

    ``plugins``: per option (``--controller``, ``--safety-layer``) the plug-ins the runs name
    (code in results, which ``regress`` imports only when told to). The ``regress`` command
    has the option of each with a place for the user's own import path: never an import path
    the results name, nor a blanket ``--trust-plugins``.
    """
    cases = directory / "cases"
    named = "".join(
        f" {option} package.module:Class" for option, paths in (plugins or {}).items() if paths
    )
    return [
        f"hazardhunt export {shlex.quote(str(directory))} --out {shlex.quote(str(cases))}",
        f"hazardhunt regress {shlex.quote(str(cases))}{named}",
    ]
