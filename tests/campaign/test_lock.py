"""The locks between hazardhunt processes: one holder at a time, and nothing left behind."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest

from hazardhunt.campaign.config import ConfigError
from hazardhunt.campaign.lock import exclusive_lock, waiting_lock


def test_a_lock_names_its_holder_while_held_and_is_gone_after(tmp_path: Path) -> None:
    lock = tmp_path / ".run.lock"
    with exclusive_lock(lock, tmp_path / "run", "run"):
        with (
            pytest.raises(ConfigError, match=r"run: another run \(pid \d+\) is writing"),
            exclusive_lock(lock, tmp_path / "run", "run"),
        ):
            pass
        assert lock.read_text().strip().isdigit()
    assert list(tmp_path.iterdir()) == []


def test_a_lock_left_by_a_killed_holder_is_taken_over(tmp_path: Path) -> None:
    lock = tmp_path / ".run.lock"
    lock.write_text("999999999\n")  # the file of a holder killed while it held the lock
    with exclusive_lock(lock, tmp_path / "run", "run"):
        pass
    assert not lock.exists()


def test_who_waited_on_a_lock_its_holder_removed_holds_the_lock_under_its_name(
    tmp_path: Path,
) -> None:
    """A waiter wakes on the file its holder removed; it must not hold that file while another
    process locks the new file under the name."""
    lock = tmp_path / ".report.lock"
    holder = exclusive_lock(lock, tmp_path, "report")
    holder.__enter__()
    acquired, release = threading.Event(), threading.Event()

    def wait() -> None:
        with waiting_lock(lock):
            acquired.set()
            release.wait(30)

    waiter = threading.Thread(target=wait)
    waiter.start()
    time.sleep(0.3)  # the waiter has opened the holder's file and waits on it
    holder.__exit__(None, None, None)
    try:
        assert acquired.wait(30)
        with (
            pytest.raises(ConfigError, match="another report"),
            exclusive_lock(lock, tmp_path, "report"),
        ):
            pass
    finally:
        release.set()
        waiter.join()
    assert not lock.exists()
