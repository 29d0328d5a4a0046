"""A run's results on disk: Parquet tables that pandas reads, JSON for configuration and summary.

Layout of a run directory::

    config.json          the resolved configuration, package version, seeds
    scenario.json        the scenario played, its map inlined (its file may change later)
    episodes.parquet     one row per episode (SPEC 7)
    failures.parquet     one row per failure: what replays it (scenario, field, seed, actions)
                         and its class (SPEC 6)
    loitering.parquet    one row per episode flagged as loitering (reward hacking), with its actions
    violations.parquet   with requirements beyond the contact rule: one row per requirement an
                         episode violated, with what replays it and the requirement's formula
    trajectories/        part-*.parquet: every failure's trajectory at 0.2 s, keyed by episode
    tester/              what the tester learned (the PPO model)
    summary.json         written last: its presence marks the run finished; it holds the
                         SHA-256 of every other file, so that a damaged run is told apart

A copy made by ``hazardhunt copy`` (:func:`copy_run`) may leave the trajectories out: its
``summary.json`` then lists ``trajectories`` under ``left_out``, and their absence is not
damage.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import shutil
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pandas as pd
import pyarrow.parquet as pq

from hazardhunt.campaign.records import (
    FirstError,
    RequirementCount,
    requirement_count,
    summary_problem,
)
from hazardhunt.campaign.table_checks import table_problem
from hazardhunt.file_writes import file_written
from hazardhunt.spec.episode import (
    SUMMARY_COLUMNS,
    TIMING_COLUMNS,
    TRAJECTORY_COLUMNS,
    EpisodeSummary,
    TrajectorySample,
)
from hazardhunt.spec.failure_classes import OTHER, FailureClassifier
from hazardhunt.spec.requirements import Requirement, Verdict
from hazardhunt.spec.reward_hacking import LoiteringRule
from hazardhunt.sut.guard import is_plugin_fault
from hazardhunt.sut.safety_layer import FieldShape
from hazardhunt.testers.base import EpisodeRecord

EPISODE_COLUMNS = ("episode", *SUMMARY_COLUMNS, *TIMING_COLUMNS, "loitering")
"""Columns of ``episodes.parquet``: the episode's index, its summary, its wall-clock timing
and whether it loitered (reward hacking)."""

REQUIREMENT_COLUMN = "requirement:"
"""The prefix of ``episodes.parquet``'s columns that hold each requirement's robustness
(``requirement:separation``), when the run has requirements beyond the contact rule."""

FAILURE_SUMMARY_COLUMNS = ("outcome", "sim_time", "decision_steps", "contact_face", "max_risk")
"""Columns of ``failures.parquet`` taken from the episode summary (besides the replay keys)."""

LOITERING_COLUMNS = ("outcome", "sim_time", "decision_steps", "emergency_stops", "time_in_field")
"""Columns of ``loitering.parquet`` taken from the episode summary (besides the replay keys)."""

VIOLATION_COLUMNS = (
    "requirement",
    "formula",
    "robustness",
    "signals",
    "time",
    "outcome",
    "sim_time",
)
"""Columns of ``violations.parquet`` besides the episode, the replay keys and the actions: the
requirement, its formula (empty for a requirement that is not a formula), the robustness, the
signals that decided the violation (``clearance+robot_speed``), its first instant, in s, and
the episode's outcome and length."""

LEFT_OUT_KEY = "left_out"
"""The key of a run's ``summary.json`` that lists the folders a copy left out."""

LEAVABLE = ("trajectories",)
"""The folders of a run a copy may leave out (the report and export work without them)."""

TRAJECTORY_FLUSH = 200
"""Failures whose trajectories are buffered before a part file is written."""


def write_json_atomic(path: Path, data: Any) -> None:
    """Write JSON so that a reader sees either the old file or the whole new one."""
    write_bytes_atomic(path, json.dumps(data, indent=2, default=str).encode())


def write_bytes_atomic(path: Path, payload: bytes) -> None:
    """Write a file via a temporary sibling and an atomic rename."""
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with file_written(Path(temporary), named=path):  # a full disk: an error naming path
            os.chmod(temporary, 0o666 & ~_umask())  # mkstemp makes it private; keep the umask's
            with os.fdopen(handle, "wb") as stream:
                stream.write(payload)
                stream.flush()
                os.fsync(stream.fileno())
            os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def file_checksums(directory: Path) -> dict[str, str]:
    """The SHA-256 of every file in a run directory but ``summary.json``, by path relative to
    the directory (what ``summary.json`` records as ``checksums``)."""
    return {
        path.relative_to(directory).as_posix(): _sha256(path)
        for path in sorted(directory.rglob("*"))
        if path.is_file() and path != directory / "summary.json"
    }


