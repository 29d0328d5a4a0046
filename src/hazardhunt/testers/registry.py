"""The testers hazardhunt knows by name, and testers of one's own loaded by import path.

Every built-in tester registers here with what the rest of hazardhunt needs to know about it: how
to build one, the reward it learns from, a line that describes it and the colour it has in every
figure. The command line, the configuration's checks and the report read this registry rather
than a list of names of their own.

A user's tester needs no registration: it is named by import path (``package.module:Class``)
and called as ``Class(seed=..., **params)``, like a built-in tester's factory. An import path
works in every worker process and on every Ray node, which a registration made at run time in
the user's own process would not reach.
"""

from __future__ import annotations

import inspect
import math
import zlib
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from hazardhunt.spec.rewards import RewardKind
from hazardhunt.sut.plugins import PluginError, build
from hazardhunt.testers.base import Tester, TesterParameterError
from hazardhunt.testers.cem import CrossEntropyTester
from hazardhunt.testers.portfolio import PortfolioTester
from hazardhunt.testers.qd import QualityDiversityTester
from hazardhunt.testers.random_sampling import RandomTester

TesterFactory = Callable[..., Tester]
"""Builds a tester: called as ``factory(seed=..., **params)``."""


@dataclass(frozen=True)
class RegisteredTester:
    """A tester known by name."""

    name: str
    factory: TesterFactory
    """Called as ``factory(seed=..., **params)`` with the run's seed and tester parameters."""
    reward: RewardKind
    """The reward the tester learns from (``acc`` or ``max``)."""
    description: str
    """One line for the command line's help and the documentation."""
    colour: str
    """Its colour in every figure (any matplotlib colour)."""


_REGISTRY: dict[str, RegisteredTester] = {}
TESTERS: Mapping[str, RegisteredTester] = MappingProxyType(_REGISTRY)
"""The registered testers by name, in the order they registered (the order of every table)."""

OTHER_COLOURS = ("#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#bcbd22", "#17becf")
"""Colours of testers that are not registered (plug-ins), chosen by name."""


def register_tester(
    name: str, factory: TesterFactory, *, reward: RewardKind, description: str, colour: str
) -> RegisteredTester:
    """Make a tester known by ``name``.

    Raises:
        ValueError: ``name`` is taken, or looks like an import path (contains ``:``).
    """
    if name in _REGISTRY:
        raise ValueError(f"a tester named {name!r} is already registered")
    if ":" in name or not name:
        raise ValueError(f"{name!r} cannot name a tester: a name is not empty and has no ':'")
    entry = RegisteredTester(name, factory, reward, description, colour)
    _REGISTRY[name] = entry
    return entry


def make_tester(name: str, seed: int, params: Mapping[str, Any] | None = None) -> Tester:
    """Build the registered tester ``name`` with keyword ``params``; or, when ``params`` has a
    ``method``, the registered tester ``method`` with the other parameters, a configuration of
    it named ``name`` (:func:`tester_method`).

    Raises:
        ValueError: ``name`` (or ``method``) is not registered.
        TesterParameterError: The tester does not take a parameter, or not its value.
    """
    method, params = tester_method(name, params or {})
    factory = _REGISTRY[method].factory
    check_parameter_types(method, factory, params)
    return factory(seed=seed, **params)


def tester_method(name: str, params: Mapping[str, Any]) -> tuple[str, dict[str, Any]]:
    """The registered tester a tester named ``name`` with ``params`` is, and its parameters.

    A configuration of a built-in tester is data, not code: ``[tester.cem-aim]`` with
    ``method = "cem"`` and cem's parameters (``--tester cem-aim --tester-param method=cem``
    on the command line) is cem with those parameters, named ``cem-aim`` in every table.

    Raises:
        ValueError: An unknown tester or method, or a configuration named like a built-in one.
        TesterParameterError: ``method`` is not a string.
    """
    params = dict(params)
    if "method" not in params:
        if name not in _REGISTRY:
            raise ValueError(
                f"unknown tester {name!r}: use one of {', '.join(_REGISTRY)}, or configure one "
                "of them under a name of your own with method = NAME"
            )
        return name, params
    method = params.pop("method")
    if not isinstance(method, str) or method not in _REGISTRY:
        raise TesterParameterError(
            name, "method", f"must be one of {', '.join(_REGISTRY)}, not {method!r}"
        )
    if name in _REGISTRY and name != method:
        raise TesterParameterError(
            name, "method", f"{name!r} is a built-in tester; name the configuration otherwise"
        )
    return method, params


def check_parameter_types(name: str, factory: TesterFactory, params: Mapping[str, Any]) -> None:
    """Raises :class:`TesterParameterError` unless ``factory`` takes every key of ``params``
    (but ``seed``, the run's), each value of the kind of the parameter's default: true or false
    for a flag, a whole number for an int, a finite number for a float, a string, a list of
    such. A factory that takes ``**params`` checks their names and values itself."""
    if "seed" in params:
        raise TesterParameterError(name, "seed", "is set by hazardhunt (the run's seed)")
    parameters = inspect.signature(factory).parameters
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters.values()):
        return
    named = {
        key: parameter.default
        for key, parameter in parameters.items()
        if key != "seed" and parameter.kind is not inspect.Parameter.VAR_POSITIONAL
    }
    for key, value in params.items():
        if key not in named:
            raise TesterParameterError(
                name, key, f"unknown parameter; the tester takes {', '.join(named) or 'none'}"
            )
        wanted = _kind_of(named[key])
        if wanted is not None and not _is_kind(value, named[key]):
            raise TesterParameterError(name, key, f"must be {wanted}, not {value!r}")


