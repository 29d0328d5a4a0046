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

A case file is data: nothing it names is imported from it. A failure classifier plug-in that a
case names must be named again (``regress --classifier``); a controller or safety-layer plug-in
must be named again (``--controller``, ``--safety-layer``) or the case's plug-ins trusted
(``--trust-plugins``). The case's folder is never searched for modules.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import pandas as pd
import tomli_w
from pydantic import BaseModel, ConfigDict, Field, Strict, ValidationError

import hazardhunt
from hazardhunt.analysis.results import load_results
from hazardhunt.analysis.tables import representatives
from hazardhunt.campaign.config import EnvOptions, file_name
from hazardhunt.campaign.plugins import PluginSpec, allowed_plugin, make_classifier
from hazardhunt.campaign.replay import load_run_config
from hazardhunt.campaign.run import build_simulation
from hazardhunt.campaign.store import sut_error_of
from hazardhunt.errors import InputError
from hazardhunt.sut.plugins import PluginError
from hazardhunt.textfiles import loads_toml
from hazardhunt.world.scenario import (
    ScenarioError,
    format_validation_error,
    scenario_data,
    scenario_from_data,
)

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

CASE_FORMAT = 1
"""Version of the case file layout."""
VERDICTS = ("still fails", "changed", "error", "fixed")


class CaseError(InputError):
    """A case file that cannot be used; the message names the file and the key."""


class _CaseTable(BaseModel):
    # Every number of a case file is finite.
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class _CaseEnvironment(EnvOptions):
    """The episode's field setting and seed, beside the run's environment options."""

    field: str
    seed: int = 0
    # Required in a case, which replays with the options it was found with rather than with
    # today's defaults; EnvOptions checks their values when the options are built.
    decision_period: float
    episode_duration: float
    stall_duration: float

    def options(self) -> EnvOptions:
        """The run's environment options.

        Raises:
            ValidationError: An option's value is out of range.
        """
        return EnvOptions.model_validate(self.model_dump(exclude={"field", "seed"}))


class _CaseExpected(_CaseTable):
    failure_class: str = Field(alias="class")
    outcome: str = "failure"
    sim_time: float | None = None
    """When the failure happened, in s."""
    contact_face: str = ""


class _CasePlugin(_CaseTable):
    path: str
    """``package.module:Class``"""
    params: dict[str, Any] = {}


class _CaseSut(_CaseTable):
    controller: _CasePlugin | None = None
    safety_layer: _CasePlugin | None = None


_Number = Annotated[float, Strict()]
"""An int or a float, not a string or a boolean."""


class _CaseHuman(_CaseTable):
    actions: list[tuple[_Number, _Number]] = Field(min_length=1)
    """The human's actions, one [speed, turn] pair per decision, as the env takes them."""


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
    """The replayed failure's class, None without a failure."""
    sim_time: float
    verdict: str
    """One of ``VERDICTS``."""
    error: str | None = None
    """What the SUT raised, for the verdict ``error``."""


def export_cases(
    directory: Path,
    out: Path,
    *,
    every_failure: bool = False,
    classifier: PluginSpec | None = None,
) -> list[Path]:
    """Write regression cases for the failures of a run or campaign directory into ``out``.

    Args:
        directory: A run or campaign directory.
        out: The folder for the case files (created).
        every_failure: One case per failure, instead of one per failure class for each
            scenario and field setting (the class's representative: the failure whose time to
            contact is the class's median).
        classifier: Classify every failure anew with this failure classifier plug-in; without
            one, the classes the runs recorded count, and each case names the classifier its
            run recorded (read as data, not imported).

    Returns:
        The case files written, in a stable order.

    Raises:
        PluginError: ``classifier`` does not load.
    """
    results = load_results(directory, None if classifier is None else make_classifier(classifier))
    failures = results.failures
    if every_failure or failures.empty:
        chosen = failures
    else:
        groups = failures.groupby(["scenario", "field"], sort=True)
        chosen = pd.concat([representatives(group) for _, group in groups], ignore_index=True)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    configs: dict[str, Any] = {}
    for _, row in chosen.sort_values(["run_id", "episode"]).iterrows():
        run_id = str(row["run_id"])
        if run_id not in configs:
            configs[run_id] = load_run_config(results.run_directory(run_id))
        case = _case(row, configs[run_id], classifier or configs[run_id].classifier)
        path = out / f"{case['name']}.toml"
        if path.resolve().parent != out.resolve():  # file_name keeps it there; never write out
            raise CaseError(f"{case['name']!r}: not a case file name inside {out}")
        header = (
            f"# A failure hazardhunt found, as a regression case: {case['expected']['class']}\n"
            f"# Re-run it with: hazardhunt regress {path.name}\n"
        )
        path.write_text(header + tomli_w.dumps(case), encoding="utf-8")
        written.append(path)
    return written


