"""A user's plug-in as configuration names it (an import path and keyword parameters), and how
each kind is built from it: controller, safety layer, tester and failure classifier.

Configuration only names plug-ins; nothing is imported while it is validated. They are built
where they are used (a run builds its own) and checked once where a campaign file or a command
line is read (:func:`hazardhunt.campaign.config.check_plugins`).

A plug-in is code, imported because the user named it: on the command line or in their own
campaign file. A plug-in named in a file hazardhunt reads back (a run's ``config.json``, a
regression case) is data: :func:`allowed_plugin` lets it be imported only when the user names it
again or trusts the file's plug-ins, and says which module is about to be imported.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

from pydantic import BaseModel, ConfigDict

from hazardhunt.errors import HazardhuntError
from hazardhunt.spec.episode import EpisodeSummary, TrajectorySample
from hazardhunt.spec.failure_classes import (
    FailureClassifier,
    MechanismClassifier,
    adapt_classifier,
)
from hazardhunt.sut.guard import is_plugin_fault, raised
from hazardhunt.sut.plugins import (
    BUILT_IN_CONTROLLERS,
    PluginError,
    build,
    build_controller,
    build_safety_layer,
)
from hazardhunt.sut.protocols import Controller, SafetyLayer
from hazardhunt.sut.safety_layer import FieldShape
from hazardhunt.testers.base import Tester
from hazardhunt.testers.registry import build_tester
from hazardhunt.world.bodies import RobotParams

T = TypeVar("T")


class PluginSpec(BaseModel):
    """A user's plug-in: an import path and its keyword parameters."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    path: str
    """``package.module:Class`` (or a factory function)."""
    params: dict[str, Any] = {}
    """Keyword parameters of the class."""
    search_path: list[str] = []
    """Directories the module is imported from besides ``sys.path``: the working directory for a
    plug-in named on the command line, plus the campaign file's directory for one named in a
    campaign file; never the directory of a file read back (see :func:`allowed_plugin`)."""


TRUST_OPTION = "--trust-plugins"
"""The command-line flag that lets ``replay`` and ``regress`` import the plug-ins a file names."""


class UntrustedPluginError(PluginError):
    """A file read back names a plug-in that the user has neither named again nor trusted."""


def allowed_plugin(
    stored: PluginSpec | None,
    given: PluginSpec | None,
    *,
    where: str,
    option: str,
    trust: bool = False,
    announce: Callable[[str], None] | None = None,
) -> PluginSpec | None:
    """The plug-in to import in place of one a file names: ``given`` (named by the user), else
    ``stored`` if ``trust``, else None when the file names none (the built-in one is used).

    ``given`` with the stored import path and no parameters of its own confirms the stored
    plug-in: it takes the stored parameters. Either way the module is imported as a plug-in
    named on the command line is (the working directory, then ``sys.path``), never from a
    directory the file names or lies in. ``announce`` is told which module is about to be
    imported.

    Args:
        stored: The plug-in the file names (data), None if it names none.
        given: The plug-in the user named for it (``option`` on the command line), or None.
        where: The file and key that name ``stored``, for messages (``case.toml: sut.controller``).
        option: The command-line option that names this plug-in (``--controller``).
        trust: The user allows the file's own plug-ins to be imported (``--trust-plugins``).
        announce: Called with one line naming the module, before anything is imported.

    Raises:
        UntrustedPluginError: ``stored`` is a plug-in, and neither ``given`` nor ``trust``.
    """
    if given is not None:
        if stored is not None and given.path == stored.path and not given.params:
            given = given.model_copy(update={"params": dict(stored.params)})
        chosen, reason = given, f"{option} {given.path}"
    elif stored is None:
        return None
    elif trust:
        chosen = PluginSpec(path=stored.path, params=stored.params, search_path=[str(Path.cwd())])
        reason = f"{TRUST_OPTION}: {where} names {stored.path}"
    else:
        raise UntrustedPluginError(
            f"{where}: names the plug-in {stored.path!r}, code that hazardhunt does not import "
            f"from a file it reads; to run it, name it ({option} {stored.path}) or trust this "
            f"file's plug-ins ({TRUST_OPTION})"
        )
    if announce is not None:
        if chosen.path in BUILT_IN_CONTROLLERS:  # a built-in one runs what its parameters say
            announce(f"controller {chosen.path} with {chosen.params!r} ({reason})")
        else:
            announce(f"importing module {chosen.path.partition(':')[0]!r} ({reason})")
    return chosen


def make_controller(spec: PluginSpec) -> Controller:
    """The controller ``spec`` names (see :func:`hazardhunt.sut.plugins.build_controller`)."""
    return build_controller(spec.path, spec.params, spec.search_path)


def make_safety_layer(spec: PluginSpec) -> SafetyLayer:
    """The safety layer ``spec`` names (see :func:`hazardhunt.sut.plugins.build_safety_layer`)."""
    return build_safety_layer(spec.path, spec.params, spec.search_path)


def make_plugin_tester(spec: PluginSpec, seed: int) -> Tester:
    """The tester ``spec`` names, for a run with ``seed`` (see
    :func:`hazardhunt.testers.registry.build_tester`)."""
    return build_tester(spec.path, seed, spec.params, spec.search_path)


def make_classifier(
    spec: PluginSpec | None, robot: RobotParams = RobotParams()
) -> FailureClassifier:
    """The failure classifier ``spec`` names, or without one the built-in
    :class:`~hazardhunt.spec.failure_classes.MechanismClassifier` for ``robot``.

    Raises:
        PluginError: The plug-in does not load or does not fit the FailureClassifier protocol
            (one written for the protocol before 0.2.0 is adapted).
    """
    if spec is None:
        return MechanismClassifier(robot=robot)
    classifier: FailureClassifier = build(
        "failure classifier", spec.path, spec.params, FailureClassifier, spec.search_path
    )
    return _Exitless(spec.path, adapt_classifier(spec.path, classifier))


class ClassifierExitError(HazardhuntError):
    """A classifier of one's own raised ``SystemExit`` or another ``BaseException`` that is no
    ``Exception`` (not the user's Ctrl-C); the message names it and where it raised."""


class _Exitless:
    """A classifier of one's own whose ``SystemExit`` (``GeneratorExit``, a ``KeyboardInterrupt``
    of its own, ...) is a :class:`ClassifierExitError`: what a run records as the failure's
    classifier error, and what ``report``, ``export`` and ``regress`` stop at in one line,
    where it would end the command silently. Its exceptions go through as they are."""

    def __init__(self, path: str, classifier: FailureClassifier) -> None:
        self.path = path
        self.classifier = classifier

    @property
    def name(self) -> str:
        return str(self.classifier.name)

    def classes_for(self, field: FieldShape) -> tuple[str, ...]:
        return self._call("classes_for()", self.classifier.classes_for, field)

    def classify(
        self, trajectory: Sequence[TrajectorySample], summary: EpisodeSummary, field: FieldShape
    ) -> str:
        return self._call("classify()", self.classifier.classify, trajectory, summary, field)

    def _call(self, call: str, method: Callable[..., T], *args: Any) -> T:
        try:
            return method(*args)
        except Exception:
            raise
        except BaseException as error:  # SystemExit, GeneratorExit, ...
            if not is_plugin_fault(error):
                raise
            raise ClassifierExitError(
                f"failure classifier {self.path!r}: {call} raised {raised(error)}"
            ) from error
