"""Writing a file so that a failed write (a full disk, above all) leaves nothing half-written
behind and ends in an error that names the file."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path


@contextlib.contextmanager
def file_written(path: Path, named: Path | None = None) -> Iterator[Path]:
    """A block that writes ``path``: if it raises ``OSError``, what it left of ``path`` is
    removed and the error names the file (its ``filename``: ``named``, or else ``path``),
    unless it names one already.

    Args:
        path: The file the block writes.
        named: The file to name instead (the one ``path``, a temporary file, becomes).
    """
    try:
        yield path
    except OSError as error:
        with contextlib.suppress(OSError):
            path.unlink(missing_ok=True)
        if error.filename:
            raise
        raise OSError(error.errno, error.strerror or str(error), str(named or path)) from error
