"""Calling the system under test's plug-ins without trusting them.

A controller or safety layer is someone's code: it may raise, return something its protocol does
not allow, or hang. The simulation calls them through these helpers, which turn the last two into
exceptions too, so that each of the three ends the episode as ``sut_error`` with the error
recorded, and the run goes on:

- :func:`checked_command` and :func:`checked_status` check what ``control`` and ``update``
  return (an :class:`UnusableReturnError` saying what is wrong);
- :class:`TimeLimit` bounds the wall-clock time of a call (a :class:`TimeLimitError`).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
import reprlib
import signal
import threading
import time
import traceback
import warnings
from collections.abc import Callable
from pathlib import Path
from types import FrameType
from typing import Any, TypeGuard, TypeVar

import numpy as np

from hazardhunt.errors import HazardhuntError
from hazardhunt.sut.protocols import ControlCommand, SafetyStatus

T = TypeVar("T")


class UnusableReturnError(HazardhuntError, ValueError):
    """A plug-in returned something its protocol does not allow."""


class TimeLimitError(HazardhuntError):
    """A plug-in's call ran longer than its time limit."""


class _Alarm(BaseException):
    """Raised inside the call when its time is up; not an Exception, so that a plug-in's own
    ``except Exception`` does not swallow it."""


def checked_command(returned: object) -> ControlCommand:
    """``returned`` as a command the simulation can play and record.

    Speed and turn rate are finite numbers (unless the command is ``failed``, which brakes and
    ignores them), the status a string, the solve time a finite number of seconds, and the
    planned and predicted positions None or (k, 2) arrays.

    Raises:
        UnusableReturnError: Saying what is wrong.
    """
    if _plain_command(returned):
        return returned
    if not isinstance(returned, ControlCommand):
        raise UnusableReturnError(
            f"control() returned {_described(returned)}, not a ControlCommand"
        )
    for name in ("speed", "yaw_rate", "solve_time_s"):
        value = getattr(returned, name)
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise UnusableReturnError(
                f"control() returned a command whose {name} is {_described(value)}"
            )
    if not isinstance(returned.failed, (bool, np.bool_)):
        raise UnusableReturnError(
            f"control() returned a command whose failed is {_described(returned.failed)}"
        )
    if not isinstance(returned.status, str):
        raise UnusableReturnError(
            f"control() returned a command whose status is {_described(returned.status)}"
        )
    if not returned.failed and not (
        math.isfinite(returned.speed) and math.isfinite(returned.yaw_rate)
    ):
        raise UnusableReturnError(
            f"control() returned a non-finite command (speed {returned.speed}, "
            f"yaw_rate {returned.yaw_rate})"
        )
    if not (math.isfinite(returned.solve_time_s) and returned.solve_time_s >= 0):
        raise UnusableReturnError(f"control() returned a solve_time_s of {returned.solve_time_s}")
    return dataclasses.replace(
        returned,
        speed=float(returned.speed),
        yaw_rate=float(returned.yaw_rate),
        failed=bool(returned.failed),
        solve_time_s=float(returned.solve_time_s),
        planned_positions=_points("planned_positions", returned.planned_positions),
        predicted_human=_points("predicted_human", returned.predicted_human),
    )


def _plain_command(command: object) -> TypeGuard[ControlCommand]:
    """Whether ``command`` is a usable ControlCommand whose values are already what
    :func:`checked_command` makes of them (floats, a bool, a string, float64 arrays of (x, y)
    rows): the usual command, checked without building a copy."""
    if type(command) is not ControlCommand:
        return False
    speed, yaw_rate, solve_time = command.speed, command.yaw_rate, command.solve_time_s
    return (
        type(speed) is float
        and type(yaw_rate) is float
        and type(solve_time) is float
        and type(command.failed) is bool
        and type(command.status) is str
        and (command.failed or (math.isfinite(speed) and math.isfinite(yaw_rate)))
        and math.isfinite(solve_time)
        and solve_time >= 0
        and _plain_points(command.planned_positions)
        and _plain_points(command.predicted_human)
    )


