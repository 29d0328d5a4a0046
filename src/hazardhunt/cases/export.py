"""Exporting failures and requirements' violations as regression cases (the case file's
layout and how a case is re-run: :mod:`hazardhunt.cases.regression`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import tomli_w

import hazardhunt
from hazardhunt.analysis.results import load_results
from hazardhunt.analysis.tables import representatives
from hazardhunt.campaign.config import ConfigError, check_output_location, file_name
from hazardhunt.campaign.plugins import PluginSpec, make_classifier
from hazardhunt.campaign.replay import load_run_config
from hazardhunt.campaign.scenario_record import played_scenario_data
from hazardhunt.cases.regression import CASE_FORMAT, CaseError
from hazardhunt.file_writes import file_written


def export_cases(
    directory: Path,
    out: Path,
    *,
    every_failure: bool = False,
    classifier: PluginSpec | None = None,
) -> list[Path]:
    """Write regression cases for the failures of a run or campaign directory into ``out``,
    and for the violations of its requirements beyond the contact rule (one per requirement,
    deciding signals, scenario and field: the deepest).

    Args:
        directory: A run or campaign directory.
        out: The folder for the case files (created).
        every_failure: One case per failure and per violation, instead of one per failure
            class for each scenario and field setting (the class's representative: the
            failure whose time to contact is the class's median).
        classifier: Classify every failure anew with this failure classifier plug-in; without
            one, the classes the runs recorded count, and each case names the classifier its
            run recorded (read as data, not imported).

    Returns:
        The case files written, in a stable order, each once: cases whose names would be one
        file name (``a:b`` and ``a_b``, run ids that differ only in characters a file name
        cannot hold) get ``-2``, ``-3`` ... after the first.

    Raises:
        PluginError: ``classifier`` does not load.
        ConfigError: ``out`` cannot be made a folder or written in, or holds a run, campaign or
            estimate (nothing was written).
    """
    results = load_results(directory, None if classifier is None else make_classifier(classifier))
    failures = results.failures
    if every_failure or failures.empty:
        chosen = failures
    else:
        groups = failures.groupby(["scenario", "field"], sort=True)
        chosen = pd.concat([representatives(group) for _, group in groups], ignore_index=True)
    violations = results.violations
    if violations.empty:  # no requirements beyond the contact rule, or none violated
        violations = violations.reindex(columns=["run_id", "episode", "requirement"])
    elif not every_failure:
        worst = violations.sort_values(["robustness", "run_id", "episode"], kind="stable")
        violations = worst.drop_duplicates(["scenario", "field", "requirement", "signals"])
    check_output_location(out)
    _check_holds_no_results(out)
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    taken: set[str] = set()
    configs: dict[str, Any] = {}

    def config_of(run_id: str) -> Any:
        if run_id not in configs:
            directory = results.run_directory(run_id)
            config = load_run_config(directory)
            # The scenario the run played, which its file may no longer say.
            configs[run_id] = (config, played_scenario_data(directory, config.scenario))
        return configs[run_id]

    for _, row in chosen.sort_values(["run_id", "episode"]).iterrows():
        config, scenario = config_of(str(row["run_id"]))
        case = _case(row, config, scenario, classifier or config.classifier)
        written.append(_write_case(out, _named_apart(case, taken)))
    for _, row in violations.sort_values(["run_id", "episode", "requirement"]).iterrows():
        case = _violation_case(row, *config_of(str(row["run_id"])))
        written.append(_write_case(out, _named_apart(case, taken)))
    return written


RESULT_FILES = {"campaign.json": "a campaign", "estimate.json": "an estimate", "config.json": ""}
"""Files that mark a folder as results (a run's or estimate's ``config.json``), not cases."""


def _check_holds_no_results(out: Path) -> None:
    """Raises ConfigError if ``out`` is a run, campaign or estimate directory: cases written
    there would mix with its files (as every other command refuses such an ``--out``)."""
    for name, kind in RESULT_FILES.items():
        if (out / name).is_file():
            if not kind:
                kind = "an estimate" if (out / "batches").is_dir() else "a run"
            raise ConfigError(
                f"--out: {out} holds {kind} ({name}), not cases; choose another --out"
            )


def _named_apart(case: dict[str, Any], taken: set[str]) -> dict[str, Any]:
    """``case`` with a name no case written before it has (``taken``, which gets it): the
    first of names that are one file name keeps it, the next get ``-2``, ``-3`` ... (compared
    without case, as some file systems do)."""
    name, number = case["name"], 1
    while name.casefold() in taken:
        number += 1
        name = f"{case['name']}-{number}"
    taken.add(name.casefold())
    return {**case, "name": name}


def _write_case(out: Path, case: dict[str, Any]) -> Path:
    path = out / f"{case['name']}.toml"
    if path.resolve().parent != out.resolve():  # file_name keeps it there; never write out
        raise CaseError(f"{case['name']!r}: not a case file name inside {out}")
    what = "A failure" if "requirement" not in case else "A requirement's violation"
    header = (
        f"# {what} hazardhunt found, as a regression case: {case['expected']['class']}\n"
        f"# Re-run it with: hazardhunt regress {path.name}\n"
    )
    with file_written(path):
        path.write_text(header + tomli_w.dumps(case), encoding="utf-8")
    return path


def _case(
    row: pd.Series, config: Any, scenario: dict[str, Any], classifier: PluginSpec | None
) -> dict[str, Any]:
    """The contents of one failure's case file, its class given by ``classifier`` (None: the
    built-in one)."""
    failure_class = str(row.get("class", "other"))
    case = _episode_case(row, config, scenario, f"{row['run_id']}__episode{int(row['episode'])}")
    case["description"] = f"{failure_class}, {case['description']}"
    case["expected"] = {
        "outcome": str(row["outcome"]),
        "class": failure_class,
        "sim_time": float(row["sim_time"]),
        "contact_face": str(row.get("contact_face") or ""),
    }
    if classifier is not None:
        case["classifier"] = _plugin_table(classifier)
    return _in_order(case)


def _violation_case(row: pd.Series, config: Any, scenario: dict[str, Any]) -> dict[str, Any]:
    """The contents of the case file of one requirement's violation, the requirement's formula
    inlined."""
    requirement = str(row["requirement"])
    expected = f"{requirement}/{row['signals']}"
    case = _episode_case(
        row, config, scenario, f"{row['run_id']}__episode{int(row['episode'])}__{requirement}"
    )
    case["description"] = f"violates {expected}, {case['description']}"
    time = row["time"]
    case["expected"] = {
        "outcome": str(row["outcome"]),
        "class": expected,
        "sim_time": float(row["sim_time"] if pd.isna(time) else time),
    }
    case["requirement"] = {"name": requirement, "formula": str(row["formula"])}
    return _in_order(case)


CASE_KEYS = (
    "format",
    "name",
    "description",
    "environment",
    "expected",
    "requirement",
    "found",
    "classifier",
    "sut",
    "human",
    "scenario",
)
"""The order of a case file's keys."""


