"""Plug-ins written for an earlier version of a protocol keep working.

A protocol method that gained a parameter still accepts implementations without it: the loader
looks at the method's signature, and one that takes the earlier parameters is wrapped so that
it is called with them, with one :class:`ProtocolWarning` that says what to add. A method that
takes neither is a one-line :class:`~hazardhunt.sut.plugins.PluginError` naming the signature
expected and since which version. ``CHANGELOG.md`` lists every change; this module and
:func:`hazardhunt.spec.failure_classes.adapt_classifier` implement them:

=================  ======================================  ===================================
method             since 0.2.0                             in 0.1.0
=================  ======================================  ===================================
Controller.reset   ``(floor, route, robot, params)``       ``(floor, route, robot)``
SafetyLayer.update ``(time, robot, human_position,         ``(robot, human_position, radius)``
                   radius)``
=================  ======================================  ===================================
"""

from __future__ import annotations

import inspect
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from hazardhunt.errors import PluginError
from hazardhunt.sut.protocols import (
    ControlCommand,
    Controller,
    FloatArray,
    RobotParams,
    RobotState,
    SafetyLayer,
    SafetyStatus,
    TrackedHuman,
)
from hazardhunt.sut.route import Route
from hazardhunt.world.floor import FloorMap

CURRENT_VERSION = "0.2.0"
"""The version whose protocols are the current ones."""


class ProtocolWarning(FutureWarning):
    """A plug-in implements an earlier version of its protocol: it works; the warning says what
    to add to silence it."""


def takes(method: Callable[..., Any], count: int) -> bool:
    """Whether ``method`` can be called with ``count`` positional arguments (True when Python
    cannot tell: a builtin without a signature)."""
    try:
        inspect.signature(method).bind(*([None] * count))
    except TypeError:
        return False
    except ValueError:
        return True
    return True


def parameter_names(method: Callable[..., Any]) -> tuple[str, ...]:
    """The names of ``method``'s parameters, ``self`` left out for a bound method."""
    try:
        return tuple(inspect.signature(method).parameters)
    except ValueError:
        return ()


def signature_of(method: Callable[..., Any]) -> str:
    """``method``'s signature as written, for messages."""
    try:
        return str(inspect.signature(method))
    except ValueError:
        return "(...)"


def warn_earlier(path: str, kind: str, method: str, earlier: str, current: str) -> None:
    """Warn, once per call site, that ``path`` implements ``method`` as before ``0.2.0``."""
    warnings.warn(
        f"{kind} {path!r}: {method}{earlier} is the protocol of hazardhunt 0.1.0; it keeps "
        f"working, called without the new parameters; since {CURRENT_VERSION} it is "
        f"{method}{current} (CHANGELOG.md)",
        ProtocolWarning,
        stacklevel=3,
    )


def mismatch(path: str, method: str, given: Callable[..., Any], expected: str) -> PluginError:
    """The one-line error of a method whose signature fits no version of its protocol."""
    return PluginError(
        f"{path!r}: {method}{signature_of(given)} does not fit the protocol: it must take "
        f"{expected} (docs/plugins.md)"
    )


class _ControllerBefore020:
    """A controller whose ``reset`` takes ``(floor, route, robot)``, as before 0.2.0."""

    def __init__(self, controller: Any) -> None:
        self.controller = controller
        self.control_period: float = controller.control_period

    def reset(self, floor: FloorMap, route: Route, robot: RobotState, params: RobotParams) -> None:
        self.controller.reset(floor, route, robot)

    def control(self, time: float, robot: RobotState, human: TrackedHuman | None) -> ControlCommand:
        command: ControlCommand = self.controller.control(time, robot, human)
        return command

    def __getattr__(self, name: str) -> Any:  # the controller's own attributes, for its users
        if name.startswith("__") or name == "controller":
            raise AttributeError(name)
        return getattr(self.controller, name)


class _SafetyLayerBefore020:
    """A safety layer whose ``update`` takes ``(robot, human_position, radius)``, as before
    0.2.0."""

    def __init__(self, layer: Any) -> None:
        self.layer = layer

    def reset(self) -> None:
        self.layer.reset()

    def update(
        self, time: float, robot: RobotState, human_position: FloatArray, radius: float
    ) -> SafetyStatus:
        status: SafetyStatus = self.layer.update(robot, human_position, radius)
        return status

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__") or name == "layer":
            raise AttributeError(name)
        return getattr(self.layer, name)


@dataclass(frozen=True)
class ProtocolChange:
    """A protocol method that gained parameters in ``since``."""

    kind: str
    """The plug-in point (``controller``, ``safety layer``)."""
    method: str
    now: tuple[str, ...]
    """Its parameters since ``since``."""
    before: tuple[str, ...]
    """Its parameters before."""
    since: str = CURRENT_VERSION

    def adapt(self, path: str, plugin: Any, earlier: Callable[[Any], Any]) -> Any:
        """``plugin`` itself if its method takes today's parameters; ``earlier(plugin)``, with
        a warning, if it takes the earlier ones.

        Raises:
            PluginError: It takes neither.
        """
        method = getattr(plugin, self.method)
        if takes(method, len(self.now)):
            return plugin
        now, before = _parameters(self.now), _parameters(self.before)
        if takes(method, len(self.before)):
            warn_earlier(path, self.kind, self.method, before, now)
            return earlier(plugin)
        raise mismatch(path, self.method, method, f"{now} (since {self.since}; before: {before})")


def _parameters(names: tuple[str, ...]) -> str:
    return f"({', '.join(names)})"


CONTROLLER_RESET = ProtocolChange(
    "controller", "reset", ("floor", "route", "robot", "params"), ("floor", "route", "robot")
)
SAFETY_LAYER_UPDATE = ProtocolChange(
    "safety layer",
    "update",
    ("time", "robot", "human_position", "radius"),
    ("robot", "human_position", "radius"),
)


def adapt_controller(path: str, controller: Controller) -> Controller:
    """``controller`` as the simulation calls it: itself, or wrapped if its ``reset`` is the
    one before 0.2.0.

    Raises:
        PluginError: ``reset`` or ``control`` takes parameters of no version of the protocol.
    """
    if not takes(controller.control, 3):
        raise mismatch(path, "control", controller.control, "(time, robot, human)")
    sense = getattr(controller, "sense_human", None)
    if sense is not None and not (callable(sense) and takes(sense, 3)):
        raise mismatch(path, "sense_human", sense, "(time, human_position, radius)")
    adapted: Controller = CONTROLLER_RESET.adapt(path, controller, _ControllerBefore020)
    return adapted


def adapt_safety_layer(path: str, layer: SafetyLayer) -> SafetyLayer:
    """``layer`` as the simulation calls it: itself, or wrapped if its ``update`` is the one
    before 0.2.0.

    Raises:
        PluginError: ``reset`` or ``update`` takes parameters of no version of the protocol.
    """
    if not takes(layer.reset, 0):
        raise mismatch(path, "reset", layer.reset, "no parameters")
    adapted: SafetyLayer = SAFETY_LAYER_UPDATE.adapt(path, layer, _SafetyLayerBefore020)
    return adapted