def find_damage(directory: Path) -> str | None:
    """What is wrong with the files of a finished run directory; None if they are as written.

    A run whose ``summary.json`` records checksums must match them; a run recorded before
    checksums were must have tables that read back. A run holds no symbolic link: one found is
    damage, and nothing reads or copies through it.
    """
    link = symbolic_link_in(directory)
    if link is not None:
        return f"{link} is a symbolic link (a run holds none; it is not followed)"
    try:
        summary = json.loads((directory / "summary.json").read_bytes())
    except (OSError, ValueError) as error:
        return f"summary.json cannot be read ({error})"
    if not isinstance(summary, dict):
        return "summary.json is not a JSON object"
    if (problem := summary_problem(summary)) is not None:
        return f"summary.json: {problem}"
    recorded = summary.get("checksums")
    if recorded is None:
        return _unreadable_file(directory) or table_problem(directory)
    if not isinstance(recorded, dict):
        return "summary.json: checksums is not a table of files"
    left_out = summary.get(LEFT_OUT_KEY, [])
    for name, digest in recorded.items():
        if Path(name).is_absolute() or ".." in Path(name).parts:
            return f"summary.json: checksums name {name!r}, outside the run"
        path = directory / name
        if name.partition("/")[0] in left_out and not path.exists():
            continue
        if not path.is_file():
            return f"{name} is missing"
        if _sha256(path) != digest:
            return f"{name} does not match its checksum (changed or truncated)"
    return table_problem(directory)


def symbolic_link_in(directory: Path) -> str | None:
    """The first symbolic link inside ``directory`` (relative to it), not following any."""
    for root, folders, files in os.walk(directory, followlinks=False):
        for name in sorted([*folders, *files]):
            path = Path(root) / name
            if path.is_symlink():
                return str(path.relative_to(directory))
    return None


def _unreadable_file(directory: Path) -> str | None:
    """The first file of a run (recorded without checksums) that does not read back."""
    try:
        json.loads((directory / "config.json").read_bytes())
    except (OSError, ValueError) as error:
        return f"config.json cannot be read ({error})"
    tables = [directory / f"{name}.parquet" for name in ("episodes", "failures", "loitering")]
    tables += sorted((directory / "trajectories").glob("*.parquet"))
    for path in tables:
        if not path.exists() and path.name != "episodes.parquet":
            continue  # a run recorded before the table existed
        try:
            pq.read_table(path)
        except (OSError, ValueError) as error:  # pyarrow's ArrowInvalid is a ValueError
            return f"{path.relative_to(directory)} cannot be read ({error})"
    return None


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


