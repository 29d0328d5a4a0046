"""Reading TOML that anyone may have written: a file larger than any input needs is refused
before it is parsed (:func:`read_input_text`); a file nested too deeply for the parser is a
decoding error that names the problem, never a ``RecursionError``; a value the file's schema
refuses is one line in the file's own words (:func:`format_validation_error`), and no line
echoes a value without bound (:func:`cut_short`)."""

from __future__ import annotations

import difflib
import errno
import hashlib
import re
import sys
import types
import typing
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ValidationError
from pydantic.fields import FieldInfo
from pydantic_core import ErrorDetails

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

TOMLDecodeError = tomllib.TOMLDecodeError


MAX_INPUT_CHARACTERS = 1_000_000
"""The most characters hazardhunt reads from one input file the user writes (a campaign,
scenario, map, requirements, people or uncertainties file): some hundred times the largest
it ships. Checking a larger one could take minutes before anything runs (an 8 MB people file
took 75 s)."""

MAX_LINE_CHARACTERS = 1000
"""The most characters of one error or warning line: a value it echoes from a file (a name,
a list) is cut there."""


class InputTooLargeError(OSError):
    """An input file of more than :data:`MAX_INPUT_CHARACTERS`; its ``strerror`` says so."""

    def __init__(self, path: Path, limit: int) -> None:
        super().__init__(
            errno.EFBIG,
            f"larger than {limit:,} characters, the most hazardhunt reads from one input file",
            str(path),
        )

    def __str__(self) -> str:
        return str(self.strerror)


def read_input_text(path: Path, limit: int = MAX_INPUT_CHARACTERS) -> str:
    """``path.read_text(encoding="utf-8")``, refusing a file of more than ``limit``
    characters without reading the rest of it.

    Raises:
        InputTooLargeError: The file holds more than ``limit`` characters.
        OSError: It cannot be read.
        UnicodeDecodeError: It is not UTF-8 text.
    """
    with path.open(encoding="utf-8") as file:
        text = file.read(limit + 1)
    if len(text) > limit:
        raise InputTooLargeError(path, limit)
    return text


def cut_short(line: str, limit: int = MAX_LINE_CHARACTERS) -> str:
    """``line``, or its first ``limit`` characters and how many more it has."""
    if len(line) <= limit:
        return line
    return f"{line[:limit]}... ({len(line) - limit:,} more characters)"


class TomlTooDeepError(TOMLDecodeError):
    """TOML whose arrays or tables are nested deeper than the parser can follow."""


def loads_toml(text: str) -> dict[str, Any]:
    """``tomllib.loads(text)``.

    Raises:
        TOMLDecodeError: It is not valid TOML (:class:`TomlTooDeepError`: nested too deeply).
    """
    try:
        return tomllib.loads(text)
    except RecursionError:
        raise TomlTooDeepError("arrays or tables nested too deeply") from None


def shortened(text: str, limit: int, joiner: str = "…") -> str:
    """``text`` if it has at most ``limit`` characters, else its start, ``joiner`` and 12 hex
    digits of its SHA-256, ``limit`` characters in all: texts that differ stay apart."""
    if len(text) <= limit:
        return text
    digest = hashlib.sha256(text.encode("utf-8", "surrogatepass")).hexdigest()[:12]
    return text[: max(limit - len(joiner) - len(digest), 0)] + joiner + digest


_KINDS = {
    "int_type": "a whole number",
    "int_parsing": "a whole number",
    "int_from_float": "a whole number",
    "float_type": "a number",
    "float_parsing": "a number",
    "bool_type": "true or false",
    "bool_parsing": "true or false",
    "string_type": "text",
    "list_type": "a list",
    "tuple_type": "a list",
    "dict_type": "a table",
    "model_type": "a table",
    "model_attributes_type": "a table",
}
"""Per pydantic error type, the kind of value it wanted, in a TOML file's words."""


def format_validation_error(error: ValidationError, model: type[BaseModel] | None = None) -> str:
    """The first problem of a pydantic error as ``key: message`` in a TOML file's words (and
    how many more): ``episods: unknown key (did you mean episodes?)``, ``seeds.0: must be a
    whole number, not 0.5``, ``episodes: missing``.

    Args:
        error: What validating ``model`` (or another schema) raised.
        model: The schema validated, whose keys an unknown key is matched against.
    """
    found = error.errors()
    # A misspelt key also leaves its key missing: the misspelling is the one to name.
    first = next((p for p in found if p["type"] == "extra_forbidden"), found[0])
    # pydantic marks a bad dictionary key with a "[key]" part after the key itself.
    location = [part for part in first["loc"] if part != "[key]"]
    key = ".".join(str(part) for part in location) or "(top level)"
    if first["type"] == "extra_forbidden":
        known = schema_keys(model, location[:-1]) if model and location else []
        close = difflib.get_close_matches(str(location[-1]), known, n=1) if location else []
        message = "unknown key" + (f" (did you mean {close[0]}?)" if close else "")
    else:
        message = refused_value(first)
    more = error.error_count() - 1
    problems = "problem" if more == 1 else "problems"
    return f"{key}: {message}" + (f" (and {more} more {problems})" if more else "")


def refused_value(problem: ErrorDetails) -> str:
    """What is wrong with a value, from one problem of a pydantic error, in a TOML file's
    words: ``must be a whole number, not "2"``, ``missing``, ``must not be empty``, ``must be
    greater than 0``, or the message of a check of the schema's own."""
    kind, value = problem["type"], problem.get("input")
    if kind == "missing":
        return "missing"
    if kind in _KINDS:
        return f"must be {_KINDS[kind]}, not {shown_value(value)}"
    if kind == "too_short" and (problem.get("ctx") or {}).get("min_length") == 1:
        return "must not be empty"
    message = str(problem["msg"]).removeprefix("Value error, ")
    # "Input should be greater than 0", "Tuple should have at most 2 items"
    return re.sub(r"^(Input|List|Tuple|String|Dictionary) should ", "must ", message)


def shown_value(value: Any) -> str:
    """A value as a TOML file writes it, cut short: ``true``, ``"1.1"``, ``[1, 2]``."""
    if isinstance(value, bool):
        text = "true" if value else "false"
    elif isinstance(value, str):
        text = f'"{value}"'
    elif isinstance(value, dict):
        text = "a table"
    elif isinstance(value, list | tuple):
        text = "[" + ", ".join(shown_value(item) for item in value) + "]"
    else:
        text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def schema_keys(model: type[BaseModel], path: Sequence[int | str]) -> list[str]:
    """The keys of the table at ``path`` in ``model``'s schema (none where the path leaves the
    schema's nested models: a list, a free table)."""
    current: type[BaseModel] = model
    for part in path:
        field = _written_fields(current).get(str(part))
        nested = [
            kind
            for kind in _alternatives(field.annotation if field else None)
            if isinstance(kind, type) and issubclass(kind, BaseModel)
        ]
        if not nested:
            return []
        current = nested[0]
    return list(_written_fields(current))


def _written_fields(model: type[BaseModel]) -> dict[str, FieldInfo]:
    """A model's fields by the key a file writes for each (its alias, where it has one)."""
    return {field.alias or name: field for name, field in model.model_fields.items()}


def _alternatives(annotation: Any) -> tuple[Any, ...]:
    """The types an annotation allows (``A | None``: ``A`` and ``None``)."""
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        return typing.get_args(annotation)
    return (annotation,)
