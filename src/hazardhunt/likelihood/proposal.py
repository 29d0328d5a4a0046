"""Importance-sampling proposals over a model's independent dimensions, and their cross-entropy
update.

A proposal tilts each dimension on its own: a continuous one through a Beta distribution over
its model quantile ``u = F(x)`` (Beta(1, 1) is the model itself), a discrete one through new
probabilities of its values. It is mixed with the model (a *defensive* share, Hesterberg 1995),
so that every likelihood ratio is at most ``1 / defensive``:

    q(x) = defensive * p(x) + (1 - defensive) * p(x) * prod_i r_i(x_i)

with ``r_i`` the Beta density at ``F_i(x_i)`` or the ratio of the new and the model's
probability. The weight ``p(x) / q(x)`` is exact: both densities are normalised.

The cross-entropy method (Rubinstein and Kroese 2004; Kochenderfer et al., "Algorithms for
Validation", ch. 7) fits the tilts to the episodes whose score reached the current level,
each weighted by its likelihood ratio, by weighted moments, smoothed with the previous tilt;
a dimension whose fit does not pay for itself (an information criterion) keeps the model.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from hazardhunt.likelihood.distributions import Dimension

MIN_ELITES = 4.0
"""The effective number of elites a dimension's penalty assumes at least (one or two heavy
elites would otherwise cost nothing to fit)."""
EDGE = 1e-12
"""Quantiles are kept this far inside (0, 1)."""
MIN_SHAPE = 0.2
"""The smallest Beta shape parameter a fit may give (a sharper tilt is refused)."""
MAX_CONCENTRATION = 10.0
"""The largest sum of the Beta's shape parameters (how narrow a tilt may get)."""
MIN_PROBABILITY = 0.05
"""The smallest share a discrete value keeps in a fitted tilt."""
SPREAD = 0.1
"""The share of a continuous dimension's tilt that stays uniform over its quantiles, so that
no part of the model's range is left to the defensive mixture alone (a failure drawn far from
where the tilt points would otherwise weigh up to ``1 / defensive``)."""


