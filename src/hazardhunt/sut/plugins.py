"""A user's controller or safety layer, loaded by import path (``package.module:Class``).

The object named by the path is called with the keyword parameters of the run (a class, or any
factory function) and what it returns must satisfy the :class:`~hazardhunt.sut.protocols.
Controller` or :class:`~hazardhunt.sut.protocols.SafetyLayer` protocol. Every problem (a module
that does not import, a missing attribute, parameters the class does not take, an object that
lacks a method) is a :class:`PluginError` that names the path and what is wrong, raised when the
run or campaign is configured rather than in the middle of a campaign.
"""

from __future__ import annotations

import importlib
import inspect
import math
import sys
from collections.abc import Sequence
from typing import Any

from hazardhunt.sut.protocols import Controller, SafetyLayer


class PluginError(ValueError):
    """A plug-in that cannot be loaded or does not fit its protocol."""


REQUIRED = {
    "controller": (Controller, ("control_period", "reset", "control")),
    "safety layer": (SafetyLayer, ("reset", "update")),
}
"""Per plug-in kind its protocol and the members the protocol asks for."""


def load_attribute(path: str, search_path: Sequence[str] = ()) -> Any:
    """The object an import path ``module:attribute`` names.

    Args:
        path: ``package.module:Name`` (``Name`` may be dotted: ``module:Outer.Inner``).
        search_path: Directories to import from besides ``sys.path``, searched first.

    Raises:
        PluginError: The path is malformed, the module does not import or lacks the name.
    """
    module_name, separator, attribute = path.partition(":")
    if not separator or not module_name or not attribute:
        raise PluginError(f"{path!r} is not an import path of the form 'package.module:Name'")
    for directory in reversed(search_path):
        if directory not in sys.path:
            sys.path.insert(0, directory)
    try:
        module = importlib.import_module(module_name)
    except ImportError as error:
        raise PluginError(f"{path!r}: cannot import module {module_name!r}: {error}") from None
    except Exception as error:  # the module itself raised while importing
        raise PluginError(
            f"{path!r}: importing module {module_name!r} raised {type(error).__name__}: {error}"
        ) from error
    target: Any = module
    for part in attribute.split("."):
        if not hasattr(target, part):
            raise PluginError(f"{path!r}: module {module_name!r} has no attribute {attribute!r}")
        target = getattr(target, part)
    return target


def build(kind: str, path: str, params: dict[str, Any], search_path: Sequence[str] = ()) -> Any:
    """Load ``path``, call it with ``params`` and check the result against ``kind``'s protocol.

    Args:
        kind: ``"controller"`` or ``"safety layer"``.
        path: The import path of a class or factory.
        params: Its keyword parameters.
        search_path: Directories to import from (see :func:`load_attribute`).

    Raises:
        PluginError: Naming the path and what is wrong.
    """
    protocol, members = REQUIRED[kind]
    factory = load_attribute(path, search_path)
    if not callable(factory):
        raise PluginError(f"{path!r} is a {type(factory).__name__}, not a class or factory")
    try:
        inspect.signature(factory).bind(**params)
    except TypeError as error:
        raise PluginError(f"{path!r} does not take these parameters: {error}") from None
    except ValueError:  # no signature to check (a builtin): let the call decide
        pass
    try:
        plugin = factory(**params)
    except Exception as error:
        raise PluginError(
            f"{path!r}: building the {kind} raised {type(error).__name__}: {error}"
        ) from error
    # A runtime-checkable protocol checks exactly this: every member is present.
    missing = [name for name in members if not hasattr(plugin, name)]
    if missing:
        raise PluginError(
            f"{path!r} does not satisfy the {protocol.__name__} protocol: it lacks "
            f"{', '.join(missing)} (see docs/plugins.md)"
        )
    not_callable = [
        name for name in members if name != "control_period" and not callable(getattr(plugin, name))
    ]
    if not_callable:
        raise PluginError(
            f"{path!r} does not satisfy the {protocol.__name__} protocol: "
            f"{', '.join(not_callable)} must be methods"
        )
    if kind == "controller":
        period = getattr(plugin, "control_period", None)
        if (
            isinstance(period, bool)
            or not isinstance(period, (int, float))
            or not (math.isfinite(period) and period > 0)
        ):
            raise PluginError(
                f"{path!r}: control_period must be a positive number of seconds, not {period!r}"
            )
    return plugin


def build_controller(
    path: str, params: dict[str, Any] | None = None, search_path: Sequence[str] = ()
) -> Controller:
    """A user's controller (see :func:`build`)."""
    controller: Controller = build("controller", path, dict(params or {}), search_path)
    return controller


def build_safety_layer(
    path: str, params: dict[str, Any] | None = None, search_path: Sequence[str] = ()
) -> SafetyLayer:
    """A user's safety layer (see :func:`build`)."""
    layer: SafetyLayer = build("safety layer", path, dict(params or {}), search_path)
    return layer