def _case(row: pd.Series, config: Any, classifier: PluginSpec | None) -> dict[str, Any]:
    """The contents of one case file, its class given by ``classifier`` (None: the built-in
    one)."""
    failure_class = str(row.get("class", "other"))
    # The run id comes from a run's files, which anyone may have made: one safe file name.
    name = file_name(f"{row['run_id']}__episode{int(row['episode'])}")
    sut: dict[str, Any] = {}
    for key in ("controller", "safety_layer"):
        spec: PluginSpec | None = getattr(config, key)
        if spec is not None:
            sut[key] = _plugin_table(spec)
    actions = np.asarray(list(row["actions"]), dtype=np.float32).reshape(-1, 2)
    return {
        "format": CASE_FORMAT,
        "name": name,
        "description": (
            f"{failure_class}, found by {row['tester']} (seed {int(row['seed'])}) in run "
            f"{row['run_id']} in episode {int(row['episode'])}"
        ),
        "environment": {
            "field": str(row["field"]),
            "seed": int(row["seed"]),
            **config.env.model_dump(exclude_none=True),
        },
        "expected": {
            "outcome": str(row["outcome"]),
            "class": failure_class,
            "sim_time": float(row["sim_time"]),
            "contact_face": str(row.get("contact_face") or ""),
        },
        "found": {
            "run_id": str(row["run_id"]),
            "tester": str(row["tester"]),
            "episode": int(row["episode"]),
            "hazardhunt_version": hazardhunt.__version__,
        },
        **({} if classifier is None else {"classifier": _plugin_table(classifier)}),
        "sut": sut,
        "human": {"actions": [[float(a), float(b)] for a, b in actions]},
        "scenario": scenario_data(config.scenario),
    }


def _plugin_table(spec: PluginSpec) -> dict[str, Any]:
    """A plug-in as a case names it: where to find it is the reader's business."""
    return {"path": spec.path, "params": dict(spec.params)}


PYTEST_MODULE = '''"""hazardhunt's regression cases in this folder as tests: each passes once the
SUT no longer fails it (written by ``hazardhunt export --pytest``; run ``pytest`` here)."""

from pathlib import Path

import pytest

from hazardhunt.cases import case_files, regress_case
{classifier_import}
CASES = case_files(Path(__file__).parent)
CLASSIFIER = {classifier}
# True: the controller and safety-layer plug-ins the case files name are imported (as with
# regress --trust-plugins); False: a case that names one is an error.
TRUST_PLUGINS = {trust_plugins}


@pytest.mark.parametrize("case", CASES, ids=[case.stem for case in CASES])
def test_the_sut_no_longer_fails(case):
    result = regress_case(case, classifier=CLASSIFIER, trust_plugins=TRUST_PLUGINS)
    assert result.verdict == "fixed", (
        f"{{case.name}}: {{result.verdict}} ({{result.failure_class}} at {{result.sim_time:.2f}} s)"
    )
'''
"""The test module ``hazardhunt export --pytest`` writes next to the cases."""


def write_pytest_module(
    out: Path, classifier: PluginSpec | None = None, *, trust_plugins: bool = False
) -> Path:
    """Write ``test_hazardhunt_cases.py`` into the cases folder ``out``; its tests classify
    failures with ``classifier`` (found next to the module or in the working directory), or
    with the built-in classifier, and import the controller and safety-layer plug-ins the cases
    name only if ``trust_plugins`` (``TRUST_PLUGINS`` in the module)."""
    if classifier is None:
        source = PYTEST_MODULE.format(
            classifier_import="", classifier="None", trust_plugins=trust_plugins
        )
    else:
        source = PYTEST_MODULE.format(
            classifier_import="from hazardhunt.campaign.plugins import PluginSpec\n",
            classifier=(
                f"PluginSpec(\n    path={classifier.path!r},\n    params={classifier.params!r},\n"
                "    search_path=[str(Path(__file__).parent), str(Path.cwd())],\n)"
            ),
            trust_plugins=trust_plugins,
        )
    path = out / "test_hazardhunt_cases.py"
    path.write_text(source, encoding="utf-8")
    return path


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
) -> RegressionResult:
    """Re-run one case, against the given plug-ins and field setting instead of the case's.

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
    try:
        options = case.environment.options()
    except ValidationError as error:
        raise CaseError(f"{path}: environment.{format_validation_error(error)}") from None
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
    actions = np.asarray(case.human.actions, dtype=np.float32).reshape(-1, 2)
    result = simulation.simulate(actions)
    outcome = result.outcome or "unfinished"
    failure_class = None
    if outcome == "failure":
        chosen = own_classifier or make_classifier(None, simulation.robot_params)
        failure_class = chosen.classify(result.trajectory or (), result.summary, simulation.field)
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
    return RegressionResult(
        path.name, expected, outcome, failure_class, result.summary.sim_time, verdict, sut_error
    )


def _read_case(path: Path) -> _Case:
    try:
        data = loads_toml(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as error:
        raise CaseError(f"{path}: not valid TOML: {error}") from None
    except OSError as error:
        raise CaseError(f"{path}: cannot be read: {error.strerror}") from None
    # Checked first: a file of another layout would otherwise fail on whatever differs.
    if data.get("format") != CASE_FORMAT:
        raise CaseError(
            f"{path}: format: expected {CASE_FORMAT}, found {data.get('format')!r} "
            "(not a hazardhunt case, or one from another version)"
        )
    try:
        return _Case.model_validate(data)
    except ValidationError as error:
        raise CaseError(f"{path}: {_problem(error)}") from None


_IN_TOML_WORDS = {
    "missing": "missing",
    "model_type": "must be a table",
    "dict_type": "must be a table",
}
"""pydantic's messages that read better in a TOML file's words, by error type."""


def _problem(error: ValidationError) -> str:
    """The first problem as ``key: message`` (``format_validation_error``), in TOML's words."""
    first = error.errors()[0]
    problem = format_validation_error(error)
    if first["type"] in _IN_TOML_WORDS:
        problem = problem.replace(f": {first['msg']}", f": {_IN_TOML_WORDS[first['type']]}", 1)
    return problem


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