@dataclass(frozen=True)
class Proposal:
    """A tilt of every dimension, mixed with the model."""

    dims: tuple[Dimension, ...]
    defensive: float = 1.0
    """The model's share of the mixture (1: the model itself)."""
    shapes: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    """The Beta shape parameters of each continuous dimension."""
    probabilities: Mapping[str, tuple[float, ...]] = field(default_factory=dict)
    """The probabilities of each discrete dimension's values."""

    @classmethod
    def model(cls, dims: Sequence[Dimension], defensive: float = 1.0) -> Proposal:
        """The model itself (no tilt), with ``defensive`` recorded for the fits to come."""
        shapes = {d.name: (1.0, 1.0) for d in dims if not d.discrete}
        probabilities = {
            d.name: tuple(float(p) for p in d.distribution.pmf(d.support))
            for d in dims
            if d.discrete
        }
        return cls(tuple(dims), defensive, shapes, probabilities)

    def sample(self, rng: np.random.Generator) -> dict[str, float]:
        """One draw: from the model with probability ``defensive``, else from the tilts."""
        from_model = rng.random() < self.defensive
        values = {}
        for dim in self.dims:
            if from_model:
                values[dim.name] = float(dim.distribution.rvs(random_state=rng))
            elif dim.discrete:
                shares = np.asarray(self.probabilities[dim.name])
                values[dim.name] = float(
                    dim.support[rng.choice(len(shares), p=shares / shares.sum())]
                )
            else:
                a, b = self.shapes[dim.name]
                draw = rng.random() if rng.random() < SPREAD else rng.beta(a, b)
                u = float(np.clip(draw, EDGE, 1.0 - EDGE))
                values[dim.name] = float(dim.distribution.ppf(u))
        return values

    def log_ratio(self, values: Mapping[str, float]) -> float:
        """``log prod_i r_i(x_i)``: the tilts' log-density relative to the model."""
        total = 0.0
        for dim in self.dims:
            value = values[dim.name]
            if dim.discrete:
                model = float(dim.distribution.pmf(value))
                index = int(np.searchsorted(dim.support, value))
                total += math.log(self.probabilities[dim.name][index]) - math.log(model)
            else:
                a, b = self.shapes[dim.name]
                if a == 1.0 and b == 1.0:
                    continue
                u = float(np.clip(dim.distribution.cdf(value), EDGE, 1.0 - EDGE))
                tilt = float(stats.beta.pdf(u, a, b))
                total += math.log(SPREAD + (1.0 - SPREAD) * tilt)
        return total

    def log_weight(self, values: Mapping[str, float]) -> float:
        """``log p(x) - log q(x)``: the episode's exact log likelihood ratio."""
        if self.defensive >= 1.0:
            return 0.0
        mixed = np.logaddexp(
            math.log(self.defensive), math.log1p(-self.defensive) + self.log_ratio(values)
        )
        return -float(mixed)

    def fitted(
        self,
        samples: Sequence[Mapping[str, float]],
        weights: NDArray[np.float64],
        smoothing: float,
        defensive: float,
        penalty: float = 0.0,
    ) -> Proposal:
        """The tilts fitted to the elite ``samples``, each weighted by its likelihood ratio,
        smoothed: ``smoothing`` * fit + (1 - ``smoothing``) * the current tilt.

        A dimension is tilted only where its fit explains the elites better than the model
        does by more than ``penalty`` times the Bayesian information criterion's price of its
        parameters (``k / 2 * log n``, ``n`` the elites' effective number, at least
        :data:`MIN_ELITES`); otherwise the fit is the model itself. A variable that does not
        matter would else follow the noise of a few heavy elites, and every such tilt
        multiplies the weights' variance."""
        w = np.asarray(weights, dtype=np.float64)
        w = w / w.sum()
        elites = 1.0 / float(np.sum(w**2))
        price = penalty * 0.5 * math.log(max(elites, MIN_ELITES))
        shapes, probabilities = dict(self.shapes), dict(self.probabilities)
        for dim in self.dims:
            column = np.array([s[dim.name] for s in samples], dtype=np.float64)
            if dim.discrete:
                index = np.searchsorted(dim.support, column)
                model = dim.distribution.pmf(dim.support)
                counts = np.bincount(index, weights=w, minlength=len(dim.support))
                # A value the model never takes stays out of the proposal.
                possible = model > 0
                counts = np.where(possible, np.maximum(counts, MIN_PROBABILITY), 0.0)
                fit = counts / counts.sum()
                gain = elites * float(w @ np.log(fit[index] / model[index]))
                if gain <= price * (int(possible.sum()) - 1):
                    fit = model / model.sum()
                old = np.asarray(self.probabilities[dim.name])
                new = smoothing * fit + (1.0 - smoothing) * old
                probabilities[dim.name] = tuple(float(p) for p in new / new.sum())
            else:
                u = np.clip(dim.distribution.cdf(column), EDGE, 1.0 - EDGE)
                a, b = _beta_moments(float(w @ u), float(w @ (u - w @ u) ** 2))
                tilt = SPREAD + (1.0 - SPREAD) * stats.beta.pdf(u, a, b)
                if elites * float(w @ np.log(tilt)) <= price * 2:
                    a, b = 1.0, 1.0
                old_a, old_b = self.shapes[dim.name]
                shapes[dim.name] = (
                    smoothing * a + (1.0 - smoothing) * old_a,
                    smoothing * b + (1.0 - smoothing) * old_b,
                )
        return Proposal(self.dims, defensive, shapes, probabilities)

    def record(self) -> dict[str, Any]:
        """The proposal as JSON data."""
        return {
            "defensive": self.defensive,
            "shapes": {name: list(ab) for name, ab in self.shapes.items()},
            "probabilities": {name: list(p) for name, p in self.probabilities.items()},
        }


def _beta_moments(mean: float, variance: float) -> tuple[float, float]:
    """The Beta with this mean and variance (method of moments), within the shape limits."""
    mean = min(max(mean, 1e-3), 1.0 - 1e-3)
    ceiling = mean * (1.0 - mean)
    variance = min(max(variance, 1e-9), 0.999 * ceiling)
    concentration = min(ceiling / variance - 1.0, MAX_CONCENTRATION)
    return max(mean * concentration, MIN_SHAPE), max((1.0 - mean) * concentration, MIN_SHAPE)
