"""A user's plug-in as configuration names it (an import path and keyword parameters), and how
each kind is built from it: controller, safety layer, tester and failure classifier.

Configuration only names plug-ins; nothing is imported while it is validated. They are built
where they are used (a run builds its own) and checked once where a campaign file or a command
line is read (:func:`hazardhunt.campaign.config.check_plugins`).

A plug-in is code, imported because the user named it: on the command line or in their own
campaign file. A plug-in named in a file hazardhunt reads back (a run's ``config.json``, a
regression case) is data: :func:`allowed_plugin` lets it be imported only when the user names it
again or trusts the file's plug-ins, and says which module is about to be imported. Its errors
never suggest the import path a file names as what to type: the user names their own. A module
that would be imported from a run, campaign, estimate or case folder (a ``.py`` that came with
results) is warned of first (:func:`warn_if_in_results`).
"""

from __future__ import annotations

import warnings
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
    module_folder,
)
from hazardhunt.sut.protocols import Controller, SafetyLayer
from hazardhunt.sut.safety_layer import FieldShape
from hazardhunt.testers.base import Tester
from hazardhunt.testers.registry import build_tester
from hazardhunt.textfiles import TOMLDecodeError, loads_toml, read_input_text
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


OWN_PLUGIN = "package.module:Class"
"""How an error shows the import path of one's own plug-in, in place of the one a file names."""

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
    plug-in: it takes the stored parameters (for a built-in controller whose parameters say
    what it runs, the ros2 bridge's node command, only with ``trust``). Either way the module
    is imported as a plug-in named on the command line is (the working directory, then
    ``sys.path``), never from a directory the file names or lies in. ``announce`` is told
    which module is about to be imported.

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
            if given.path in BUILT_IN_CONTROLLERS and not trust:
                # Its parameters say what it runs (the ros2 bridge's node command): code too.
                raise UntrustedPluginError(
                    f"{where}: names the controller {given.path} with parameters that say what "
                    "it starts (a command line), which hazardhunt does not run from a file it "
                    f"reads; give your own ({option} {given.path} {option}-param "
                    f"command=...), or, having read them, trust this file's plug-ins "
                    f"({TRUST_OPTION})"
                )
            given = given.model_copy(update={"params": dict(stored.params)})
        chosen, reason = given, f"{option} {given.path}"
    elif stored is None:
        return None
    elif trust:
        chosen = PluginSpec(path=stored.path, params=stored.params, search_path=[str(Path.cwd())])
        reason = f"{TRUST_OPTION}: {where} names {stored.path}"
    else:
        raise UntrustedPluginError(
            f"{where}: names the plug-in {shown_path(stored.path)}, code that hazardhunt does "
            "not import from a file it reads; to test with your own, name it "
            f"({option} {OWN_PLUGIN}), or, having read that code, trust this file's plug-ins "
            f"({TRUST_OPTION})"
        )
    warn_if_in_results(chosen, reason)
    if announce is not None:
        if chosen.path in BUILT_IN_CONTROLLERS:  # a built-in one runs what its parameters say
            announce(f"controller {chosen.path} with {chosen.params!r} ({reason})")
        else:
            announce(f"importing module {chosen.path.partition(':')[0]!r} ({reason})")
    return chosen


def shown_path(path: str) -> str:
    """An import path a file names, quoted and cut short, to say what it names (never as a
    command to type)."""
    return repr(path if len(path) <= 80 else path[:77] + "...")


CASE_KEYS = frozenset({"format", "expected", "human"})
"""Top-level tables and keys every regression case file has."""


def results_folder(directory: Path) -> str | None:
    """What kind of folder hazardhunt writes ``directory`` is (``a run folder``, ``a campaign
    folder``, ``an estimate folder``, ``a folder of regression cases``), None if none."""
    if (directory / "campaign.json").is_file():
        return "a campaign folder"
    if (directory / "config.json").is_file():
        if (directory / "batches").is_dir() or (directory / "estimate.json").is_file():
            return "an estimate folder"
        if (directory / "episodes.parquet").is_file() or (directory / "summary.json").is_file():
            return "a run folder"
    for path in sorted(directory.glob("*.toml"))[:20]:
        try:
            if set(loads_toml(read_input_text(path))) >= CASE_KEYS:
                return "a folder of regression cases"
        except (OSError, UnicodeDecodeError, TOMLDecodeError):
            continue
    return None


def warn_if_in_results(spec: PluginSpec, named_by: str) -> None:
    """Warn, in one line and before anything is imported, if the module of ``spec`` would be
    imported from a folder of results (a ``.py`` file that came with a run or a case, found
    because the working directory is that folder), rather than from the user's own code.

    Args:
        spec: The plug-in about to be imported.
        named_by: How the user named it, for the message (``--controller x:Y``).
    """
    if spec.path in BUILT_IN_CONTROLLERS:  # hazardhunt's own code, whatever the folder holds
        return
    folder = module_folder(spec.path, spec.search_path)
    kind = None if folder is None else results_folder(folder)
    if folder is not None and kind is not None:
        module = spec.path.partition(":")[0].partition(".")[0]
        warnings.warn(
            f"module {module!r} is imported from {folder}, {kind}: code that came with "
            f"results, not code of your own ({named_by})",
            stacklevel=3,
        )


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
