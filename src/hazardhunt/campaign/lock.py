"""The lock that keeps two processes from writing one run or campaign directory."""

from __future__ import annotations

import fcntl
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from hazardhunt.campaign.config import ConfigError


@contextmanager
def exclusive_lock(lock_file: Path, guarded: Path, holder: str) -> Iterator[None]:
    """Hold ``lock_file`` (``flock``, created if absent) while writing ``guarded``; the kernel
    drops the lock when the process dies, however it dies, so no stale lock survives a kill.

    Args:
        lock_file: The file locked; it stays, holding the pid of the last holder.
        guarded: The directory the lock protects, named in the error.
        holder: What else would hold the lock, for the error ("campaign", "run").

    Raises:
        ConfigError: Another process holds the lock (the caller has written nothing).
    """
    with open(lock_file, "a+") as handle:
        try:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            pid = handle.read().strip() or "?"
            raise ConfigError(
                f"{guarded}: another {holder} (pid {pid}) is writing this directory"
            ) from None
        handle.truncate(0)
        handle.write(f"{os.getpid()}\n")
        handle.flush()
        yield
