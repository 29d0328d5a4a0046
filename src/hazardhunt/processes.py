"""Worker processes that die with the process that started them.

A run's or campaign's worker processes must not outlive it: an orphan would go on writing
into a directory whose owner is gone, or hold memory until someone finds it. On Linux the
kernel kills a worker when its parent dies (``PR_SET_PDEATHSIG``); a worker whose parent died
before that took effect exits at once.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys

_PR_SET_PDEATHSIG = 1


def die_with_parent(parent_pid: int) -> None:
    """Have the kernel kill this process (SIGKILL) when its parent dies; exit now if the parent
    ``parent_pid`` is already gone (elsewhere than on Linux, only the latter).

    Raises:
        OSError: The kernel refused.
    """
    if sys.platform == "linux":
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        if libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL) != 0:
            errno = ctypes.get_errno()
            raise OSError(errno, f"prctl(PR_SET_PDEATHSIG): {os.strerror(errno)}")
    if os.getppid() != parent_pid:  # the parent died before prctl took effect
        os._exit(1)
