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
from typing import TextIO

from hazardhunt.campaign.config import ConfigError


@contextmanager
def exclusive_lock(lock_file: Path, guarded: Path, holder: str) -> Iterator[None]:
    """Hold ``lock_file`` (``flock``, created for the while) while writing ``guarded``; the
    kernel drops the lock when the process dies, however it dies, so no stale lock survives a
    kill, and the file goes when the lock is given up.

    Args:
        lock_file: The file locked; it holds the pid of its holder.
        guarded: The directory the lock protects, named in the error.
        holder: What else would hold the lock, for the error ("campaign", "run").

    Raises:
        ConfigError: Another process holds the lock (the caller has written nothing).
    """
    try:
        handle = _acquire(lock_file, wait=False)
    except BlockingIOError:
        raise ConfigError(
            f"{guarded}: another {holder} (pid {_read_pid(lock_file)}) is writing this directory"
        ) from None
    try:
        handle.truncate(0)
        handle.write(f"{os.getpid()}\n")
        handle.flush()
        yield
    finally:
        _release(lock_file, handle)


@contextmanager
def waiting_lock(lock_file: Path) -> Iterator[None]:
    """Hold ``lock_file`` (``flock``, created for the while), waiting while another process
    holds it: for short steps that may take turns (two reports putting their pages in place)."""
    handle = _acquire(lock_file, wait=True)
    try:
        yield
    finally:
        _release(lock_file, handle)


def _acquire(lock_file: Path, *, wait: bool) -> TextIO:
    """``lock_file`` opened and locked.

    A process that opened the file before its holder removed it (:func:`_release`) may lock
    the removed file afterwards; it checks that the name still leads to the file it locked, and
    else starts again with the file now under the name, so two processes never both hold it.

    Raises:
        BlockingIOError: Another process holds the lock and ``wait`` is False.
    """
    while True:
        handle = open(lock_file, "a+")  # noqa: SIM115 - closed by _release
        try:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX if wait else fcntl.LOCK_EX | fcntl.LOCK_NB)
            if _names(lock_file, handle):
                return handle
        except BaseException:
            handle.close()
            raise
        handle.close()


def _release(lock_file: Path, handle: TextIO) -> None:
    """Remove ``lock_file``, then unlock it: nothing of the lock is left beside what it kept."""
    try:
        lock_file.unlink(missing_ok=True)
    finally:
        handle.close()


def _names(lock_file: Path, handle: TextIO) -> bool:
    """Whether ``lock_file`` still names the file open in ``handle``."""
    try:
        named = lock_file.stat()
    except FileNotFoundError:
        return False
    opened = os.fstat(handle.fileno())
    return (named.st_dev, named.st_ino) == (opened.st_dev, opened.st_ino)


def _read_pid(lock_file: Path) -> str:
    """The pid the holder of ``lock_file`` wrote, or "?" (gone, or not yet written)."""
    try:
        return lock_file.read_text().strip() or "?"
    except OSError:
        return "?"


def process_running(pid: int) -> bool:
    """Whether process ``pid`` runs (another user's counts as running)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass  # another user's process
    return True
