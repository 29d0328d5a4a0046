"""Episode-level search as ask/tell: a sampler proposes episodes, one loop plays them.

A search method here is a :class:`Sampler`: ``ask()`` gives a batch of :class:`Plan` s,
``tell(plans, results)`` takes what they did. The loop that plays them, and its worker
processes, belong to :class:`SearchTester` and the
:class:`~hazardhunt.testers.evaluator.EpisodeEvaluator` (as pyribs leaves the evaluation loop
to its caller). A sampler's settings are a frozen :class:`SearchParams` model, validated once
when the tester is built and recorded as they were resolved (``tester/<method>.json``).

The vocabulary the samplers share: ``batch_size`` (episodes per batch), ``initial_spread``
(the sampling's spread at the start, decisions being in [-1, 1]), ``space``
(:class:`~hazardhunt.testers.spaces.SearchSpace`) and ``workers`` (processes that play a
batch). The names of earlier versions (``population``, ``initial_std``, ``sigma0``,
``min_std``, ``n_workers``, ``clear_path``, ``probes``) are still read.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Protocol, TypeVar, runtime_checkable

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from hazardhunt.sim.simulation import EpisodeResult, Simulation
from hazardhunt.testers.base import EpisodeRecorder, TesterParameterError
from hazardhunt.testers.evaluator import MAX_WORKER_PROCESSES, EpisodeEvaluator, Plan
from hazardhunt.testers.objective import CONTACT, Objective
from hazardhunt.testers.spaces import SearchSpace
from hazardhunt.textfiles import refused_value, schema_keys


@runtime_checkable
class Sampler(Protocol):
    """An episode-level search method in ask/tell form."""

    def ask(self) -> list[Plan]:
        """The next batch of episodes to play (at least one)."""
        ...

    def tell(self, plans: list[Plan], results: list[EpisodeResult]) -> None:
        """What the first ``len(results)`` of the plans asked for did (fewer than asked when
        the budget ends within the batch)."""
        ...

    def record(self) -> dict[str, Any]:
        """What the search did, beside its settings, for the run's record (e.g. restarts)."""
        ...


@runtime_checkable
class Observer(Protocol):
    """A sampler that also learns from episodes it did not ask for (in a portfolio, those of
    the other arms). Optional: a sampler without :meth:`observe` learns only from its own."""

    def observe(self, plans: list[Plan], results: list[EpisodeResult]) -> None:
        """What the first ``len(results)`` of the plans another sampler asked for did."""
        ...


RENAMED = {
    "population": "batch_size",
    "initial_std": "initial_spread",
    "sigma0": "initial_spread",
    "min_std": "min_spread",
    "n_workers": "workers",
}
"""Earlier names of the searchers' shared settings, and their names now."""

SPACE_FLAGS = {"clear_path": "detour", "probes": "plain_attacks"}
"""Earlier flat settings that are now part of ``space``."""


