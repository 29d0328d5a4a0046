"""The `hazardhunt` command itself: its version."""

from __future__ import annotations

import sys
from pathlib import Path

import hazardhunt
from tests.helpers import hazardhunt as command

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

PYPROJECT = Path(__file__).parents[1] / "pyproject.toml"


def test_version_prints_the_package_version() -> None:
    result = command("--version")
    assert result.returncode == 0, result.stderr
    packaged = tomllib.loads(PYPROJECT.read_text())["project"]["version"]
    assert result.stdout == f"hazardhunt {packaged}\n"
    assert hazardhunt.__version__ == packaged
