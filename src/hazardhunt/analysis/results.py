"""A run or campaign directory's results as pandas tables, one row per run, episode or failure."""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd
from pydantic import ValidationError

from hazardhunt.campaign.config import RECORDED, CampaignConfig
from hazardhunt.campaign.ledger import RunStates, campaign_run_states
from hazardhunt.campaign.plugins import PluginSpec
from hazardhunt.campaign.replay import not_finished
from hazardhunt.campaign.run import is_finished
from hazardhunt.campaign.store import REQUIREMENT_COLUMN, find_damage, left_out
from hazardhunt.errors import HazardhuntError, InputError
from hazardhunt.spec.episode import EpisodeSummary, TrajectorySample
from hazardhunt.spec.failure_classes import (
    FailureClassifier,
    MechanismClassifier,
    classify_failures,
)
from hazardhunt.sut.safety_layer import FieldShape
from hazardhunt.testers.registry import sort_testers
from hazardhunt.textfiles import format_validation_error, shortened

RUN_KEYS = ("run_id", "scenario", "field", "tester", "seed")
"""Columns that name a run in every table."""

TEXT_LIMIT = 1000
"""The most characters of a text read from the results (a class's, a tester's, a
requirement's name): longer ones are shortened (:func:`~hazardhunt.textfiles.shortened`, a
digest keeps them apart), since a received run's name of megabytes takes the figures minutes
to draw."""
WHOLE_TEXT = ("formula", "directory")
"""Columns read whole: a requirement's formula (it replays the requirement; its cost is
bounded when parsed) and where a run is."""


class ResultsError(InputError):
    """The directory holds no results that can be read."""


class RunsFailed(HazardhuntError):  # noqa: N818 - names an outcome, as the command reports it
    """No run of a campaign is complete, and some failed: there are no results to read, and
    that is not a pass (exit code 1, as the campaign's own)."""


@dataclass(frozen=True)
class Results:
    """Everything the finished runs of a run or campaign directory recorded."""

    directory: Path
    runs: pd.DataFrame
    """One row per finished run: its summary and its ``directory``."""
    episodes: pd.DataFrame
    """One row per episode (``episodes.parquet``), with the run's keys."""
    failures: pd.DataFrame
    """One row per failure (``failures.parquet``), with the run's keys."""
    loitering: pd.DataFrame
    """One row per episode flagged as loitering (``loitering.parquet``), with the run's keys."""
    violations: pd.DataFrame = field(default_factory=lambda: pd.DataFrame(columns=list(RUN_KEYS)))
    """One row per requirement an episode violated (``violations.parquet``), with the run's
    keys; empty for runs without requirements beyond the contact rule."""
    unfinished: list[str] = field(default_factory=list)
    """Run ids of the campaign that have not run yet or are running (they are left out of every
    table)."""
    failed: dict[str, str] = field(default_factory=dict)
    """Run ids of the campaign that failed, with the error its ledger (``summary.json``)
    records: a run that tested nothing (its episodes ended in ``sut_error``), or that raised or
    could not write its results. Nothing of them was kept, so they are in no table."""
    damaged: dict[str, str] = field(default_factory=dict)
    """Run ids of the campaign whose files do not match the checksums they recorded (or do not
    read back), with what is wrong; they are left out of every table."""
    ledger_problems: list[str] = field(default_factory=list)
    """Why a campaign's ledger (``summary.json``) does not read, per campaign whose does not:
    its runs that failed are then among ``unfinished``."""
    classifier: FailureClassifier | None = MechanismClassifier()
    """The taxonomy of the ``class`` column: the classifier that classified the failures anew,
    else the built-in one if every run recorded it, else None (runs classified by a plug-in
    that was not named again: their recorded classes stand, read as data)."""

    def classes_for(self, field_setting: str, scenario: str = "") -> tuple[str, ...] | None:
        """The classes a failure can have under a field setting (of ``scenario`` when it
        defines its own fields), ``other`` last; None without a known ``classifier``."""
        if self.classifier is None:
            return None
        return self.classifier.classes_for(self.field_shape(field_setting, scenario))

    def field_shape(self, field_setting: str, scenario: str = "") -> FieldShape:
        """The shape of a field setting, as the runs recorded it (of ``scenario``'s runs
        when given)."""
        runs = self.runs[self.runs["field"] == field_setting]
        if scenario:
            runs = runs[runs["scenario"] == scenario]
        if runs.empty:
            raise ResultsError(f"{self.directory}: no run used the field {field_setting!r}")
        return FieldShape(**runs.iloc[0]["field_shape"])

    def run_directory(self, run_id: str) -> Path:
        """Where a run's files are."""
        return Path(self.runs.set_index("run_id").at[run_id, "directory"])


def load_results(directory: Path, classifier: FailureClassifier | None = None) -> Results:
    """Read a run directory or a campaign directory (its finished runs); see
    :func:`load_results_of`."""
    return load_results_of([directory], classifier)