class SearchParams(BaseModel):
    """Settings every episode-level searcher has; each method's model adds its own."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)

    workers: int = Field(default=1, ge=1, le=MAX_WORKER_PROCESSES)
    """Processes that play each batch (1: in the run's own process)."""

    @model_validator(mode="before")
    @classmethod
    def _earlier_names(cls, data: Any) -> Any:
        """Reads the names of earlier versions (:data:`RENAMED`, :data:`SPACE_FLAGS`)."""
        if not isinstance(data, Mapping):
            return data
        data = dict(data)
        for old, new in RENAMED.items():
            if old in data and new in cls.model_fields:
                if new in data:
                    raise ValueError(f"{old}: is the earlier name of {new}: give only {new}")
                data[new] = data.pop(old)
        flags = {new: data.pop(old) for old, new in SPACE_FLAGS.items() if old in data}
        space = data.get("space", "open")
        if flags and "space" in cls.model_fields and isinstance(space, str | list | Mapping):
            space = dict(space) if isinstance(space, Mapping) else {"kind": space}
            data["space"] = {**space, **flags}
        else:
            # Refused as unknown, by the names the user gave.
            data.update({old: flags[new] for old, new in SPACE_FLAGS.items() if new in flags})
        return data


class SpaceParams(SearchParams):
    """The settings of a searcher over decision sequences."""

    space: SearchSpace = SearchSpace()
    """Where the search looks (:class:`~hazardhunt.testers.spaces.SearchSpace`)."""


ParamsT = TypeVar("ParamsT", bound=SearchParams)


def parse_params(tester: str, model: type[ParamsT], params: Mapping[str, Any]) -> ParamsT:
    """``params`` as ``model``.

    Raises:
        TesterParameterError: Naming the first parameter at fault and what is wrong with it.
    """
    try:
        return model.model_validate(dict(params))
    except ValidationError as error:
        first = error.errors()[0]
        location = [str(part) for part in first["loc"]]
        message = refused_value(first)
        key, separator, rest = message.partition(": ")
        if not location and separator and " " not in key:  # a check of several settings
            raise TesterParameterError(tester, key, rest) from None
        key = _as_given(".".join(location), params) or next(iter(params), "parameters")
        if first["type"] == "extra_forbidden":
            known = ", ".join(schema_keys(model, location[:-1]))
            problem = f"unknown parameter; the tester takes {known}"
            if len(location) > 1:
                problem = f"unknown setting of {'.'.join(location[:-1])}, which takes {known}"
            raise TesterParameterError(tester, key, problem) from None
        scalar = not isinstance(first["input"], dict | list)
        if first["type"] != "value_error" and ", not " not in message and scalar:  # a range
            message += f", not {first['input']!r}"
        raise TesterParameterError(tester, key, message) from None


def _as_given(key: str, params: Mapping[str, Any]) -> str:
    """``key`` as the user gave it: a setting given by its earlier name (:data:`RENAMED`,
    :data:`SPACE_FLAGS`) is named by that, with its name now."""
    earlier = {new: old for old, new in RENAMED.items() if old in params}
    earlier |= {f"space.{new}": old for old, new in SPACE_FLAGS.items() if old in params}
    for new, old in earlier.items():
        if key == new or key.startswith(f"{new}."):
            return f"{old} (now {key})"
    return key


@dataclass(frozen=True)
class SearchContext:
    """What a sampler learns about the episodes before it proposes any."""

    simulation: Simulation
    """The run's simulation: horizon, robot and human parameters, field (not for playing)."""
    seed: int
    """The run's seed."""
    objective: Objective = CONTACT
    """What the search looks for: unsafe contacts, or a requirement's violations."""

    @property
    def horizon(self) -> int:
        """Decisions in an episode that runs its full duration."""
        return self.simulation.horizon


SamplerFactory = Callable[[Any, SearchContext], Sampler]
"""Builds a sampler from its settings and the run's context."""


class SearchTester:
    """A :class:`~hazardhunt.testers.base.Tester` that drives a sampler: ask, play, tell."""

    params_model: ClassVar[type[SearchParams]] = SearchParams
    """The sampler's settings."""
    name: str = "search"

    def __init__(self, seed: int, **params: Any) -> None:
        """Args:
        seed: The run's seed.
        params: The sampler's settings (:attr:`params_model`).

        Raises:
            TesterParameterError: A setting unknown, of the wrong type or out of its range.
        """
        self.seed = seed
        self.params = parse_params(self.name, self.params_model, params)
        self.sampler: Sampler | None = None

    def make_sampler(self, context: SearchContext) -> Sampler:
        """The sampler of this method with :attr:`params`."""
        raise NotImplementedError

    def explore(self, env: EpisodeRecorder, episodes: int) -> None:
        context = SearchContext(env.simulation, self.seed, env.objective)
        sampler = self.sampler = self.make_sampler(context)
        with EpisodeEvaluator(env, self.params.workers) as evaluator:
            while env.episodes_done < episodes:
                plans = sampler.ask()
                if not plans:
                    raise RuntimeError(f"tester {self.name!r}: its sampler proposed no episode")
                results = evaluator.evaluate(plans[: episodes - env.episodes_done])
                sampler.tell(plans, results)

    def save(self, directory: Path) -> None:
        """The settings as resolved and what the search did (``<name>.json``)."""
        directory.mkdir(parents=True, exist_ok=True)
        done = {} if self.sampler is None else self.sampler.record()
        settings = {"tester": self.name, "seed": self.seed, **self.params.model_dump(), **done}
        (directory / f"{self.name}.json").write_text(json.dumps(settings, indent=2) + "\n")
