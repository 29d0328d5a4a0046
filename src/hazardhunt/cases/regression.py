"""Failures as regression cases: export them from runs, re-run them against a changed SUT.

A case is one TOML file that needs nothing else: the scenario (with its map inlined), the
field setting, the environment's options, the SUT's configuration (the built-in NMPC or a
plug-in's import path and parameters), the human's action sequence, the seed, and the outcome
the run observed with its failure class (and the failure classifier, when not the built-in
one). Re-running a case plays the same actions against today's SUT (or one given instead) and
compares:

- ``still fails``: a failure of the same class;
- ``changed``: a failure of another class: it fails differently;
- ``error``: the SUT erred (``sut_error``: raised, hung, returned something unusable), so the
  case tested nothing: it is neither fixed nor failing, and ``regress`` exits with its own code;
- ``fixed``: none of these.

A run's violations of requirements beyond the contact rule (``violations.parquet``) are cases
too: the case holds the requirement's name and formula, the expected class is the requirement
and the signals that decided the violation, and re-running judges the episode by the formula
(``still fails`` while violated for the same signals, ``changed`` for others, ``fixed`` once
kept).

A case file is data: nothing it names is imported from it. A failure classifier plug-in that a
case names must be named again (``regress --classifier``); a controller or safety-layer plug-in
must be named again (``--controller``, ``--safety-layer``) or the case's plug-ins trusted
(``--trust-plugins``). The case's folder is never searched for modules.
"""

from __future__ import annotations

import sys
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, Strict, ValidationError, field_validator

from hazardhunt.campaign.config import EnvOptions, Seed
from hazardhunt.campaign.plugins import PluginSpec, allowed_plugin, make_classifier
from hazardhunt.campaign.simulations import build_simulation
from hazardhunt.campaign.store import sut_error_of
from hazardhunt.errors import InputError
from hazardhunt.sim.simulation import EpisodeResult, Simulation
from hazardhunt.spec.failure_classes import FailureClassifier
from hazardhunt.spec.outcomes import Outcome
from hazardhunt.spec.requirements import RequirementError, StlRequirement
from hazardhunt.sut.plugins import PluginError
from hazardhunt.testers.objective import violation_class
from hazardhunt.textfiles import format_validation_error, loads_toml
from hazardhunt.world.scenario import ScenarioError, scenario_from_data

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

CASE_FORMAT = 1
"""Version of the case file layout."""
VERDICTS = ("still fails", "changed", "error", "fixed")
OUTCOMES = tuple(outcome.value for outcome in Outcome)


class CaseError(InputError):
    """A case file that cannot be used; the message names the file and the key."""


_Number = Annotated[float, Strict()]
"""An int or a float, not a string or a boolean."""


class _CaseTable(BaseModel):
    # Every number of a case file is finite.
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class _CaseEnvironment(EnvOptions):
    """The episode's field setting and seed, beside the run's environment options."""

    field: str
    seed: Seed = 0
    # Required in a case, which replays with the options it was found with rather than with
    # today's defaults; EnvOptions checks their values when the options are built.
    decision_period: _Number
    episode_duration: _Number
    stall_duration: _Number

    def options(self) -> EnvOptions:
        """The run's environment options.

        Raises:
            ValidationError: An option's value is out of range.
        """
        return EnvOptions.model_validate(self.model_dump(exclude={"field", "seed"}))


class _CaseExpected(_CaseTable):
    failure_class: str = Field(alias="class")
    outcome: str = "failure"
    sim_time: Annotated[_Number, Field(ge=0)] | None = None
    """When the failure happened, in s."""
    contact_face: str = ""

    @field_validator("outcome")
    @classmethod
    def _known_outcome(cls, value: str) -> str:
        if value not in OUTCOMES:
            raise ValueError(f"unknown outcome {value!r}: use one of {', '.join(OUTCOMES)}")
        return value


class _CasePlugin(_CaseTable):
    path: str
    """``package.module:Class``"""
    params: dict[str, Any] = {}


class _CaseSut(_CaseTable):
    controller: _CasePlugin | None = None
    safety_layer: _CasePlugin | None = None


_Action = Annotated[float, Strict()]
"""A normalised speed or turn rate; one outside [-1, 1] is played clipped, with a warning
(:func:`_played_actions`)."""


class _CaseHuman(_CaseTable):
    actions: list[tuple[_Action, _Action]] = Field(min_length=1)
    """The human's actions, one [speed, turn] pair per decision, as the env takes them."""