class RunStore:
    """Collects a run's episodes and failures and writes them as Parquet."""

    def __init__(
        self,
        directory: Path,
        replay_keys: dict[str, Any],
        classifier: FailureClassifier,
        field: FieldShape,
        loitering: LoiteringRule = LoiteringRule(),
        requirements: Sequence[Requirement] = (),
    ) -> None:
        """Args:
        directory: The run directory (exists).
        replay_keys: Columns every failure row carries to replay it (scenario, field, seed,
            decision period).
        classifier: Names each failure's class.
        field: The protective field, for the classifier.
        loitering: Flags episodes whose actions are kept to show reward hacking.
        requirements: The run's requirements beyond the contact rule: their violations are
            kept with what replays them (``violations.parquet``).
        """
        self.formulas = {r.name: str(getattr(r, "formula", "")) for r in requirements}
        self.violations: list[dict[str, Any]] = []
        self.directory = directory
        self.replay_keys = replay_keys
        self.classifier = classifier
        self.field = field
        self.loitering_rule = loitering
        self.loitering: list[dict[str, Any]] = []
        self.episodes: list[dict[str, Any]] = []
        self.failures: list[dict[str, Any]] = []
        self.sut_error_count = 0
        """Episodes stored so far that ended in ``sut_error``."""
        self.first_sut_error: FirstError | None = None
        self.classifier_errors = 0
        """Failures the classifier raised on or gave no class name for (recorded as ``other``)."""
        self.first_classifier_error: FirstError | None = None
        """The first of them: its ``episode`` and ``error`` (the plug-in and what it raised)."""
        self.requirements = {name: requirement_count() for name in self.formulas}
        """Each requirement's episodes judged and violations so far (the run's requirements
        beyond the contact rule)."""
        self._trajectory_rows: list[dict[str, Any]] = []
        self._buffered_failures = 0
        self._parts = 0
        (directory / "trajectories").mkdir(exist_ok=True)

    def add(self, record: EpisodeRecord) -> None:
        """Store one finished episode."""
        result, episode = record.result, record.episode
        summary = result.summary
        row = {"episode": episode, **summary.as_row(), **dataclasses.asdict(result.timing)}
        row["loitering"] = self.loitering_rule.matches(summary)
        for name, verdict in result.verdicts.items():
            row[REQUIREMENT_COLUMN + name] = verdict.robustness
            self._count(name, episode, verdict)
            if verdict.violated:
                self.violations.append(
                    {
                        "episode": episode,
                        **self.replay_keys,
                        "requirement": name,
                        "formula": self.formulas.get(name, ""),
                        "robustness": verdict.robustness,
                        "signals": verdict.decided_by,
                        "time": verdict.time,
                        "outcome": summary.outcome,
                        "sim_time": summary.sim_time,
                        "actions": result.actions.tolist(),
                    }
                )
        self.episodes.append(row)
        if summary.outcome == "sut_error":
            self.sut_error_count += 1
            if self.first_sut_error is None:
                self.first_sut_error = {"episode": episode, "error": sut_error_of(summary)}
        replay = {"episode": episode, **self.replay_keys}
        if row["loitering"]:
            self.loitering.append(
                {
                    **replay,
                    **{key: row[key] for key in LOITERING_COLUMNS},
                    "actions": result.actions.tolist(),
                }
            )
        if summary.outcome != "failure":
            return
        trajectory = result.trajectory or ()
        contact = trajectory[-1] if trajectory else None
        self.failures.append(
            {
                **replay,
                **{key: row[key] for key in FAILURE_SUMMARY_COLUMNS},
                "class": self._classify(episode, trajectory, summary),
                "contact_x": None if contact is None else contact.human_x,
                "contact_y": None if contact is None else contact.human_y,
                "actions": result.actions.tolist(),
            }
        )
        self._trajectory_rows.extend({"episode": episode} | s.as_row() for s in trajectory)
        self._buffered_failures += 1
        if self._buffered_failures >= TRAJECTORY_FLUSH:
            self._flush_trajectories()

    def _classify(
        self, episode: int, trajectory: Sequence[TrajectorySample], summary: EpisodeSummary
    ) -> str:
        """The failure's class; ``other`` (counted, the first error kept) when the classifier
        raises or returns anything but a class name: a plug-in's fault costs the failure its
        class, not the run."""
        try:
            name = self.classifier.classify(trajectory, summary, self.field)
            if not isinstance(name, str):
                raise TypeError(f"classify() returned {name!r}, not a class name (str)")
        except BaseException as error:  # a plug-in may raise anything
            if not is_plugin_fault(error):
                raise
            self.classifier_errors += 1
            if self.first_classifier_error is None:
                what = f"{type(error).__name__}: {error}"
                self.first_classifier_error = {"episode": episode, "error": what}
            return OTHER
        return name

    @property
    def failure_count(self) -> int:
        """Failures stored so far."""
        return len(self.failures)

    @property
    def classes(self) -> list[str]:
        """The distinct failure classes stored so far, in the classifier's order."""
        found = {row["class"] for row in self.failures}
        return [name for name in self.classifier.classes_for(self.field) if name in found]

    def _count(self, name: str, episode: int, verdict: Verdict) -> None:
        count = self.requirements.setdefault(name, requirement_count())
        count["judged"] += 1
        lowest = count["min_robustness"]
        robustness = verdict.robustness
        count["min_robustness"] = robustness if lowest is None else min(lowest, robustness)
        if verdict.violated:
            count["violations"] += 1
            if count["first_violation_episode"] is None:
                count["first_violation_episode"] = episode
            signals = verdict.decided_by
            count["decided_by"][signals] = count["decided_by"].get(signals, 0) + 1

    def requirement_summary(self) -> dict[str, RequirementCount]:
        """Each requirement's episodes judged (an episode that ended as ``sut_error`` is not:
        it tested nothing), violations, first violating episode and lowest robustness."""
        return {
            name: RequirementCount(**{**count, "decided_by": dict(count["decided_by"])})
            for name, count in self.requirements.items()
        }

    def close(self) -> None:
        """Write the tables."""
        self._flush_trajectories()
        judged = [REQUIREMENT_COLUMN + name for name in self.requirements]
        episodes = pd.DataFrame(self.episodes, columns=[*EPISODE_COLUMNS, *judged])
        _write_table(episodes, self.directory / "episodes.parquet")
        failure_columns = [
            "episode",
            *self.replay_keys,
            *FAILURE_SUMMARY_COLUMNS,
            "class",
            "contact_x",
            "contact_y",
            "actions",
        ]
        failures = pd.DataFrame(self.failures, columns=failure_columns)
        _write_table(failures, self.directory / "failures.parquet")
        loitering = pd.DataFrame(
            self.loitering,
            columns=["episode", *self.replay_keys, *LOITERING_COLUMNS, "actions"],
        )
        _write_table(loitering, self.directory / "loitering.parquet")
        if self.formulas:
            violations = pd.DataFrame(
                self.violations,
                columns=["episode", *self.replay_keys, *VIOLATION_COLUMNS, "actions"],
            )
            _write_table(violations, self.directory / "violations.parquet")

    def _flush_trajectories(self) -> None:
        if not self._trajectory_rows:
            return
        part = self.directory / "trajectories" / f"part-{self._parts:05d}.parquet"
        columns = ["episode", *TRAJECTORY_COLUMNS]
        _write_table(pd.DataFrame(self._trajectory_rows, columns=columns), part)
        self._parts += 1
        self._trajectory_rows = []
        self._buffered_failures = 0