def _in_order(case: dict[str, Any]) -> dict[str, Any]:
    return {key: case[key] for key in CASE_KEYS if key in case}


def _episode_case(
    row: pd.Series, config: Any, scenario: dict[str, Any], name: str
) -> dict[str, Any]:
    """What every case file holds: where (``scenario``, its map inlined) and against what to
    play the episode, and how it was found."""
    sut: dict[str, Any] = {}
    for key in ("controller", "safety_layer"):
        spec: PluginSpec | None = getattr(config, key)
        if spec is not None:
            sut[key] = _plugin_table(spec)
    # As played: the simulation clips each action to [-1, 1], which a case file must hold.
    actions = np.clip(np.asarray(list(row["actions"]), dtype=np.float32).reshape(-1, 2), -1, 1)
    return {
        "format": CASE_FORMAT,
        # The run id comes from a run's files, which anyone may have made: one safe file name.
        "name": file_name(name),
        "description": (
            f"found by {row['tester']} (seed {int(row['seed'])}) in run {row['run_id']} in "
            f"episode {int(row['episode'])}"
        ),
        "environment": {
            "field": str(row["field"]),
            "seed": int(row["seed"]),
            **config.env.model_dump(exclude_none=True),
        },
        "found": {
            "run_id": str(row["run_id"]),
            "tester": str(row["tester"]),
            "episode": int(row["episode"]),
            "hazardhunt_version": hazardhunt.__version__,
        },
        "sut": sut,
        "human": {"actions": [[float(a), float(b)] for a, b in actions]},
        "scenario": scenario,
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
    with file_written(path):
        path.write_text(source, encoding="utf-8")
    return path
