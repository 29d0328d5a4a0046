"""What a campaign shows while it runs and when it ends: progress bars of the runs and of the
episodes (or, when the output is not a terminal, a line every few minutes), and the table of
failures per scenario, field and tester."""

from __future__ import annotations

import contextlib
import statistics
import time
from collections.abc import Callable
from pathlib import Path

from rich.console import Console
from rich.markup import escape
from rich.progress import Progress
from rich.table import Column, Table

from hazardhunt.campaign.config import RunConfig
from hazardhunt.campaign.ledger import Ledger, RunOutcome
from hazardhunt.campaign.records import CampaignSummary, LedgerEntry
from hazardhunt.campaign.run import LOG_INTERVAL_S


class ProgressDisplay:
    """Progress bars of the runs and of the episodes done, in complete and running runs."""

    def __init__(
        self,
        progress: Progress,
        ledger: Ledger,
        pending: list[RunConfig],
        show_episodes: bool,
        log: Callable[[str], None] | None = None,
    ) -> None:
        """Args:
        progress: Where the bars are drawn.
        ledger: The campaign's runs and how they stand.
        pending: The runs about to be executed.
        show_episodes: Whether the episodes done are counted (not with Ray).
        log: Where a line of progress goes every ``LOG_INTERVAL_S`` and at each run's end,
            for output that is not a terminal; None for none.
        """
        complete = [e for e in ledger.entries.values() if e["status"] == "complete"]
        self.progress = progress
        self.log = log
        self.logged_at = time.monotonic()
        # A slice (--runs) counts the runs it executes and those already complete, not the
        # runs it leaves pending, as the episodes do.
        self.runs_ended, self.runs_total = len(complete), len(complete) + len(pending)
        self.episodes_of_complete_runs = sum(int(e["episodes"]) for e in complete)
        self.episodes_total = self.episodes_of_complete_runs + sum(r.episodes for r in pending)
        self.in_flight: dict[str, int] = {}
        self.ended: set[str] = set()  # a run's last report may arrive after its end
        self.run_task = progress.add_task("runs", total=self.runs_total, completed=len(complete))
        self.episode_task = progress.add_task(
            "episodes", total=self.episodes_total, visible=show_episodes
        )
        self._show_episodes()

    def episodes_done(self, run_id: str, episodes_done: int) -> None:
        """A running run reports its episodes done so far."""
        if run_id not in self.ended:
            self.in_flight[run_id] = max(self.in_flight.get(run_id, 0), episodes_done)
            self._show_episodes()

    def run_restarted(self, run_id: str) -> None:
        """A run starts again from its first episode."""
        self.in_flight.pop(run_id, None)
        self._show_episodes()

    def run_ended(self, outcome: RunOutcome) -> None:
        """A run completed or raised."""
        self.ended.add(outcome.config.run_id)
        self.in_flight.pop(outcome.config.run_id, None)
        if outcome.summary is not None:
            self.episodes_of_complete_runs += int(outcome.summary["episodes"])
        else:
            self.episodes_total -= outcome.config.episodes
        self.progress.advance(self.run_task)
        self.runs_ended += 1
        self._show_episodes()
        if self.log is not None:
            how = "failed"
            if outcome.summary is not None:
                errors = outcome.summary.get("sut_errors", 0)
                how = "complete" + (f" with {errors} SUT errors" if errors else "")
            self.log(f"run {outcome.config.run_id} {how}: {self._standing()}")
            self.logged_at = time.monotonic()

    def _show_episodes(self) -> None:
        done = self.episodes_of_complete_runs + sum(self.in_flight.values())
        self.progress.update(self.episode_task, completed=done, total=self.episodes_total)
        if self.log is not None and time.monotonic() - self.logged_at >= LOG_INTERVAL_S:
            self.log(self._standing())
            self.logged_at = time.monotonic()

    def _standing(self) -> str:
        """How far the campaign is, in one line."""
        done = self.episodes_of_complete_runs + sum(self.in_flight.values())
        share = done / self.episodes_total if self.episodes_total else 1.0
        return (
            f"{self.runs_ended} of {self.runs_total} runs ended, "
            f"{done:,} of {self.episodes_total:,} episodes ({share:.0%})"
        )


