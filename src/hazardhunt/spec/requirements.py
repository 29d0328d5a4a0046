"""Safety requirements beyond the contact rule, judged on an episode's signals.

The study's requirement (no contact for which the robot is responsible, SPEC 4) stays the one
every episode is judged by. A safety engineer's own requirements are usually stricter and hold
before any contact: a separation that grows with the robot's speed, a slow robot near people,
no restart with a person in the field. A **requirement** here takes an episode's signals
(:data:`SIGNALS`, sampled at every control instant and at the episode's end) and returns a
:class:`Verdict`: its *robustness*, the signed margin by which the episode satisfied it
(negative: violated by that much), which guides a search long before any violation.

Requirements written in signal temporal logic come from a TOML file (``[requirements.NAME]``
with ``formula``, ``description`` and ``source``), monitored by ``rtamt`` in discrete time
with the control period as its sampling period (time bounds such as ``eventually[0:20]`` are
in seconds). hazardhunt ships a library of them (``requirements.toml`` beside this module).
A formula that does not parse or names an unknown signal is refused when it is read, with
the file, the requirement and the position in the formula; so is a time bound longer than the
longest episode (:data:`~hazardhunt.spec.outcomes.MAX_EPISODE_DURATION`), which rtamt would
monitor with a buffer of that many samples.
"""

from __future__ import annotations

import logging
import math
import re
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from hazardhunt.errors import InputError
from hazardhunt.spec.episode import TrajectorySample
from hazardhunt.spec.outcomes import MAX_EPISODE_DURATION
from hazardhunt.textfiles import TOMLDecodeError, loads_toml, read_input_text

LIBRARY = Path(__file__).with_name("requirements.toml")
"""hazardhunt's named requirements for the shop floor."""

Signals = Mapping[str, NDArray[np.float64]]
"""An episode's signals by name, each one value per sample, with ``time`` (s) among them."""

SIGNALS: dict[str, str] = {
    "clearance": "gap between the human and the robot, in m (negative: overlap)",
    "robot_speed": "the robot's speed, in m/s",
    "human_speed": "the human's speed since the sample before, in m/s",
    "closing_speed": "how fast the gap shrinks since the sample before, in m/s (negative: grows)",
    "human_in_field": "1 while the human overlaps the protective field, else 0",
    "emergency_stop": "1 while the safety layer's emergency stop holds, else 0",
    "human_visible": "1 while the tracking cameras see the human, else 0",
    "controller_ok": "1 while the controller's last command succeeded, else 0",
    "stopping_distance": (
        "the distance the robot needs to stand still, in m: its speed times the safety "
        "function's response time, plus speed^2 / (2 * emergency deceleration)"
    ),
    "protective_separation": (
        "the protective separation distance of ISO/TS 15066 speed and separation monitoring, "
        "in m: the human's speed times (response time + the robot's stopping time) plus the "
        "stopping distance (no intrusion or uncertainty allowance: add yours in the formula)"
    ),
    "goal_distance": "the robot's distance to its goal, in m",
}
"""The signals a requirement can name, with their units (time bounds of operators are in s)."""

_KEYWORDS = frozenset(
    "always eventually historically once since until next prev implies iff xor and or not "  # noqa: SIM905
    "abs sqrt exp pow rise fall true false s ms us ns".split()
)
"""Words of rtamt's discrete-time STL that are not signals."""


@dataclass(frozen=True)
class Verdict:
    """What a requirement says of an episode."""

    robustness: float
    """The signed margin: positive, satisfied by that much; negative, violated by that much."""
    signals: tuple[str, ...] = ()
    """For a violation, the signals that explain it (rtamt's explanation of the formula:
    those that hold the violating values); empty otherwise."""
    time: float | None = None
    """For a violation, the first instant of the episode the explanation points at, in s."""

    @property
    def decided_by(self) -> str:
        """The signals that explain a violation, joined (``clearance+robot_speed``), or
        ``unexplained``."""
        return "+".join(self.signals) or "unexplained"

    @property
    def violated(self) -> bool:
        """Whether the episode violated the requirement."""
        return self.robustness < 0.0


@runtime_checkable
class Requirement(Protocol):
    """A requirement on an episode (a plug-in point: any object with these two members)."""

    name: str
    """A short name, unique in a run (it names the columns of the episode table)."""

    def check(self, signals: Signals) -> Verdict:
        """The verdict on an episode's signals (:data:`SIGNALS` and ``time``)."""
        ...


class RequirementError(InputError):
    """A requirement that cannot be read: the message names the file, the requirement and,
    for a formula, the position in it."""