class _CaseRequirement(_CaseTable):
    name: str = Field(min_length=1)
    formula: str = Field(min_length=1)
    """Signal temporal logic over hazardhunt's signals (``docs/requirements.md``): data,
    parsed by rtamt, never run as code."""
    description: str = ""


class _Case(_CaseTable):
    format: int
    name: str = ""
    description: str = ""
    environment: _CaseEnvironment
    expected: _CaseExpected
    found: dict[str, Any] = {}
    """Where the failure was found, for people; regress does not read it."""
    sut: _CaseSut = _CaseSut()
    classifier: _CasePlugin | None = None
    """The failure-classifier plug-in that named the expected class (None: the built-in
    one); regress never imports it from the file."""
    requirement: _CaseRequirement | None = None
    """For a violation case: the requirement the episode violated (the expected class is the
    requirement and the signals that explained the violation)."""
    human: _CaseHuman
    scenario: dict[str, Any]
    """A scenario file's contents with its map inlined (checked by ``scenario_from_data``)."""


@dataclass(frozen=True)
class RegressionResult:
    """What a case expected and what re-running it gave."""

    case: str
    """The case file's name."""
    expected_class: str
    outcome: str
    """The replayed episode's outcome (``failure``, ``goal``, ``stall``, ...)."""
    failure_class: str | None
    """The replayed failure's class (or violation's, for a case of a requirement), None
    without one."""
    sim_time: float
    """When the replayed episode failed (or first violated the case's requirement), else
    ended, in s."""
    verdict: str
    """One of ``VERDICTS``."""
    error: str | None = None
    """What the SUT raised, for the verdict ``error``."""


def case_files(path: Path) -> list[Path]:
    """The case files at ``path``: the file itself, or the ``*.toml`` files of a folder."""
    if path.is_file():
        return [path]
    if path.is_dir():
        files = sorted(path.glob("*.toml"))
        if files:
            return files
        raise CaseError(f"{path}: no case files (*.toml) in this folder")
    raise CaseError(f"{path}: no such file or folder")


def regress_case(
    path: Path,
    *,
    controller: PluginSpec | None = None,
    safety_layer: PluginSpec | None = None,
    field: str | None = None,
    classifier: PluginSpec | None = None,
    trust_plugins: bool = False,
    announce: Callable[[str], None] | None = None,
    controller_timeout: float | None = None,
) -> RegressionResult:
    """Re-run one case, against the given plug-ins, field setting and wall-clock limit on each
    call of the SUT (``controller_timeout``, in s) instead of the case's.

    Nothing the case file names is imported from it. Its controller and safety layer (when it
    names plug-ins) are imported only when given again (the same import path confirms the
    case's, with its parameters) or with ``trust_plugins``, and never from the case's folder;
    ``announce`` is told which module is about to be imported. The replayed failure is
    classified by ``classifier``, else by the built-in classifier; a case whose class came
    from a classifier plug-in needs it given.

    Raises:
        CaseError: The file is not a valid case, or it names a classifier plug-in that is not
            given.
        UntrustedPluginError: The case names a SUT plug-in that is neither given nor trusted;
            nothing has been imported.
        PluginError: A plug-in does not load.
    """
    case = _read_case(path)
    if classifier is None and case.classifier is not None:
        raise CaseError(
            f"{path}: classifier: the case was classified by the plug-in "
            f"{case.classifier.path!r}, which is not imported from a file; name it to re-run "
            "the case (regress --classifier)"
        )
    own_classifier = None if classifier is None else make_classifier(classifier)
    try:
        scenario = scenario_from_data(case.scenario, f"{path} [scenario]")
    except ScenarioError as error:
        raise CaseError(str(error)) from None
    options = _options(path, case, controller_timeout)
    controller = _allowed(path, case.sut, "controller", controller, trust_plugins, announce)
    safety_layer = _allowed(path, case.sut, "safety_layer", safety_layer, trust_plugins, announce)
    try:
        simulation = build_simulation(
            scenario, field or case.environment.field, options, controller, safety_layer
        )
    except ScenarioError as error:
        raise CaseError(f"{path}: environment: {error}") from None
    except ValueError as error:
        if isinstance(error, PluginError):
            raise
        raise CaseError(f"{path}: environment: {error}") from None
    if case.requirement is not None:
        simulation.requirements = (_requirement_of(path, case.requirement, simulation),)
    result = simulation.simulate(_played_actions(path, case))
    outcome = result.outcome or "unfinished"
    failure_class = _class_of(case, result, own_classifier, simulation)
    expected = case.expected.failure_class
    sut_error = None
    if outcome == "sut_error":
        verdict, sut_error = "error", sut_error_of(result.summary)
    elif failure_class == expected:
        verdict = "still fails"
    elif failure_class is not None:
        verdict = "changed"
    else:
        verdict = "fixed"
    at = result.summary.sim_time
    if case.requirement is not None and failure_class is not None:
        first = result.verdicts[case.requirement.name].time  # the violation's first instant
        at = at if first is None else first
    return RegressionResult(path.name, expected, outcome, failure_class, at, verdict, sut_error)


