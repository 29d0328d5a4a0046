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
TRAJECTORY_NUMBERS = (
    "time",
    "human_x",
    "human_y",
    "human_heading",
    "robot_x",
    "robot_y",
    "robot_heading",
    "robot_speed",
    "robot_yaw_rate",
    "clearance",
)
"""The columns of a run's trajectories that the report draws and clusters failures on."""
TRAJECTORY_LIMIT = 1e6
"""The largest size of a trajectory's value (m, rad, m/s, rad/s or s): no floor, robot or
episode comes near it, and a position beyond it no figure can draw."""


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
    return _trajectory_problem(directory)


def _trajectory_problem(directory: Path) -> str | None:
    """What is wrong with the numbers of the run's stored trajectories, if anything."""
    for path in sorted((directory / "trajectories").glob("*.parquet")):
        name = path.relative_to(directory).as_posix()
        try:
            present = set(pq.read_schema(path).names)
            columns = [column for column in TRAJECTORY_NUMBERS if column in present]
            table = pq.read_table(path, columns=columns)
        except (OSError, ValueError) as error:
            return f"{name} cannot be read ({error})"
        if table.num_rows == 0:
            continue
        for column in columns:
            values = table[column]
            if not (pa.types.is_integer(values.type) or pa.types.is_floating(values.type)):
                return f"{name}: {column} holds a value that is not a number"
            sizes = pc.abs(pc.cast(values, pa.float64()))
            within = pc.less_equal(sizes, TRAJECTORY_LIMIT)  # False for NaN, null for null
            if values.null_count or not pc.all(within).as_py():
                return (
                    f"{name}: {column} holds a value that is not a finite number of at most "
                    f"{TRAJECTORY_LIMIT:g} in size"
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
    counts = pc.value_counts(episodes)
    repeated = pc.filter(counts, pc.greater(counts.field("counts"), 1))
    if len(repeated):
        first = repeated[0].as_py()
        return f"{name}: episode {first['values']} has {first['counts']} rows, not one"
    return None