class StlRequirement:
    """A requirement written in signal temporal logic over :data:`SIGNALS`."""

    def __init__(
        self,
        name: str,
        formula: str,
        description: str = "",
        source: str = "",
        where: str = "",
        sampling_period: float = 0.2,
    ) -> None:
        """Parse ``formula``.

        Args:
            name: The requirement's name.
            formula: The formula (rtamt's discrete-time STL).
            description: What it asks, in words.
            source: Where it comes from (a standard, a hazard analysis).
            where: The file it was read from, for error messages ("": none).
            sampling_period: The period of the episode's samples, in s (the control period).

        Raises:
            RequirementError: The formula names an unknown signal or does not parse.
        """
        self.name, self.formula = name, formula
        self.description, self.source = description, source
        self.sampling_period = sampling_period
        place = f"{where}: requirement {name!r}" if where else f"requirement {name!r}"
        self.signals = _signals_named(formula, place)
        self._spec = _parsed(formula, self.signals, sampling_period, place)

    def check(self, signals: Signals) -> Verdict:
        """The robustness of the formula at the episode's start."""
        # Sample i at i periods: the last sample, at the episode's end, may come early.
        count = len(signals["time"])
        data: dict[str, Any] = {"time": [i * self.sampling_period for i in range(count)]}
        for name in self.signals:
            data[name] = [float(v) for v in signals[name]]
        trace = self._spec.evaluate(data)
        robustness = float(trace[0][1])
        if robustness >= 0.0:
            return Verdict(robustness)
        return Verdict(robustness, *self._explained())

    def _explained(self) -> tuple[tuple[str, ...], float | None]:
        """The signals that explain the violation just evaluated, and its first instant."""
        explainer = self._spec.explainer
        explainer.explanations = {}  # it keeps what it explained before
        try:
            self._spec.explain()
        except Exception:  # an operator rtamt cannot explain: the verdict stands without it
            return (), None
        found = {name: explainer.explanations.get(name) or [] for name in self.signals}
        signals = tuple(name for name, intervals in found.items() if intervals)
        starts = [interval[0] for name in signals for interval in found[name]]
        return signals, (min(starts) * self.sampling_period if starts else None)

    def __repr__(self) -> str:
        return f"StlRequirement({self.name!r}, {self.formula!r})"


def _signals_named(formula: str, place: str) -> tuple[str, ...]:
    """The signals ``formula`` names, in order; an unknown one is an error with its position."""
    found: list[str] = []
    # A word that starts a name: not the exponent of 1e-3 nor the unit of 5s.
    for match in re.finditer(r"(?<![\w.])[A-Za-z_]\w*", formula):
        word = match.group()
        if word in _KEYWORDS:
            continue
        if word not in SIGNALS:
            raise RequirementError(
                f"{place}: formula position {match.start() + 1}: unknown signal {word!r} "
                f"(known: {', '.join(SIGNALS)})"
            )
        if word not in found:
            found.append(word)
    return tuple(found)


MAX_NEGATIONS = 12
"""The most negations a formula may hold: rtamt parses 20 nested ones in a second, 30 in
many minutes."""

_NEGATION = re.compile(r"(?<![\w.])not(?!\w)|!(?!=)")


def _parsed(formula: str, signals: Sequence[str], period: float, place: str) -> Any:
    """rtamt's monitor of ``formula``."""
    with warnings.catch_warnings():  # its parser's imports use typing.io
        warnings.simplefilter("ignore", DeprecationWarning)
        from rtamt.spec.stl.discrete_time.specification import (
            StlDiscreteTimeOfflineSpecification,
        )

    negations = len(_NEGATION.findall(formula))
    if negations > MAX_NEGATIONS:
        raise RequirementError(
            f"{place}: formula: {negations} negations ('not', '!'), at most {MAX_NEGATIONS} "
            "(rtamt's parser takes twice as long with each nested one)"
        )
    spec = StlDiscreteTimeOfflineSpecification()  # offline: it explains its violations
    for name in signals:
        spec.declare_var(name, "float")
    spec.set_sampling_period(period, "s", 0.1)
    spec.spec = formula
    quiet = logging.getLogger()
    level = quiet.level
    quiet.setLevel(logging.ERROR)  # rtamt warns on the root logger while it parses
    try:
        spec.parse()
    except Exception as error:  # rtamt raises its own and plain exceptions on bad input
        raise RequirementError(f"{place}: {_parse_message(error)}") from None
    finally:
        quiet.setLevel(level)
    for node in spec.ast.specs:
        _check_time_bounds(node, place)
    _check_evaluation_cost(spec.ast.specs, period, place)
    return spec