def _played_actions(path: Path, case: _Case) -> np.ndarray:
    """The case's actions; one outside [-1, 1] (the simulation clips it) is named in a warning:
    a case exported before export clipped them holds the values a searcher gave, played
    clipped as the episode was, while a hand-edited one may not mean what is played."""
    actions = np.asarray(case.human.actions, dtype=np.float32).reshape(-1, 2)
    outside = np.argwhere(np.abs(actions) > 1.0)
    if len(outside):
        decision, number = (int(i) for i in outside[0])
        more = f" and {len(outside) - 1} more" if len(outside) > 1 else ""
        warnings.warn(
            f"{path}: human.actions.{decision}.{number} ({actions[decision, number]:g}){more} "
            "lie outside [-1, 1]: played clipped to it, as every action is",
            RuntimeWarning,
            stacklevel=3,
        )
    return actions


def _options(path: Path, case: _Case, controller_timeout: float | None) -> EnvOptions:
    """The case's environment options, with ``controller_timeout`` instead of its own if given.

    Raises:
        CaseError: An option of the case is out of range.
    """
    try:
        options = case.environment.options()
    except ValidationError as error:
        raise CaseError(f"{path}: environment.{format_validation_error(error)}") from None
    if controller_timeout is None:
        return options
    return options.model_copy(update={"controller_timeout": controller_timeout})


def _class_of(
    case: _Case,
    result: EpisodeResult,
    classifier: FailureClassifier | None,
    simulation: Simulation,
) -> str | None:
    """The replayed episode's class: of its failure, classified by ``classifier`` (None: the
    built-in one), or of its violation of the case's requirement; None if neither."""
    if result.outcome == "sut_error":
        return None
    if case.requirement is not None:
        if not result.verdicts[case.requirement.name].violated:
            return None
        return violation_class(case.requirement.name, result)
    if result.outcome != "failure":
        return None
    chosen = classifier or make_classifier(None, simulation.robot_params)
    return chosen.classify(result.trajectory or (), result.summary, simulation.field)


def _requirement_of(
    path: Path, requirement: _CaseRequirement, simulation: Simulation
) -> StlRequirement:
    """The case's requirement, its formula parsed (not run: it is data)."""
    try:
        return StlRequirement(
            requirement.name,
            requirement.formula,
            requirement.description,
            where=f"{path} [requirement]",
            sampling_period=simulation.controller.control_period,
        )
    except RequirementError as error:
        raise CaseError(str(error)) from None


def _read_case(path: Path) -> _Case:
    try:
        data = loads_toml(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as error:
        raise CaseError(f"{path}: not valid TOML: {error}") from None
    except OSError as error:
        raise CaseError(f"{path}: cannot be read: {error.strerror}") from None
    except UnicodeDecodeError as error:
        raise CaseError(f"{path}: not a text file: {error.reason}") from None
    # Checked first: a file of another layout would otherwise fail on whatever differs.
    if data.get("format") != CASE_FORMAT:
        raise CaseError(
            f"{path}: format: expected {CASE_FORMAT}, found {data.get('format')!r} "
            "(not a hazardhunt case, or one from another version)"
        )
    try:
        return _Case.model_validate(data)
    except ValidationError as error:
        raise CaseError(f"{path}: {format_validation_error(error, _Case)}") from None


def _allowed(
    path: Path,
    sut: _CaseSut,
    key: str,
    given: PluginSpec | None,
    trust: bool,
    announce: Callable[[str], None] | None,
) -> PluginSpec | None:
    """The plug-in to use for the case's ``sut.<key>`` (see
    :func:`hazardhunt.campaign.plugins.allowed_plugin`)."""
    stored: _CasePlugin | None = getattr(sut, key)
    return allowed_plugin(
        None if stored is None else PluginSpec(path=stored.path, params=stored.params),
        given,
        where=f"{path}: sut.{key}",
        option=f"--{key.replace('_', '-')}",
        trust=trust,
        announce=announce,
    )
