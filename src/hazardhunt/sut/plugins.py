"""Plug-ins loaded by import path (``package.module:Class``), and the SUT's two: a controller and a
safety layer.

The object named by the path is called with keyword parameters (a class, or any factory function)
and what it returns must satisfy a runtime-checkable protocol. :func:`build` does this for any
plug-in point; the caller names the protocol, so that the testers and the failure classifiers,
which live above the SUT, load through the same code. Every problem (a module that does not
import, a missing attribute, parameters the class does not take, an object that lacks a member)
is a :class:`PluginError` that names the path and what is wrong.

Loading a plug-in leaves ``sys.path`` as it was: the directories it may be found in are on it only
while its module is imported.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import math
import pkgutil
import sys
import warnings
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from hazardhunt.errors import PluginError as PluginError
from hazardhunt.sut.compat import ProtocolWarning, adapt_controller, adapt_safety_layer
from hazardhunt.sut.guard import is_plugin_fault
from hazardhunt.sut.protocols import Controller, SafetyLayer

MOVED_MODULES = {"hazardhunt.sut.conservative": "hazardhunt.benchmark.conservative"}
"""Built-in plug-in modules that moved, by their earlier name: a path naming the earlier one
still loads, with a warning."""


BUILT_IN_CONTROLLERS = {"ros2": "hazardhunt.sut.ros2.bridge:Ros2Controller"}
"""Controllers that ship with hazardhunt, by the name that stands for their import path
(``--controller ros2``, ``path = "ros2"`` in a campaign file's ``[controller]``)."""


def controller_path(name: str) -> str:
    """The import path of the built-in controller ``name``, else ``name`` itself."""
    return BUILT_IN_CONTROLLERS.get(name, name)


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
    if module_name in MOVED_MODULES:
        moved = f"{MOVED_MODULES[module_name]}:{attribute}"
        warnings.warn(
            f"{path!r} has moved to {moved!r} (CHANGELOG.md); loading it from there",
            ProtocolWarning,
            stacklevel=2,
        )
        module_name, path = MOVED_MODULES[module_name], moved
    with _importable_from(search_path):
        try:
            return pkgutil.resolve_name(path)
        except ImportError as error:
            raise PluginError(f"{path!r}: cannot import module {module_name!r}: {error}") from None
        except AttributeError as error:
            if module_name in sys.modules:  # the module imported; the name is missing
                raise PluginError(
                    f"{path!r}: module {module_name!r} has no attribute {attribute!r}"
                ) from None
            raise _import_raised(path, module_name, error) from error
        except BaseException as error:  # the module itself raised while importing
            if not is_plugin_fault(error):
                raise
            raise _import_raised(path, module_name, error) from error


def module_folder(path: str, search_path: Sequence[str] = ()) -> Path | None:
    """The directory the top-level module of the import path ``path`` would be imported from
    (the entry of ``search_path`` or ``sys.path`` that holds its file or package), found
    without importing anything; None if it is not found there, or is built into Python."""
    top = path.partition(":")[0].partition(".")[0]
    with _importable_from(search_path):
        try:
            spec = importlib.util.find_spec(top) if top else None
        except (ImportError, ValueError):
            return None
    if spec is None:
        return None
    if spec.submodule_search_locations:  # a package: the folder that holds its folder
        return Path(next(iter(spec.submodule_search_locations))).resolve().parent
    if spec.origin is None or not spec.has_location:
        return None
    return Path(spec.origin).resolve().parent


def _import_raised(path: str, module_name: str, error: BaseException) -> PluginError:
    return PluginError(
        f"{path!r}: importing module {module_name!r} raised {type(error).__name__}: {error}"
    )


@contextmanager
def _importable_from(directories: Sequence[str]) -> Iterator[None]:
    """Put ``directories`` first on ``sys.path`` for the duration, then restore it exactly."""
    saved = list(sys.path)
    sys.path[:0] = directories
    importlib.invalidate_caches()  # a module written since the last import is found
    try:
        yield
    finally:
        sys.path[:] = saved


def build(
    kind: str,
    path: str,
    params: Mapping[str, Any],
    protocol: type,
    search_path: Sequence[str] = (),
) -> Any:
    """Load ``path``, call it with ``params`` and check the result against ``protocol``.

    Args:
        kind: What the plug-in is, for messages (``"controller"``, ``"tester"``, ...).
        path: The import path of a class or factory.
        params: Its keyword parameters.
        protocol: A runtime-checkable ``typing.Protocol`` the result must satisfy.
        search_path: Directories to import from (see :func:`load_attribute`).

    Raises:
        PluginError: Naming the path and what is wrong.
    """
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
    except BaseException as error:  # SystemExit included
        if not is_plugin_fault(error):
            raise
        raise PluginError(
            f"{path!r}: building the {kind} raised {type(error).__name__}: {error}"
        ) from error
    check_protocol(path, plugin, protocol)
    return plugin


def check_protocol(path: str, plugin: object, protocol: type) -> None:
    """Raises PluginError, naming what ``plugin`` (built from ``path``) lacks, unless it is an
    instance of the runtime-checkable ``protocol`` whose methods are all callable."""
    members = protocol_members(protocol)
    methods = [name for name, is_method in members.items() if is_method]
    not_methods = [name for name in methods if not callable(getattr(plugin, name, None))]
    if isinstance(plugin, protocol) and not not_methods:
        return
    missing = [name for name in members if not hasattr(plugin, name)]
    if missing:
        problem = f"it lacks {', '.join(missing)}"
    elif not_methods:
        problem = f"{', '.join(not_methods)} must be methods"
    else:
        problem = "isinstance() says no"
    raise PluginError(
        f"{path!r} does not satisfy the {protocol.__name__} protocol: {problem} "
        "(see docs/plugins.md)"
    )


def protocol_members(protocol: type) -> dict[str, bool]:
    """The public members a protocol declares, in declaration order, each with whether it is a
    method (rather than an attribute or a property)."""
    members: dict[str, bool] = {}
    for cls in reversed(protocol.__mro__):
        if not vars(cls).get("_is_protocol", False):
            continue
        for name in getattr(cls, "__annotations__", {}):
            members.setdefault(name, False)
        for name, value in vars(cls).items():
            if not name.startswith("_"):
                members[name] = callable(value)
    return members


def build_controller(
    path: str, params: Mapping[str, Any] | None = None, search_path: Sequence[str] = ()
) -> Controller:
    """A user's controller (see :func:`build`), whose ``control_period`` is a positive number;
    one written for an earlier protocol is adapted (:mod:`hazardhunt.sut.compat`). A name of
    :data:`BUILT_IN_CONTROLLERS` builds that controller, whose own errors name what is wrong."""
    if path in BUILT_IN_CONTROLLERS:
        return _built_in_controller(path, params or {})
    controller: Controller = build("controller", path, params or {}, Controller, search_path)
    controller = adapt_controller(path, controller)
    period = controller.control_period
    if (
        isinstance(period, bool)
        or not isinstance(period, (int, float))
        or not (math.isfinite(period) and period > 0)
    ):
        raise PluginError(
            f"{path!r}: control_period must be a positive number of seconds, not {period!r}"
        )
    return controller


def build_safety_layer(
    path: str, params: Mapping[str, Any] | None = None, search_path: Sequence[str] = ()
) -> SafetyLayer:
    """A user's safety layer (see :func:`build`); one written for an earlier protocol is adapted
    (:mod:`hazardhunt.sut.compat`)."""
    layer: SafetyLayer = build("safety layer", path, params or {}, SafetyLayer, search_path)
    return adapt_safety_layer(path, layer)


def _built_in_controller(name: str, params: Mapping[str, Any]) -> Controller:
    """The built-in controller ``name`` (a key of :data:`BUILT_IN_CONTROLLERS`) with ``params``.

    Raises:
        PluginError: Parameters it does not take, or its own (a missing package, a bad value).
    """
    factory = load_attribute(BUILT_IN_CONTROLLERS[name])
    try:
        inspect.signature(factory).bind(**params)
    except TypeError as error:
        raise PluginError(f"{name}: does not take these parameters: {error}") from None
    controller: Controller = factory(**params)
    return controller