_KINDS: tuple[tuple[type, str, str], ...] = (
    (bool, "true or false", "true or false"),
    (int, "a whole number", "whole numbers"),
    (float, "a finite number", "finite numbers"),
    (str, "a string", "strings"),
)
"""Kinds of parameter defaults, first match wins (a bool is an int), and how a value of each is
called, alone and in a list."""


def _kind_of(default: object, plural: bool = False) -> str | None:
    """What a value standing for ``default`` must be, in words; None if anything goes."""
    for kind, one, many in _KINDS:
        if isinstance(default, kind):
            return many if plural else one
    if isinstance(default, (list, tuple)):
        entries = _kind_of(default[0], plural=True) if default else None
        return "a list" + (f" of {entries}" if entries else "")
    return None


def _is_kind(value: object, default: object) -> bool:
    if isinstance(default, bool) or isinstance(value, bool):
        return isinstance(default, bool) and isinstance(value, bool)
    if isinstance(default, int):
        return isinstance(value, int)
    if isinstance(default, float):
        return isinstance(value, (int, float)) and math.isfinite(value)
    if isinstance(default, str):
        return isinstance(value, str)
    if isinstance(default, (list, tuple)):
        return isinstance(value, (list, tuple)) and (
            not default or all(_is_kind(entry, default[0]) for entry in value)
        )
    return True


def build_tester(
    path: str, seed: int, params: Mapping[str, Any] | None = None, search_path: Sequence[str] = ()
) -> Tester:
    """A user's tester: ``Class(seed=seed, **params)`` for the class (or factory) at import path
    ``path``, checked against the :class:`~hazardhunt.testers.base.Tester` protocol.

    Raises:
        PluginError: Naming the path and what is wrong.
    """
    params = dict(params or {})
    if "seed" in params:
        raise PluginError(f"{path!r}: parameter 'seed' is set by hazardhunt (the run's seed)")
    tester: Tester = build("tester", path, {"seed": seed, **params}, Tester, search_path)
    return tester


def is_import_path(tester: str) -> bool:
    """Whether ``tester`` names a plug-in (``package.module:Class``) rather than a registered
    tester."""
    return ":" in tester


def sort_testers(names: Iterable[str]) -> list[str]:
    """``names`` without repeats: registered testers in registration order, then the others in
    alphabetical order."""
    distinct = set(names)
    return [n for n in _REGISTRY if n in distinct] + sorted(distinct - set(_REGISTRY))


def colour_of(name: str) -> str:
    """The colour of a tester in figures: its registered one, else one chosen by its name."""
    if name in _REGISTRY:
        return _REGISTRY[name].colour
    return OTHER_COLOURS[zlib.crc32(name.encode()) % len(OTHER_COLOURS)]


def _ppo(name: str, reward: RewardKind, **defaults: Any) -> TesterFactory:
    """The factory of a PPO tester; Stable-Baselines3 and torch load only when one is built."""

    def factory(seed: int, **params: Any) -> Tester:
        from hazardhunt.testers.ppo import PPOTester

        return PPOTester(name, reward, seed, defaults | params)

    return factory


register_tester(
    "random",
    RandomTester,
    reward="max",
    description="uniform random actions that keep the human clear of obstacles (the baseline)",
    colour="#7f7f7f",
)
register_tester(
    "ppo-acc",
    _ppo("ppo-acc", "acc"),
    reward="acc",
    description="PPO (Stable-Baselines3) learning from the risk accumulated over the episode",
    colour="#1f77b4",
)
register_tester(
    "ppo-max",
    _ppo("ppo-max", "max"),
    reward="max",
    description="PPO (Stable-Baselines3) learning from the episode's maximum risk",
    colour="#ff7f0e",
)
register_tester(
    "cem",
    CrossEntropyTester,
    reward="max",
    description="the cross-entropy method over whole action sequences, restarting away from "
    "the failure mechanisms it has found",
    colour="#2ca02c",
)
register_tester(
    "qd",
    QualityDiversityTester,
    reward="max",
    description="quality-diversity (pyribs CMA-ME) over an archive of failure descriptors",
    colour="#9467bd",
)
register_tester(
    "ppo-novelty",
    _ppo("ppo-novelty", "max", novelty=100.0),
    reward="max",
    description="PPO learning from the episode's maximum risk plus a bonus for failures unlike "
    "those found before (Corso et al. 2019)",
    colour="#8c564b",
)
register_tester(
    "portfolio",
    PortfolioTester,
    reward="max",
    description="the default: uniform sampling, cem and qd as arms, the budget moving to the "
    "arms that find new failure mechanisms",
    colour="#d62728",
)