def _write_table(table: pd.DataFrame, path: Path) -> None:
    """Write a table of a run (in its ``.partial`` directory): on a full disk, an error that
    names the file, and no half-written file left."""
    with file_written(path):
        table.to_parquet(path, index=False)


def read_trajectory(run_directory: Path, episode: int) -> list[TrajectorySample]:
    """The stored trajectory of one failure, samples in time order."""
    table = pd.read_parquet(run_directory / "trajectories", filters=[("episode", "==", episode)])
    table = table.sort_values("time")
    return [TrajectorySample.from_row(row) for row in table.to_dict("records")]


def left_out(directory: Path) -> list[str]:
    """The folders the copy of a finished run left out (empty for a run as it was recorded)."""
    summary = json.loads((directory / "summary.json").read_bytes())
    return [str(name) for name in summary.get(LEFT_OUT_KEY, [])]


def copy_run(source: Path, destination: Path, leave_out: tuple[str, ...] = ()) -> None:
    """Copy the finished, undamaged run ``source`` to ``destination`` (which must not exist),
    without the folders ``leave_out`` (of :data:`LEAVABLE`), atomically: a hidden sibling is
    renamed into place once complete. Its ``summary.json`` keeps the checksums of every file
    and lists what was left out.

    Raises:
        ValueError: ``leave_out`` names a folder outside :data:`LEAVABLE`, or ``source`` holds
            a symbolic link.
    """
    unknown = set(leave_out) - set(LEAVABLE)
    if unknown:
        raise ValueError(f"only {', '.join(LEAVABLE)} can be left out, not {sorted(unknown)}")
    link = symbolic_link_in(source)
    if link is not None:
        raise ValueError(f"{source}: {link} is a symbolic link; a run holds none: nothing copied")
    partial = destination.with_name(f".{destination.name}.partial")
    shutil.rmtree(partial, ignore_errors=True)
    try:
        try:
            shutil.copytree(
                source,
                partial,
                ignore=shutil.ignore_patterns(*leave_out, "summary.json"),
                symlinks=True,  # never followed (there are none: checked above)
            )
        except shutil.Error as error:  # one entry per file: a full disk lists them all
            failed = error.args[0] if error.args and isinstance(error.args[0], list) else []
            first = failed[0][2] if failed else str(error)
            raise OSError(
                f"{destination}: {len(failed) or 'some'} files could not be copied; the first: "
                f"{first}"
            ) from None
        summary = json.loads((source / "summary.json").read_bytes())
        already = [str(name) for name in summary.get(LEFT_OUT_KEY, [])]
        summary[LEFT_OUT_KEY] = sorted(set(already) | set(leave_out))
        write_json_atomic(partial / "summary.json", summary)
        partial.rename(destination)
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)
        raise


def sut_error_of(summary: EpisodeSummary) -> str:
    """What ended an episode as ``sut_error``, in one line: the first error of the controller or
    of the safety layer, or the controller's failed commands in a row."""
    if summary.controller_errors:
        return f"controller: {summary.controller_errors[0]}"
    if summary.safety_layer_errors:
        return f"safety layer: {summary.safety_layer_errors[0]}"
    return f"controller: {summary.controller_failures} failed commands (brake requests)"