def shown_scenario(scenario: str) -> str:
    """A scenario as the campaign's table shows it: a built-in by its name, a file by its path
    relative to the working directory when it lies below it, or else by its file name."""
    if not scenario.endswith(".toml"):
        return scenario
    path = Path(scenario)
    with contextlib.suppress(ValueError):
        return str(path.resolve().relative_to(Path.cwd().resolve()))
    return path.name


def print_campaign_table(console: Console, summary: CampaignSummary, out: Path) -> None:
    """Per scenario x field x tester with a run that ended (complete or failed): failures of
    the run, or over seeds their mean ± std, the SUT errors (of the runs that failed because
    they tested nothing too) and the mean wall time; then what is left to do. Groups none of
    whose runs has been run yet are counted below the table, not listed: a slice of a large
    grid shows its own rows."""
    groups: dict[tuple[str, str, str], list[LedgerEntry]] = {}
    for entry in summary["runs"]:
        key = (entry["scenario"], entry["field"], entry["tester"])
        groups.setdefault(key, []).append(entry)
    table = Table(
        Column("scenario", overflow="fold"),  # a scenario file's path, whole where it is long
        Column("field", overflow="fold"),
        Column("tester", overflow="fold"),
        "runs",
        "failures",
        "SUT errors",
        "wall time (s)",
    )
    not_started = 0
    for (scenario, field, tester), entries in groups.items():
        if all(entry["status"] == "pending" for entry in entries):
            not_started += 1
            continue
        complete = [e for e in entries if e["status"] == "complete"]
        failures = [int(e["failures"]) for e in complete]
        sut_errors = sum(_sut_errors(e) for e in entries)
        wall_times = [float(e["wall_time_s"]) for e in complete]
        table.add_row(
            escape(shown_scenario(scenario)),
            escape(field),
            escape(tester),
            f"{len(complete)}/{len(entries)}",
            _mean_std(failures),
            f"[red]{sut_errors}[/red]" if sut_errors else "0",
            f"{statistics.fmean(wall_times):.1f}" if wall_times else "-",
        )
    console.print(table)
    _print_what_is_left(console, summary, out, not_started)


def _print_what_is_left(
    console: Console, summary: CampaignSummary, out: Path, not_started: int
) -> None:
    """Below the campaign's table: the runs that failed, the totals, and what is left to do;
    ``not_started`` groups of the grid were left out of the table."""
    for entry in summary["runs"]:
        if entry["status"] == "failed":
            console.print(f"[red]failed:[/red] {entry['run_id']}: {escape(str(entry['error']))}")
    console.print(
        f"{summary['runs_complete']}/{summary['runs_total']} runs complete, "
        f"{summary['failures']} failures in {summary['episodes']} episodes; "
        f"results in [bold]{out.resolve()}[/bold] (summary.json, runs/)"
    )
    if sut_errors := sum(_sut_errors(entry) for entry in summary["runs"]):
        console.print(
            f"[red]warning: {sut_errors} episodes ended in a SUT error and tested "
            "nothing[/red] (the column SUT errors; each run's first in its summary.json or its "
            "error)"
        )
    if summary["runs_failed"]:
        console.print(
            f"[red]runs that failed: {summary['runs_failed']}[/red] (errors in summary.json); "
            "run the same command again to retry them"
        )
    if summary["runs_pending"]:
        unlisted = (
            f" (the table leaves out {not_started} scenario x field x tester "
            f"{'group' if not_started == 1 else 'groups'} none of whose runs has run)"
            if not_started
            else ""
        )
        console.print(
            f"{summary['runs_pending']} runs not run yet{unlisted}: run the campaign again "
            "(with other --runs patterns, or without) to run them"
        )


def _sut_errors(entry: LedgerEntry) -> int:
    """The episodes of a run that ended in ``sut_error``: of a complete run, and of one that
    failed because it tested nothing (0 for the other runs)."""
    return int(entry.get("sut_errors") or 0) if entry["status"] != "pending" else 0


def _mean_std(counts: list[int]) -> str:
    """One run's count as it is; the mean ± standard deviation of several."""
    if not counts:
        return "-"
    if len(counts) == 1:
        return str(counts[0])
    return f"{statistics.fmean(counts):.1f} ± {statistics.stdev(counts):.1f}"
