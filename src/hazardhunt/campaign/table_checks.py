"""What makes a run's tables unusable although they read back: a run received from someone
else, whose checksums match what they made (:func:`hazardhunt.campaign.store.find_damage`
reports it as damage, so that no command reads such a run as results)."""

from __future__ import annotations

from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

REQUIRED_COLUMNS = {
    "episodes.parquet": ("episode", "outcome"),
    "failures.parquet": ("episode", "outcome", "sim_time", "contact_face", "max_risk", "class"),
}
"""Columns every run's tables have had, which reading results relies on."""
FINITE_COLUMNS = {"failures.parquet": ("sim_time", "max_risk")}
"""Columns whose every value is a finite number."""
TEXT_COLUMNS = {"episodes.parquet": ("outcome",), "failures.parquet": ("outcome", "class")}
"""Columns whose every value is text."""


def table_problem(directory: Path) -> str | None:
    """What makes the tables of the run in ``directory`` unusable although they read back: a
    missing column, a number that is not one where the results need one, a value that is not
    text where they need text, an episode that is not a whole number from 0, or a failure of an
    episode the run did not play."""
    tables: dict[str, pa.Table] = {}
    for name, columns in REQUIRED_COLUMNS.items():
        path = directory / name
        if not path.is_file():
            continue  # reported by the checksums, or a run recorded before the table existed
        try:
            present = set(pq.read_schema(path).names)
            missing = [column for column in columns if column not in present]
            if missing:
                return f"{name} lacks the column {', '.join(missing)}"
            checked = {"episode", *FINITE_COLUMNS.get(name, ()), *TEXT_COLUMNS.get(name, ())}
            table = tables[name] = pq.read_table(path, columns=sorted(checked))
        except (OSError, ValueError) as error:  # pyarrow's errors are ValueErrors too
            return f"{name} cannot be read ({error})"
        if (problem := _values_problem(name, table)) is not None:
            return problem
    if len(tables) == len(REQUIRED_COLUMNS):
        played = tables["episodes.parquet"]["episode"]
        failed = tables["failures.parquet"]["episode"]
        unplayed = pc.filter(failed, pc.invert(pc.is_in(failed, value_set=played)))
        if len(unplayed):
            return (
                f"failures.parquet: episode {unplayed[0].as_py()} is not an episode of "
                "episodes.parquet"
            )
    return None


def _values_problem(name: str, table: pa.Table) -> str | None:
    """What is wrong with the values of ``table``, the table ``name`` of a run, if anything."""
    if table.num_rows == 0:  # a run without failures: its columns may have no type
        return None
    for column in FINITE_COLUMNS.get(name, ()):
        values = table[column]
        numbers = pa.types.is_integer(values.type) or pa.types.is_floating(values.type)
        if not numbers or values.null_count or not pc.all(pc.is_finite(values)).as_py():
            return f"{name}: {column} holds a value that is not a finite number"
    for column in TEXT_COLUMNS.get(name, ()):
        values = table[column]
        text = pa.types.is_string(values.type) or pa.types.is_large_string(values.type)
        if not text or values.null_count:
            return f"{name}: {column} holds a value that is not text"
    episodes = table["episode"]
    if (
        not pa.types.is_integer(episodes.type)
        or episodes.null_count
        or pc.min(episodes).as_py() < 0
    ):
        return f"{name}: episode holds a value that is not a whole number from 0"
    return None
