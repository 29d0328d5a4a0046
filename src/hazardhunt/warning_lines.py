"""hazardhunt's own warnings as one line each on stderr, ``warning: ...``, each once.

Python shows a warning in two lines, a path into the source and the line that warned; for a
warning hazardhunt gives on purpose (a plug-in of an earlier protocol, an arm of the portfolio
dropped) that is noise around one sentence. The command line shows them as one line; a
campaign's worker processes send theirs to the campaign process, which shows them the same way
after the id of the run they belong to (above its progress bars, where a worker's own writes
would break them). Warnings of other libraries keep Python's form. Either kind may quote a
file someone else made (a class name matplotlib cannot draw): its control characters are
written out (``\\x1b``), never sent to the terminal.
"""

from __future__ import annotations

import sys
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import TextIO

_PACKAGE = Path(__file__).resolve().parent


def printable(text: str) -> str:
    """``text`` with every character the terminal would not print as itself (escape
    sequences, line breaks) written out as Python writes it in a string: ``\\x1b``, ``\\n``."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in str(text))


def print_warning(text: str) -> None:
    """Show one warning's text as ``warning: TEXT`` on stderr."""
    print(f"warning: {printable(text)}", file=sys.stderr, flush=True)


def show_warnings_in_one_line(
    write: Callable[[str], None] = print_warning, prefix: str = ""
) -> None:
    """From now on, show each warning given from hazardhunt's own code once, as ``write``
    (``prefix`` + the message); others as before.

    Args:
        write: Shows one warning's text (default: ``warning: TEXT`` on stderr).
        prefix: Put before every message (a run's id, in a campaign's worker process).
    """
    shown: set[str] = set()
    show_other = warnings.showwarning

    def show(
        message: Warning | str,
        category: type[Warning],
        filename: str,
        lineno: int,
        file: TextIO | None = None,
        line: str | None = None,
    ) -> None:
        if not Path(filename).resolve().is_relative_to(_PACKAGE):
            show_other(printable(str(message)), category, filename, lineno, file, line)
            return
        text = printable(f"{prefix}{message}")
        if text not in shown:
            shown.add(text)
            write(text)

    warnings.showwarning = show