_SECONDS_PER_UNIT = {"": 1.0, "s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
"""rtamt's time units (a bound without one is in s, the unit of the sampling period)."""


def _check_time_bounds(node: Any, place: str) -> None:
    """Refuse a time bound of ``node`` or below it longer than the longest episode: rtamt
    keeps a buffer of the bound's samples per operator (``[0:1e9]`` runs out of memory)."""
    for bound in ("begin", "end"):
        value = getattr(node, bound, None)
        if value is None:
            continue
        unit = str(getattr(node, f"{bound}_unit", "") or "")
        seconds = float(value) * _SECONDS_PER_UNIT.get(unit, 1.0)
        if seconds > MAX_EPISODE_DURATION:
            operator = type(node).__name__.removeprefix("Timed").lower()
            raise RequirementError(
                f"{place}: formula: the time bound {float(value):g}{unit or ' s'} of "
                f"{operator!r} is longer than the longest episode ({MAX_EPISODE_DURATION:g} s)"
            )
    for child in node.children:
        _check_time_bounds(child, place)


MAX_EVALUATION_STEPS = 4e8
"""The most steps evaluating a formula on one episode may take (about 3 s): one ``always``
or ``eventually`` bounded by the longest episode takes 3.2e8; rtamt's cost grows with each
temporal operator nested, by the samples of its time bound (their square for ``until`` and
``since``), so a formula that passes the other checks could take minutes per episode."""

_PYTHON_STEP = 40
"""What one step of rtamt's ``until`` and ``since`` costs, in steps of its other operators
(a Python loop against a C-level ``min`` or ``max`` over a window)."""


def _check_evaluation_cost(nodes: Sequence[Any], period: float, place: str) -> None:
    """Refuse a formula whose evaluation on one episode would take more than
    :data:`MAX_EVALUATION_STEPS`, counted as rtamt evaluates it offline, on an episode of the
    default length (30 s) or, if longer, of its longest time bound."""
    operators: list[tuple[str, int, int]] = []  # kind, window and end of the window in samples
    pending = list(nodes)
    while pending:  # a loop, not recursion: the parser has followed the nesting already
        node = pending.pop()
        pending.extend(node.children)
        kind = type(node).__name__
        if kind.startswith("Timed"):
            begin, end = (_bound_seconds(node, bound) for bound in ("begin", "end"))
            last = round(end / period)
            operators.append((kind, last - round(begin / period) + 1, last))
        else:
            operators.append((kind, 1, 0))
    samples = max([round(30.0 / period) + 1, *(end + 1 for _, _, end in operators)])
    steps = 0.0
    for kind, window, end in operators:
        looped = kind in ("TimedUntil", "TimedSince")
        steps += samples * window * ((end + 1) / 2 * _PYTHON_STEP if looped else 1)
    if steps > MAX_EVALUATION_STEPS:
        raise RequirementError(
            f"{place}: formula: too costly to evaluate: about {steps:.2g} steps per episode "
            f"(each temporal operator nested adds the samples of its time bound), at most "
            f"{MAX_EVALUATION_STEPS:.2g}: nest fewer bounded operators or shorten their bounds"
        )


def _bound_seconds(node: Any, bound: str) -> float:
    """A time bound of ``node`` in s (a begin without a unit takes the end's, as in rtamt)."""
    unit = str(getattr(node, f"{bound}_unit", "") or "") or str(node.end_unit or "")
    return float(getattr(node, bound)) * _SECONDS_PER_UNIT.get(unit, 1.0)


def _parse_message(error: Exception) -> str:
    """rtamt's parse error as ``formula position N: what``."""
    text = str(error).replace("RTAMT Exception:", "").strip()
    located = re.match(r"(\d+):(\d+):\s*(.*)", text, re.DOTALL)
    if located is None:
        return f"formula does not parse: {text or type(error).__name__}"
    what = re.sub(r"\s*expecting \{.*", "", located.group(3)).strip()
    return f"formula position {int(located.group(2)) + 1}: {what}"


def load_requirements(path: Path, sampling_period: float = 0.2) -> tuple[StlRequirement, ...]:
    """Every requirement of a requirements file, in order.

    Raises:
        RequirementError: The file is missing, not TOML, has no ``[requirements.NAME]``
            table, or a requirement is malformed.
    """
    try:
        data = loads_toml(read_input_text(path))
    except OSError as error:
        raise RequirementError(f"{path}: cannot be read: {error.strerror or error}") from None
    except UnicodeDecodeError as error:
        raise RequirementError(f"{path}: not a text file: {error.reason}") from None
    except TOMLDecodeError as error:
        raise RequirementError(f"{path}: not valid TOML: {error}") from None
    tables = data.get("requirements")
    if not isinstance(tables, dict) or not tables:
        raise RequirementError(f"{path}: requirements: must have at least one [requirements.NAME]")
    unknown = sorted(set(data) - {"requirements"})
    if unknown:
        raise RequirementError(f"{path}: {unknown[0]}: unknown key (only [requirements.NAME])")
    found = []
    for name, table in tables.items():
        place = f"{path}: requirements.{name}"
        if not isinstance(table, dict):
            raise RequirementError(f"{place}: must be a table with a 'formula'")
        extra = sorted(set(table) - {"formula", "description", "source"})
        if extra:
            raise RequirementError(f"{place}: {extra[0]}: unknown key")
        for key in ("formula", "description", "source"):
            if key in table and not isinstance(table[key], str):
                raise RequirementError(f"{place}: {key}: must be a string")
        if not table.get("formula", "").strip():
            raise RequirementError(f"{place}: formula: missing")
        found.append(
            StlRequirement(
                name,
                table["formula"],
                table.get("description", ""),
                table.get("source", ""),
                where=str(path),
                sampling_period=sampling_period,
            )
        )
    return tuple(found)


def requirements_of(
    names: Sequence[str], sampling_period: float = 0.2
) -> tuple[StlRequirement, ...]:
    """The requirements ``names`` say: a name of hazardhunt's library, a requirements file
    (every requirement in it), or ``FILE.toml:NAME`` (one of them).

    Raises:
        RequirementError: An unknown name, a file that cannot be read, two of one name.
    """
    library = {r.name: r for r in load_requirements(LIBRARY, sampling_period)}
    chosen: list[StlRequirement] = []
    for given in names:
        file, _, one = given.rpartition(":") if ".toml:" in given else (given, "", "")
        if file.endswith(".toml"):
            path = Path(file)
            read = load_requirements(path, sampling_period)
            if one:
                read = tuple(r for r in read if r.name == one)
                if not read:
                    raise RequirementError(f"{path}: requirements.{one}: no such requirement")
            chosen.extend(read)
        elif given in library:
            chosen.append(library[given])
        else:
            raise RequirementError(
                f"requirement {given!r}: not in hazardhunt's library ({', '.join(library)}) "
                "and not a .toml file"
            )
    seen: set[str] = set()
    for requirement in chosen:
        if requirement.name in seen:
            raise RequirementError(f"requirement {requirement.name!r}: named twice")
        seen.add(requirement.name)
    return tuple(chosen)


def episode_signals(
    samples: Sequence[TrajectorySample],
    emergency_deceleration: float,
    response_time: float,
    goal: tuple[float, float],
) -> dict[str, NDArray[np.float64]]:
    """An episode's :data:`SIGNALS` (and ``time``) from its trajectory.

    Args:
        samples: The episode at every control instant and at its end.
        emergency_deceleration: The robot's braking, in m/s^2.
        response_time: From a violation of the field to the brake, in s.
        goal: The robot's goal, in m.
    """

    def column(field: str) -> NDArray[np.float64]:
        return np.array([float(getattr(s, field)) for s in samples], dtype=np.float64)

    time = column("time")
    step = np.maximum(np.diff(time, prepend=time[:1] - 1.0), 1e-9)
    human_x, human_y = column("human_x"), column("human_y")
    moved = np.hypot(np.diff(human_x, prepend=human_x[:1]), np.diff(human_y, prepend=human_y[:1]))
    clearance = column("clearance")
    robot_speed = np.abs(column("robot_speed"))
    human_speed = moved / step
    stopping_time = robot_speed / emergency_deceleration
    stopping = robot_speed * response_time + robot_speed**2 / (2.0 * emergency_deceleration)
    return {
        "time": time,
        "clearance": clearance,
        "robot_speed": robot_speed,
        "human_speed": human_speed,
        "closing_speed": -np.diff(clearance, prepend=clearance[:1]) / step,
        "human_in_field": column("human_in_field"),
        "emergency_stop": column("emergency_stop"),
        "human_visible": column("human_visible"),
        "controller_ok": 1.0 - column("controller_failed"),
        "stopping_distance": stopping,
        "protective_separation": human_speed * (response_time + stopping_time) + stopping,
        "goal_distance": np.hypot(column("robot_x") - goal[0], column("robot_y") - goal[1]),
    }


def judged(requirements: Sequence[Requirement], signals: Signals) -> dict[str, Verdict]:
    """Every requirement's verdict on one episode.

    Raises:
        RequirementError: A requirement returned something but a Verdict with a finite
            robustness (a formula that takes the root of a negative number, say): an episode
            that cannot be judged must not pass as one that kept the requirement.
    """
    verdicts = {}
    for requirement in requirements:
        verdict = requirement.check(signals)
        if not isinstance(verdict, Verdict) or not math.isfinite(verdict.robustness):
            raise RequirementError(
                f"requirement {requirement.name!r}: check() must return a Verdict with a "
                f"finite robustness, not {verdict!r}"
            )
        verdicts[requirement.name] = verdict
    return verdicts
