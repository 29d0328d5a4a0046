"""The errors hazardhunt raises on purpose, under one base that carries the command's exit code.

``hazardhunt`` prints such an error as one line on stderr and exits with its ``exit_code``:

- 2, :class:`InputError`: something the user gave is wrong (a file, an option, a plug-in);
  nothing was written;
- 1, every other :class:`HazardhuntError`: the work could not be done or did not test anything
  (a run that could not write its results, a run whose every episode ended in a SUT error, a
  campaign some of whose runs failed).
"""

from __future__ import annotations

from typing import ClassVar


class HazardhuntError(Exception):
    """An error hazardhunt raises on purpose; the command exits with ``exit_code``."""

    exit_code: ClassVar[int] = 1


class InputError(HazardhuntError, ValueError):
    """Something the user gave is wrong: a file, an option, a plug-in. Nothing was written."""

    exit_code: ClassVar[int] = 2


class PluginError(InputError):
    """A plug-in that cannot be loaded or does not fit its protocol."""
