"""Locks between hazardhunt processes, all ``flock``s that the kernel drops when their process
dies: the one that keeps two processes from writing one run or campaign directory, the one under
which two reports of a directory take turns, and whether a process named in a leftover file
still runs."""

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


@contextmanager
def waiting_lock(lock_file: Path) -> Iterator[None]:
    """Hold ``lock_file`` (``flock``, created if absent), waiting while another process holds
    it: for short steps that may take turns (two reports putting their pages in place)."""
    with open(lock_file, "a") as handle:
        fcntl.flock(handle.fileno(), fcntl.LOCK_EX)
        yield


def process_running(pid: int) -> bool:
    """Whether process ``pid`` runs (another user's counts as running)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass  # another user's process
    return True