def load_results_of(
    directories: Sequence[Path], classifier: FailureClassifier | None = None
) -> Results:
    """Read run and campaign directories (their finished runs) as one set of results, named
    after the first.

    Nothing that the results name is imported: a failure classifier the runs recorded by
    import path is not loaded; their recorded classes are read instead.

    Args:
        directories: Run or campaign directories (at least one).
        classifier: Classify every failure anew from its stored trajectory with this
            classifier (None: keep the classes recorded with the runs).

    Raises:
        ResultsError: When a directory is neither, or nothing in one is complete, or it is a
            run whose files are damaged. A campaign's damaged runs are left out and listed in
            ``damaged``, its failed runs in ``failed``.
        RunsFailed: When nothing in a campaign directory is complete and some of its runs
            failed.
    """
    directory = directories[0]
    run_directories: list[Path] = []
    unfinished: list[str] = []
    failed: dict[str, str] = {}
    damaged: dict[str, str] = {}
    ledger_problems: list[str] = []
    for each in directories:
        found = run_states(each)
        if not found.complete:
            raise _nothing_complete(each, found)
        run_directories += found.complete
        unfinished += found.unfinished
        failed |= found.failed
        damaged |= found.damaged
        if found.ledger_problem is not None and found.unfinished:
            ledger_problems.append(found.ledger_problem)
    summaries = [_read_json(path / "summary.json") for path in run_directories]
    configs = [_read_run_config(path / "config.json") for path in run_directories]
    runs = pd.DataFrame(summaries).drop(columns="checksums", errors="ignore")
    runs["directory"] = [str(path) for path in run_directories]
    runs["reward"] = [config.get("reward") for config in configs]
    runs["blas"] = [config.get("blas") for config in configs]  # absent before 0.2
    runs = _capped(in_tester_order(runs, ("scenario", "field"), ("seed",)))
    if "requirements" in runs:  # each requirement's counts, by its name
        runs["requirements"] = runs["requirements"].map(_capped_keys)
    tables = {
        name: _capped(_stacked(run_directories, summaries, f"{name}.parquet"))
        for name in ("episodes", "failures", "loitering", "violations")
    }
    _judge_tested_only(tables)
    taxonomy = classifier
    if classifier is None:
        plugins = [
            recorded_classifier(config, path / "config.json")
            for config, path in zip(configs, run_directories, strict=True)
        ]
        taxonomy = MechanismClassifier() if all(p is None for p in plugins) else None
    else:
        tables["failures"] = _reclassified(tables["failures"], runs, classifier)
    return Results(
        directory,
        runs,
        unfinished=unfinished,
        failed=failed,
        damaged=damaged,
        ledger_problems=ledger_problems,
        classifier=taxonomy,
        **tables,
    )


def _reclassified(
    failures: pd.DataFrame, runs: pd.DataFrame, classifier: FailureClassifier
) -> pd.DataFrame:
    """``failures`` with its ``class`` column computed from the stored trajectories."""
    relabelled = failures.copy()
    directories = runs.set_index("run_id")["directory"]
    for run_id, group in failures.groupby("run_id", sort=False):
        directory = Path(directories[run_id])
        if "trajectories" in left_out(directory):
            raise ResultsError(
                f"{directory}: a copy without the failures' trajectories, which classifying "
                "anew needs; use the original results"
            )
        stored = pd.read_parquet(directory / "trajectories")
        trajectories = {
            int(episode): [TrajectorySample.from_row(row) for row in samples.to_dict("records")]
            for episode, samples in stored.sort_values("time").groupby("episode")
        }
        summaries = {
            int(row["episode"]): EpisodeSummary.from_row(row.to_dict())
            for _, row in group.iterrows()
        }
        field = FieldShape(**_read_json(directory / "summary.json")["field_shape"])
        classes = classify_failures(
            {episode: trajectories[episode] for episode in summaries}, summaries, field, classifier
        )
        relabelled.loc[group.index, "class"] = [classes[i] for i in summaries]
    return relabelled


def recorded_classifier(config: dict[str, Any], path: Path) -> PluginSpec | None:
    """The failure classifier plug-in a run recorded in ``config``, its ``config.json`` at
    ``path``, as data (None: the built-in classifier). Nothing is imported."""
    spec = config.get("run", {}).get("classifier")
    try:
        return None if spec is None else PluginSpec.model_validate(spec)
    except ValidationError as error:
        raise ResultsError(f"{path}: run.{format_validation_error(error)}") from None


def run_states(directory: Path) -> RunStates:
    """The runs of a run or campaign directory, by how they stand.

    Raises:
        ResultsError: When ``directory`` is neither, or is a run that is not complete.
    """
    if not directory.is_dir():
        raise ResultsError(f"{directory}: no such directory")
    if (directory / "campaign.json").is_file():
        return _campaign_runs(directory)
    if not (directory / "config.json").is_file():
        raise ResultsError(
            f"{directory}: not a run or campaign directory (no config.json or campaign.json)"
        )
    if not is_finished(directory):
        raise ResultsError(not_finished(directory))
    damage = find_damage(directory)
    if damage is not None:
        raise ResultsError(f"{directory}: the run is damaged ({damage}); run it again")
    return RunStates([directory], [], {}, {})


