"""Write plain data (dicts, lists, strings, numbers, booleans) as TOML that reads back equal.

Floats are written with ``repr``, the shortest text that parses back to the same double, so a
recorded action sequence replays bit for bit after a round trip through a file.
"""

from __future__ import annotations

import json
import math
import re
from typing import Any

_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def dumps(data: dict[str, Any], header: str = "") -> str:
    """``data`` as a TOML document, after ``header`` (comment lines, written as given)."""
    lines = [header.rstrip("\n")] if header else []
    _table(data, [], lines)
    return "\n".join(lines).strip("\n") + "\n"


def _table(data: dict[str, Any], path: list[str], lines: list[str]) -> None:
    tables: dict[str, dict[str, Any] | list[dict[str, Any]]] = {}
    for key, value in data.items():
        if (isinstance(value, dict) and value and not _is_inline(value)) or _is_table_array(value):
            tables[key] = value
        elif _is_long_rows(value):
            rows = ",\n".join(f"    {_value(row)}" for row in value)
            lines.append(f"{_key(key)} = [\n{rows},\n]")
        else:
            lines.append(f"{_key(key)} = {_value(value)}")
    for key, value in tables.items():
        if isinstance(value, dict):
            lines += ["", f"[{'.'.join(_key(k) for k in [*path, key])}]"]
            _table(value, [*path, key], lines)
        else:
            for item in value:
                lines += ["", f"[[{'.'.join(_key(k) for k in [*path, key])}]]"]
                _table(item, [*path, key], lines)


def _is_long_rows(value: Any) -> bool:
    """A long list of lists (an action sequence) reads best one row per line."""
    return (
        isinstance(value, list)
        and len(value) > 4
        and all(isinstance(row, (list, tuple)) for row in value)
    )


def _is_table_array(value: Any) -> bool:
    return isinstance(value, list) and bool(value) and all(isinstance(v, dict) for v in value)


def _is_inline(value: dict[str, Any]) -> bool:
    """Small tables of scalars (a pose, a point) read best on one line."""
    return len(value) <= 4 and all(isinstance(v, (str, int, float, bool)) for v in value.values())


def _key(key: str) -> str:
    return key if _BARE_KEY.match(key) else json.dumps(key, ensure_ascii=False)


def _value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    if isinstance(value, dict):
        if not value:
            return "{}"
        return "{ " + ", ".join(f"{_key(k)} = {_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"cannot write {type(value).__name__} {value!r} as TOML")
