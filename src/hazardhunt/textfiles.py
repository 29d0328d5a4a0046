"""Reading TOML that anyone may have written: a file nested too deeply for the parser is a
decoding error that names the problem, never a ``RecursionError``."""

from __future__ import annotations

import sys
from typing import Any

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

TOMLDecodeError = tomllib.TOMLDecodeError


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