def _plain_points(value: object) -> bool:
    return value is None or (
        type(value) is np.ndarray
        and value.dtype == np.float64
        and value.ndim == 2
        and value.shape[1] == 2
    )


def checked_status(returned: object) -> SafetyStatus:
    """``returned`` as the safety layer's verdict: a SafetyStatus of two bools.

    Raises:
        UnusableReturnError: Saying what is wrong.
    """
    if not isinstance(returned, SafetyStatus):
        raise UnusableReturnError(f"update() returned {_described(returned)}, not a SafetyStatus")
    flags = (returned.emergency_stop, returned.human_in_field)
    plain = type(returned) is SafetyStatus and type(flags[0]) is bool and type(flags[1]) is bool
    if not plain and not all(isinstance(flag, (bool, np.bool_)) for flag in flags):
        raise UnusableReturnError(
            f"update() returned a SafetyStatus of {_described(flags[0])} and "
            f"{_described(flags[1])}, not two bools"
        )
    return returned if plain else SafetyStatus(bool(flags[0]), bool(flags[1]))


def is_finite_number(value: object) -> bool:
    """Whether ``value`` is a finite real number (a bool is not)."""
    return not isinstance(value, bool) and isinstance(value, numbers.Real) and math.isfinite(value)


def _points(name: str, value: Any) -> Any:
    """None, or ``value`` as an array of (x, y) rows."""
    if value is None:
        return None
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        array = None
    if array is None or array.ndim != 2 or array.shape[1] != 2:
        raise UnusableReturnError(
            f"control() returned a command whose {name} is {_described(value)}, not None or "
            "an array of (x, y) rows"
        )
    return array


def _described(value: object) -> str:
    """``value`` in a message: its type and a short repr."""
    if value is None:
        return "None"
    return f"a {type(value).__name__} ({reprlib.repr(value)})"


class TimeLimit:
    """A wall-clock limit on each call of a plug-in, in s; None for no limit.

    It arms a SIGALRM timer (``signal.setitimer``), which only the main thread of a process
    receives: hazardhunt plays its episodes there, in the worker processes of a batch too. In
    another thread, or on a platform without SIGALRM, calls run without a limit and a warning
    says so. A call stuck inside native code (a solver written in C) is interrupted once it
    returns to Python.
    """

    def __init__(self, seconds: float | None) -> None:
        """Raises ValueError unless ``seconds`` is None or a positive number of seconds, at
        most a day (the interval timer holds no more)."""
        if seconds is not None and not (is_finite_number(seconds) and 0 < seconds <= 86_400):
            raise ValueError(
                "controller_timeout must be a positive number of seconds, at most a day "
                f"(86400), or None, not {seconds!r}"
            )
        self.seconds = seconds
        self._warned = False

    def bound(self, what: str, function: Callable[..., T]) -> Callable[..., T]:
        """``function`` under the limit, to call as often as needed: ``function`` itself when
        there is no limit, so that a call per physics step costs nothing more."""
        if self.seconds is None:
            return function
        return functools.partial(self.call, what, function)

    def call(self, what: str, function: Callable[..., T], *args: Any) -> T:
        """``function(*args)``, interrupted when it outlasts the limit.

        Args:
            what: The call, for the message (``"control()"``).

        Raises:
            TimeLimitError: The call took longer than the limit (also when the function
                caught the interruption and returned).
        """
        if self.seconds is None or not self._can_interrupt():
            return function(*args)
        try:
            return _interruptible(self.seconds, function, args)
        except _Alarm:
            raise TimeLimitError(
                f"{what} took longer than its time limit of {self.seconds:g} s"
            ) from None

    def _can_interrupt(self) -> bool:
        if hasattr(signal, "setitimer") and threading.current_thread() is threading.main_thread():
            return True
        if not self._warned:
            warnings.warn(
                "controller_timeout works only in a process's main thread on a platform with "
                "SIGALRM; the controller and the safety layer run here without a time limit",
                RuntimeWarning,
                stacklevel=3,
            )
            self._warned = True
        return False


