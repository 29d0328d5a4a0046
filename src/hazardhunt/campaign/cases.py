"""Failures as regression cases: export them from runs, re-run them against a changed SUT.

A case is one TOML file that needs nothing else: the scenario (with its map inlined), the
field setting, the environment's options, the SUT's configuration (the built-in NMPC or a
plug-in's import path and parameters), the human's action sequence, the seed, and the outcome
the run observed with its failure class (and the failure classifier, when not the built-in
one). Re-running a case plays the same actions against today's SUT (or one given instead) and
compares:

- ``still fails``: a failure of the same class;
- ``changed``: a failure of another class, or the SUT erred (``sut_error``): it fails
  differently;
- ``fixed``: neither.

A failure classifier plug-in that a case names is not imported from the file: re-running such
a case needs the classifier named again (``regress --classifier``).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from pydantic import ValidationError

import hazardhunt
from hazardhunt.analysis.results import load_results
from hazardhunt.analysis.tables import representatives
from hazardhunt.campaign.config import EnvOptions
from hazardhunt.campaign.plugins import PluginSpec, make_classifier
from hazardhunt.campaign.replay import load_run_config, play
from hazardhunt.campaign.run import build_env
from hazardhunt.campaign.toml_writer import dumps
from hazardhunt.sut.plugins import PluginError
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

_ENV_OPTIONS = ("decision_period", "solver", "episode_duration", "stall_duration")
"""The keys of a case's ``environment`` that are the run's environment options."""
CASE_FORMAT = 1
"""Version of the case file layout."""
VERDICTS = ("still fails", "changed", "fixed")


class CaseError(ValueError):
    """A case file that cannot be used; the message names the file and the key."""


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
    for _, row in chosen.sort_values(["run_id", "failure_id"]).iterrows():
        run_id = str(row["run_id"])
        if run_id not in configs:
            configs[run_id] = load_run_config(results.run_directory(run_id))[0]
        case = _case(row, configs[run_id], classifier or configs[run_id].classifier)
        path = out / f"{case['name']}.toml"
        header = (
            f"# A failure hazardhunt found, as a regression case: {case['expected']['class']}\n"
            f"# Re-run it with: hazardhunt regress {path.name}\n"
        )
        path.write_text(dumps(case, header), encoding="utf-8")
        written.append(path)
    return written


def _case(row: pd.Series, config: Any, classifier: PluginSpec | None) -> dict[str, Any]:
    """The contents of one case file, its class given by ``classifier`` (None: the built-in
    one)."""
    failure_class = str(row.get("class", "other"))
    name = f"{row['run_id']}__failure{int(row['failure_id'])}"
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
            f"{row['run_id']} as failure {int(row['failure_id'])}"
        ),
        "environment": {
            "field": str(row["field"]),
            "seed": int(row["seed"]),
            **config.env.model_dump(),
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
            "failure_id": int(row["failure_id"]),
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

from hazardhunt.campaign.cases import case_files, regress_case
{classifier_import}
CASES = case_files(Path(__file__).parent)
CLASSIFIER = {classifier}


@pytest.mark.parametrize("case", CASES, ids=[case.stem for case in CASES])
def test_the_sut_no_longer_fails(case):
    result = regress_case(case, classifier=CLASSIFIER)
    assert result.verdict == "fixed", (
        f"{{case.name}}: {{result.verdict}} ({{result.failure_class}} at {{result.sim_time:.2f}} s)"
    )
'''
"""The test module ``hazardhunt export --pytest`` writes next to the cases."""


def write_pytest_module(out: Path, classifier: PluginSpec | None = None) -> Path:
    """Write ``test_hazardhunt_cases.py`` into the cases folder ``out``; its tests classify
    failures with ``classifier`` (found next to the module or in the working directory), or
    with the built-in classifier."""
    if classifier is None:
        source = PYTEST_MODULE.format(classifier_import="", classifier="None")
    else:
        source = PYTEST_MODULE.format(
            classifier_import="from hazardhunt.campaign.plugins import PluginSpec\n",
            classifier=(
                f"PluginSpec(\n    path={classifier.path!r},\n    params={classifier.params!r},\n"
                "    search_path=[str(Path(__file__).parent), str(Path.cwd())],\n)"
            ),
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
) -> RegressionResult:
    """Re-run one case, against the given plug-ins and field setting instead of the case's.

    The replayed failure is classified by ``classifier``, else by the built-in classifier. A
    case whose class came from a classifier plug-in needs it given as ``classifier``: an import
    path read from the case file is not imported.

    Raises:
        CaseError: The file is not a valid case, or it names a classifier plug-in that is not
            given.
        PluginError: A plug-in does not load.
    """
    case = _read_case(path)
    if classifier is None and "classifier" in case:
        named = case["classifier"].get("path") if isinstance(case["classifier"], dict) else None
        raise CaseError(
            f"{path}: classifier: the case was classified by the plug-in {named!r}, which is not "
            "imported from a file; name it to re-run the case (regress --classifier)"
        )
    own_classifier = None if classifier is None else make_classifier(classifier)
    environment = case["environment"]
    try:
        scenario = scenario_from_data(case["scenario"], f"{path} [scenario]")
    except ScenarioError as error:
        raise CaseError(str(error)) from None
    sut = case.get("sut", {})
    controller = controller or _spec(path, sut, "controller")
    safety_layer = safety_layer or _spec(path, sut, "safety_layer")
    try:
        options = EnvOptions.model_validate(
            {key: environment[key] for key in _ENV_OPTIONS if key in environment}
        )
    except ValidationError as error:
        raise CaseError(f"{path}: environment.{format_validation_error(error)}") from None
    try:
        env = build_env(
            scenario, field or environment["field"], options, "max", controller, safety_layer
        )
    except ScenarioError as error:
        raise CaseError(f"{path}: environment: {error}") from None
    except ValueError as error:
        if isinstance(error, PluginError):
            raise
        raise CaseError(f"{path}: environment: {error}") from None
    info = play(env, environment["seed"], case["human"]["actions"])
    outcome = info["outcome"] or "unfinished"
    failure_class = None
    if outcome == "failure":
        chosen = own_classifier or make_classifier(None, env.robot_params)
        failure_class = chosen.classify(env.trajectory(), info["summary"], env.field_diameter)
    expected = case["expected"]["class"]
    if failure_class == expected:
        verdict = "still fails"
    elif failure_class is not None or outcome == "sut_error":
        verdict = "changed"
    else:
        verdict = "fixed"
    return RegressionResult(
        path.name, expected, outcome, failure_class, float(info["sim_time"]), verdict
    )


def _read_case(path: Path) -> dict[str, Any]:
    try:
        case = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as error:
        raise CaseError(f"{path}: not valid TOML: {error}") from None
    except OSError as error:
        raise CaseError(f"{path}: cannot be read: {error.strerror}") from None
    if case.get("format") != CASE_FORMAT:
        raise CaseError(
            f"{path}: format: expected {CASE_FORMAT}, found {case.get('format')!r} "
            "(not a hazardhunt case, or one from another version)"
        )
    required = {
        "environment": ("field", "decision_period", "episode_duration", "stall_duration"),
        "expected": ("class",),
        "human": ("actions",),
    }
    for table, keys in required.items():
        if not isinstance(case.get(table), dict):
            raise CaseError(f"{path}: {table}: missing table")
        for key in keys:
            if key not in case[table]:
                raise CaseError(f"{path}: {table}.{key}: missing")
    if not isinstance(case.get("scenario"), dict):
        raise CaseError(f"{path}: scenario: missing table")
    actions = case["human"]["actions"]
    if not (
        isinstance(actions, list)
        and actions
        and all(
            isinstance(a, list)
            and len(a) == 2
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in a)
            for a in actions
        )
    ):
        raise CaseError(f"{path}: human.actions: must be a non-empty list of [speed, turn] pairs")
    case["environment"].setdefault("seed", 0)
    return case


def _spec(path: Path, sut: dict[str, Any], key: str) -> PluginSpec | None:
    """The case's own plug-in, importable from the case's folder or the working directory."""
    entry = sut.get(key)
    if entry is None:
        return None
    if not isinstance(entry, dict) or "path" not in entry:
        raise CaseError(f"{path}: sut.{key}: needs a path = 'package.module:Class'")
    return PluginSpec(
        path=entry["path"],
        params=entry.get("params", {}),
        search_path=[str(path.parent.resolve()), str(Path.cwd())],
    )