def _campaign_runs(directory: Path) -> RunStates:
    stored = directory / "campaign.json"
    try:  # what ran is read from the runs' files, its scenarios too: their files are not needed
        config = CampaignConfig.model_validate(_read_json(stored), context=RECORDED)
    except ValidationError as error:
        problem = format_validation_error(error)
        raise ResultsError(f"{stored}: not a campaign configuration: {problem}") from None
    return campaign_run_states(directory, config)


def _nothing_complete(directory: Path, found: RunStates) -> HazardhuntError:
    """Why no run of a campaign can be read: ``RunsFailed`` when some failed, else a
    ``ResultsError``."""
    if not found.failed and not found.damaged:
        if found.ledger_problem is not None:
            return ResultsError(
                f"{directory}: no run of the campaign has finished, and its ledger cannot tell "
                f"which failed: {found.ledger_problem}; running the campaign again writes it anew"
            )
        return ResultsError(f"{directory}: no run of the campaign has finished yet")
    reasons = [f"run {run_id} failed ({error})" for run_id, error in found.failed.items()]
    reasons += [f"{run_id} is damaged ({damage})" for run_id, damage in found.damaged.items()]
    message = f"{directory}: no run of the campaign is complete: {'; '.join(reasons)}"
    return RunsFailed(message) if found.failed else ResultsError(message)


def _stacked(
    run_directories: list[Path], summaries: list[dict[str, Any]], name: str
) -> pd.DataFrame:
    """One table of every run, with the run's keys as the first columns."""
    parts = []
    for path, summary in zip(run_directories, summaries, strict=True):
        table_path = path / name
        if not table_path.is_file():
            continue  # a run recorded before the table existed
        table = pd.read_parquet(table_path)
        for position, key in enumerate(RUN_KEYS):
            if key in table.columns:
                table = table.drop(columns=key)
            table.insert(position, key, summary[key])
        parts.append(table)
    if not parts:
        return pd.DataFrame(columns=list(RUN_KEYS))
    return pd.concat(parts, ignore_index=True)


def _capped(table: pd.DataFrame) -> pd.DataFrame:
    """``table`` with each text longer than :data:`TEXT_LIMIT` shortened, in its cells and in
    the names of its requirements' columns, but for :data:`WHOLE_TEXT`."""
    table = table.rename(
        columns={
            column: REQUIREMENT_COLUMN + shortened(column[len(REQUIREMENT_COLUMN) :], TEXT_LIMIT)
            for column in table.columns
            if str(column).startswith(REQUIREMENT_COLUMN)
        }
    )
    for column in table.columns:
        values = table[column]
        if column in WHOLE_TEXT or not (
            pd.api.types.is_object_dtype(values) or pd.api.types.is_string_dtype(values)
        ):
            continue
        if any(isinstance(value, str) and len(value) > TEXT_LIMIT for value in values):
            table[column] = values.map(
                lambda value: shortened(value, TEXT_LIMIT) if isinstance(value, str) else value
            )
    return table


def _capped_keys(counts: Any) -> Any:
    """A table of ``counts`` by name with its names shortened as :func:`_capped` does."""
    if not isinstance(counts, dict):
        return counts
    return {shortened(str(name), TEXT_LIMIT): count for name, count in counts.items()}


def _judge_tested_only(tables: dict[str, pd.DataFrame]) -> None:
    """Take the requirements' verdicts on episodes that ended in a SUT error out of ``tables``
    (their violations, their robustness): such an episode tested nothing, and is neither a
    violation nor a pass. Runs before 0.2.0 recorded verdicts on them."""
    episodes, violations = tables["episodes"], tables["violations"]
    if "outcome" in violations:
        tables["violations"] = violations[violations["outcome"] != "sut_error"].reset_index(
            drop=True
        )
    judged = [c for c in episodes.columns if str(c).startswith(REQUIREMENT_COLUMN)]
    if judged and "outcome" in episodes:
        episodes.loc[episodes["outcome"] == "sut_error", judged] = float("nan")


def _read_run_config(path: Path) -> dict[str, Any]:
    """A run's ``config.json``, read as data: a JSON object with a ``run`` table."""
    config = _read_json(path)
    if not isinstance(config.get("run"), dict):
        raise ResultsError(f"{path}: not a run's configuration (no run table)")
    return config


def _read_json(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as error:  # not JSON, or not UTF-8
        raise ResultsError(f"{path}: cannot be read ({error})") from error
    if not isinstance(data, dict):
        raise ResultsError(f"{path}: expected a JSON object")
    return data


def in_tester_order(
    table: pd.DataFrame, keys: Sequence[str] = (), then: Sequence[str] = ()
) -> pd.DataFrame:
    """``table`` sorted by ``keys``, then by tester, then by ``then``: registered testers in the
    registry's order, the others (plug-ins) after them by name."""
    rank = {name: i for i, name in enumerate(sort_testers(table["tester"]))}

    def sort_key(column: pd.Series) -> pd.Series:
        return column.map(rank) if column.name == "tester" else column

    ordered = table.sort_values([*keys, "tester", *then], key=sort_key, kind="stable")
    return ordered.reset_index(drop=True)