def is_plugin_fault(error: BaseException) -> bool:
    """Whether ``error``, raised out of a plug-in's call, is the plug-in's to record: any
    exception, ``SystemExit``, ``GeneratorExit`` (the interpreter throws it into a generator
    being closed, at its ``yield``, never out of a call) and every other ``BaseException``,
    but the user's Ctrl-C (:func:`is_users_interrupt`) and the time limit's own interruption."""
    if isinstance(error, KeyboardInterrupt):
        return not is_users_interrupt()
    return not isinstance(error, _Alarm)


def raised(error: BaseException) -> str:
    """What a plug-in raised, and where: ``Type: message (file, line N)``, at the last place in
    the traceback outside hazardhunt's own code (the plug-in's, when it called back into
    hazardhunt)."""
    said = f"{type(error).__name__}: {error}" if str(error) else type(error).__name__
    frames = traceback.extract_tb(error.__traceback__)
    ours = Path(__file__).parents[1]
    own = [frame for frame in frames if not Path(frame.filename).is_relative_to(ours)]
    if not (own or frames):
        return said
    frame = (own or frames)[-1]
    return f"{said} ({frame.filename}, line {frame.lineno})"


_ctrl_c_received = False


def _on_ctrl_c(signum: int, frame: FrameType | None) -> None:
    """Python's own SIGINT handler, which also notes that the signal came."""
    global _ctrl_c_received
    _ctrl_c_received = True
    raise KeyboardInterrupt


def notice_ctrl_c() -> None:
    """Handle SIGINT as Python does (a ``KeyboardInterrupt``), noting that it came, so that
    :func:`is_users_interrupt` tells the user's Ctrl-C from a ``KeyboardInterrupt`` a plug-in
    raised itself. hazardhunt's command calls it when it starts, its worker processes too;
    it leaves a SIGINT that is ignored so (the workers of a campaign's worker), and does
    nothing outside the main thread."""
    main = threading.current_thread() is threading.main_thread()
    if main and signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:
        signal.signal(signal.SIGINT, _on_ctrl_c)


def is_users_interrupt() -> bool:
    """Whether a ``KeyboardInterrupt`` just raised is the user's Ctrl-C: a SIGINT came, where
    :func:`notice_ctrl_c` watches for it; never, where SIGINT is ignored (a campaign's worker
    processes, whose Ctrl-C the campaign process handles); and, where neither (hazardhunt
    used as a library), taken to be, as nothing tells."""
    handler = signal.getsignal(signal.SIGINT)
    if handler is _on_ctrl_c:
        return _ctrl_c_received
    return handler is not signal.SIG_IGN


def _interruptible(seconds: float, function: Callable[..., T], args: tuple[Any, ...]) -> T:
    """``function(*args)`` under a SIGALRM timer of ``seconds``; raises _Alarm when it goes off,
    also when the function caught the interruption and returned or raised something else."""
    expired = False

    def on_alarm(signum: int, frame: FrameType | None) -> None:
        nonlocal expired
        expired = True
        raise _Alarm

    started = time.monotonic()
    previous_handler = signal.signal(signal.SIGALRM, on_alarm)
    previous_timer = (0.0, 0.0)
    try:
        try:
            previous_timer = signal.setitimer(signal.ITIMER_REAL, seconds)
            result = function(*args)
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
    except Exception:
        if not expired:
            raise
    finally:
        signal.signal(signal.SIGALRM, previous_handler)
        _rearm(previous_timer, time.monotonic() - started)
    if expired:
        raise _Alarm
    return result


def _rearm(timer: tuple[float, float], elapsed: float) -> None:
    """Restart a timer someone else had set, less the time the call took."""
    delay, interval = timer
    if delay > 0:
        signal.setitimer(signal.ITIMER_REAL, max(delay - elapsed, 1e-6), interval)
