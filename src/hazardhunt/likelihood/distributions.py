"""Named random variables with exact log-densities, read from data files.

A model of the people on the floor and the SUT's uncertainties are both products of independent
:class:`Dimension` s: a name and a one-dimensional distribution of ``scipy.stats`` (continuous
with a density, or discrete with a finite support). Independence is what lets the importance
samplers (:mod:`hazardhunt.likelihood.proposal`) tilt each dimension on its own and still
compute every episode's likelihood ratio exactly.

A distribution is written as a table, e.g. ``{ distribution = "truncnorm", mean = 1.34,
sd = 0.26, low = 0.5, high = 1.5 }``; :data:`FAMILIES` lists the families and their parameters.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from hazardhunt.errors import InputError


class DistributionError(InputError):
    """A distribution that cannot be used; the message names where it was written."""


FAMILIES: dict[str, tuple[str, ...]] = {
    "uniform": ("low", "high"),
    "normal": ("mean", "sd"),
    "truncnorm": ("mean", "sd", "low", "high"),
    "lognormal": ("median", "sigma"),
    "exponential": ("mean",),
    "bernoulli": ("p",),
    "categorical": ("weights",),
}
"""Every family of distribution a data file may name, with the parameters it takes (all
required): uniform on [low, high]; normal; normal truncated to [low, high]; log-normal by its
median and the standard deviation of its logarithm; exponential by its mean; Bernoulli (0 or 1,
1 with probability ``p``); categorical over 0, 1, ... with the given (unnormalised) weights."""


@dataclass(frozen=True)
class Dimension:
    """One random variable: its name, its distribution and how it was written."""

    name: str
    distribution: Any
    """A frozen ``scipy.stats`` distribution."""
    table: Mapping[str, Any]
    """The table it was read from (recorded with every estimate)."""

    @property
    def discrete(self) -> bool:
        """Whether it takes finitely many values (0, 1, ..., ``len(support) - 1``)."""
        return self.table["distribution"] in ("bernoulli", "categorical")

    @property
    def support(self) -> NDArray[np.float64]:
        """The values of a discrete dimension."""
        low, high = self.distribution.support()
        return np.arange(int(low), int(high) + 1, dtype=np.float64)

    def log_prob(self, value: float) -> float:
        """The log-density (continuous) or log-probability (discrete) of ``value``."""
        if self.discrete:
            return float(self.distribution.logpmf(value))
        return float(self.distribution.logpdf(value))


def dimension(where: str, name: str, table: Mapping[str, Any]) -> Dimension:
    """The dimension ``name`` written as ``table``.

    Raises:
        DistributionError: An unknown family, a missing, unknown or invalid parameter; the
            message starts with ``where`` and the name.
    """
    place = f"{where}: {name}"
    if not isinstance(table, Mapping):
        raise DistributionError(f"{place}: must be a table with a 'distribution' key")
    family = table.get("distribution")
    if family not in FAMILIES:
        raise DistributionError(
            f"{place}: distribution must be one of {', '.join(FAMILIES)}, not {family!r}"
        )
    wanted = FAMILIES[family]
    given = set(table) - {"distribution"}
    if missing := [key for key in wanted if key not in given]:
        raise DistributionError(f"{place}: {family} needs {', '.join(missing)}")
    if unknown := sorted(given - set(wanted)):
        raise DistributionError(
            f"{place}: {family} takes {', '.join(wanted)}, not {', '.join(unknown)}"
        )
    try:
        distribution = _frozen(family, table)
    except (TypeError, ValueError) as error:
        raise DistributionError(f"{place}: {error}") from None
    return Dimension(name, distribution, dict(table))


def _number(table: Mapping[str, Any], key: str) -> float:
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{key} must be a finite number, not {value!r}")
    return float(value)


def _positive(table: Mapping[str, Any], key: str) -> float:
    value = _number(table, key)
    if value <= 0:
        raise ValueError(f"{key} must be > 0, not {value!r}")
    return value


def _frozen(family: str, table: Mapping[str, Any]) -> Any:
    """The frozen ``scipy.stats`` distribution of a checked family."""
    if family == "uniform":
        low, high = _number(table, "low"), _number(table, "high")
        if not low < high:
            raise ValueError(f"low must be < high, not {low!r} and {high!r}")
        return stats.uniform(loc=low, scale=high - low)
    if family == "normal":
        return stats.norm(loc=_number(table, "mean"), scale=_positive(table, "sd"))
    if family == "truncnorm":
        mean, sd = _number(table, "mean"), _positive(table, "sd")
        low, high = _number(table, "low"), _number(table, "high")
        if not low < high:
            raise ValueError(f"low must be < high, not {low!r} and {high!r}")
        return stats.truncnorm((low - mean) / sd, (high - mean) / sd, loc=mean, scale=sd)
    if family == "lognormal":
        return stats.lognorm(s=_positive(table, "sigma"), scale=_positive(table, "median"))
    if family == "exponential":
        return stats.expon(scale=_positive(table, "mean"))
    if family == "bernoulli":
        p = _number(table, "p")
        if not 0.0 <= p <= 1.0:
            raise ValueError(f"p must be in [0, 1], not {p!r}")
        return stats.bernoulli(p)
    weights = table["weights"]
    if not isinstance(weights, Sequence) or isinstance(weights, str) or not weights:
        raise ValueError("weights must be a non-empty list of numbers")
    values = [_number({"weights": w}, "weights") for w in weights]
    if min(values) < 0 or sum(values) <= 0:
        raise ValueError("weights must be >= 0 and not all 0")
    shares = np.asarray(values) / sum(values)
    return stats.rv_discrete(values=(np.arange(len(shares)), shares))


def dimensions(where: str, tables: Mapping[str, Any]) -> tuple[Dimension, ...]:
    """Every ``name = {distribution = ...}`` of a table, in order."""
    return tuple(dimension(where, name, table) for name, table in tables.items())


def sample(dims: Sequence[Dimension], rng: np.random.Generator) -> dict[str, float]:
    """One draw of every dimension."""
    return {dim.name: float(dim.distribution.rvs(random_state=rng)) for dim in dims}


def log_prob(dims: Sequence[Dimension], values: Mapping[str, float]) -> float:
    """The joint log-density of independent ``dims`` at ``values`` (-inf outside the support)."""
    return sum((dim.log_prob(values[dim.name]) for dim in dims), 0.0)


def check_ranges(
    where: str, dims: Sequence[Dimension], ranges: Mapping[str, tuple[float, float]]
) -> None:
    """Check that every draw of each dimension named in ``ranges`` lies within its range: a
    value the simulation cannot play (it would clip or ignore it) would make the estimate one
    of another model than the file's.

    Raises:
        DistributionError: The first dimension whose distribution reaches outside its range.
    """
    for dim in dims:
        if dim.name not in ranges:
            continue
        low, high = (float(v) for v in dim.distribution.support())
        lowest, highest = ranges[dim.name]
        if low < lowest or high > highest:
            raise DistributionError(
                f"{where}: {dim.name}: its values must lie in [{lowest:g}, {highest:g}], but "
                f"the distribution reaches [{low:g}, {high:g}] (bound it: uniform, truncnorm)"
            )
