"""The models an estimate was played on, recorded with it: the SHA-256 of the model of people
(its file's contents, or a plug-in's source), of the SUT's uncertainties (its file's contents)
and of the scenario (its contents, map inlined), in the estimate's ``config.json``. An estimate
resumed or extended after one of them changed would mix two models in one result, so it is
refused; the report replays its most likely failures only on the models they were drawn from.
An estimate of a version that recorded none resumes on the files as they are now, as a run does
on a scenario file it recorded nothing of (:mod:`hazardhunt.campaign.scenario_record`).
"""

from __future__ import annotations

import contextlib
import hashlib
import inspect
import json
import os
import sys
import warnings
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from hazardhunt.errors import InputError
from hazardhunt.likelihood.people import DEFAULT_MODEL, ModelError
from hazardhunt.likelihood.uncertainty import DEFAULT_UNCERTAINTIES, NO_UNCERTAINTIES
from hazardhunt.sut.plugins import load_attribute
from hazardhunt.world.scenario import scenario_data

BUILT_IN_PEOPLE = "people.toml (built-in)"
BUILT_IN_UNCERTAINTIES = "uncertainties.toml (built-in)"


@dataclass(frozen=True)
class Models:
    """What an estimate's encounters are drawn from and played on, as its configuration names
    them: a scenario (built-in or file), a model of people (None, built-in, a file or a
    plug-in) and one of the uncertainties (None, built-in, ``none`` or a file)."""

    scenario: str
    people: str | None
    uncertainties: str | None

    def digests(self) -> dict[str, str]:
        """The SHA-256 of each, by option name (``scenario``, ``people``, ``uncertainties``;
        none for ``--uncertainties none``).

        Raises:
            InputError: A file does not read, or a plug-in does not import (PluginError).
        """
        digests = {
            "scenario": _scenario_digest(self.scenario),
            "people": _people_digest(self.people),
        }
        if self.uncertainties is None or self.uncertainties == DEFAULT_UNCERTAINTIES:
            digests["uncertainties"] = _built_in_digest("uncertainties.toml")
        elif self.uncertainties != NO_UNCERTAINTIES:
            digests["uncertainties"] = _file_digest(
                self.uncertainties, "the model of the uncertainties"
            )
        return digests

    def source(self, option: str) -> str:
        """What the model of ``option`` is read from, for a message: a file, a built-in file or
        a plug-in's import path."""
        if option == "scenario":
            return self.scenario
        if option == "people":
            return BUILT_IN_PEOPLE if self.people in (None, DEFAULT_MODEL) else str(self.people)
        if self.uncertainties in (None, DEFAULT_UNCERTAINTIES):
            return BUILT_IN_UNCERTAINTIES
        return str(self.uncertainties)


def models_recorded(
    directory: Path, recorded: dict[str, str] | None, models: Models, digests: dict[str, str]
) -> bool:
    """Whether the estimate in ``directory``, whose ``config.json`` records ``recorded``, was
    played on ``models`` (of ``digests``, :meth:`Models.digests`); False for one of a version
    that recorded none, which a warning says is taken to be (it resumes on them as they are
    now, as a run does on a scenario file it recorded nothing of, rather than throw away
    batches that were almost always played on the same files).

    Raises:
        InputError: A model it recorded has changed since, naming its file.
    """
    if recorded is None:
        warnings.warn(
            f"{directory / 'config.json'}: written by an earlier version, which recorded no "
            "digest of the scenario and the models its batches were played on: they are taken "
            "to be the files as they are now, and recorded from now on (if one changed since, "
            "choose another --out: the estimate would mix two models)",
            stacklevel=2,
        )
        return False
    changed = next(
        (key for key in (*recorded, *digests) if recorded.get(key) != digests.get(key)), None
    )
    if changed is None:
        return True
    raise InputError(
        f"{models.source(changed)}: changed since the batches in {directory} were played on "
        f"it (its SHA-256 is not the one config.json records for {changed}): resuming would "
        "mix two models in one estimate; restore it, or choose another --out for an estimate "
        "of it as it is now"
    )


def _people_digest(people: str | None) -> str:
    if people is None or people == DEFAULT_MODEL:
        return _built_in_digest("people.toml")
    if people.endswith(".toml"):
        return _file_digest(people, "the model of people")
    return _plugin_digest(people)


def _plugin_digest(path: str) -> str:
    """The SHA-256 of a plug-in's source: the file of the module its import path names and
    the file that defines what it names, when that is another."""
    named = load_attribute(path, [os.getcwd()])
    files = {getattr(sys.modules.get(path.partition(":")[0]), "__file__", None)}
    with contextlib.suppress(TypeError):  # a builtin, or an object: no source of its own
        files.add(inspect.getsourcefile(named))
    digest = hashlib.sha256(path.encode())
    for file in sorted(f for f in files if f):
        try:
            digest.update(Path(file).read_bytes())
        except OSError as error:
            raise ModelError(
                f"people model {path!r}: cannot read its source {file}: {error}"
            ) from None
    return digest.hexdigest()


def _scenario_digest(scenario: str) -> str:
    return hashlib.sha256(json.dumps(scenario_data(scenario), sort_keys=True).encode()).hexdigest()


def _built_in_digest(name: str) -> str:
    text = resources.files("hazardhunt.likelihood").joinpath(name).read_bytes()
    return hashlib.sha256(text).hexdigest()


def _file_digest(file: str, what: str) -> str:
    try:
        return hashlib.sha256(Path(file).read_bytes()).hexdigest()
    except OSError as error:
        raise ModelError(f"{file}: cannot read {what}: {error}") from None
