"""The SUT's uncertainties as distributions: a model that draws each episode's
:class:`~hazardhunt.sim.effects.SutEffects`.

A model of the uncertainties is a ``[effects]`` table of independent distributions, one per
effect it makes random (``uncertainties.toml``, shipped with hazardhunt, is the default);
effects it leaves out keep their nominal value.
"""

from __future__ import annotations

from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import Any

from hazardhunt.likelihood.distributions import (
    Dimension,
    DistributionError,
    check_ranges,
    dimensions,
)
from hazardhunt.likelihood.people import ModelError
from hazardhunt.sim.effects import SutEffects
from hazardhunt.textfiles import TOMLDecodeError, loads_toml, read_input_text

DEFAULT_UNCERTAINTIES = "default"
"""The name of the built-in model of the uncertainties (``uncertainties.toml``)."""
NO_UNCERTAINTIES = "none"
"""The name of the nominal SUT: no random effects."""


class Uncertainties:
    """Independent distributions of some of the SUT's effects."""

    def __init__(self, dims: tuple[Dimension, ...] = (), source: str = NO_UNCERTAINTIES) -> None:
        self.dimensions = dims
        self.source = source

    def effects(self, values: Mapping[str, float], seed: int) -> SutEffects:
        """The effects of one episode: the drawn ``values`` of this model's dimensions."""
        return SutEffects(
            **{dim.name: float(values[dim.name]) for dim in self.dimensions}, seed=seed
        )


def load_uncertainties(spec: str | Path | None) -> Uncertainties:
    """The model of the uncertainties ``spec`` names: None or ``default`` for the built-in one,
    ``none`` for the nominal SUT, else a TOML file with an ``[effects]`` table.

    Raises:
        ModelError: The file does not read, names an unknown effect or an invalid distribution.
    """
    if spec is not None and str(spec) == NO_UNCERTAINTIES:
        return Uncertainties()
    if spec is None or str(spec) == DEFAULT_UNCERTAINTIES:
        where = "uncertainties.toml (built-in)"
        text = resources.files("hazardhunt.likelihood").joinpath("uncertainties.toml").read_text()
    else:
        where = str(spec)
        try:
            text = read_input_text(Path(spec))
        except (OSError, UnicodeDecodeError) as error:
            raise ModelError(
                f"{where}: cannot read the model of the uncertainties: {error}"
            ) from None
    try:
        data: dict[str, Any] = loads_toml(text)
    except TOMLDecodeError as error:
        raise ModelError(f"{where}: not valid TOML: {error}") from None
    if set(data) != {"effects"} or not isinstance(data["effects"], Mapping):
        raise ModelError(f"{where}: must hold exactly one table, [effects]")
    known = SutEffects.names()
    if unknown := sorted(set(data["effects"]) - set(known)):
        raise ModelError(
            f"{where}: effects: unknown {', '.join(unknown)} (known: {', '.join(known)})"
        )
    try:
        dims = dimensions(f"{where}: effects", data["effects"])
        check_ranges(f"{where}: effects", dims, EFFECT_RANGES)
    except DistributionError as error:
        raise ModelError(str(error)) from None
    for dim in dims:
        if dim.name == "brake_deceleration" and float(dim.distribution.support()[0]) <= 0:
            raise ModelError(
                f"{where}: effects: brake_deceleration: its values must lie above 0, but the "
                "distribution reaches 0 (bound it: uniform, truncnorm)"
            )
    return Uncertainties(dims, where)


EFFECT_RANGES = {
    "tracking_noise": (0.0, 10.0),
    "tracking_latency": (0.0, 10.0),
    "dropped_frames": (0.0, 1.0),
    "response_time": (0.0, 10.0),
    "brake_deceleration": (0.0, 100.0),
}
"""The values each effect may take (m, s, probability, s, m/s^2): a distribution must stay
within them, so that every draw is an effect the simulation can play."""
