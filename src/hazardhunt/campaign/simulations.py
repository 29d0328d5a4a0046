"""The simulation a run's settings describe, its SUT built from the built-in parts or the
user's plug-ins, and the trial episode that checks those plug-ins before a run starts."""

from __future__ import annotations

from collections.abc import Sequence

from hazardhunt.campaign.config import ConfigError, EnvOptions, RunConfig
from hazardhunt.campaign.plugins import PluginSpec, make_controller, make_safety_layer
from hazardhunt.campaign.trial import try_plugins
from hazardhunt.sim.simulation import PeriodError, Simulation
from hazardhunt.spec.requirements import requirements_of
from hazardhunt.world.scenario import Scenario


def build_simulation(
    scenario: str | Scenario,
    field: str,
    options: EnvOptions,
    controller: PluginSpec | None = None,
    safety_layer: PluginSpec | None = None,
    requirements: Sequence[str] = (),
) -> Simulation:
    """The simulation a run's settings describe: the built-in SUT unless plug-ins are given,
    judging each episode by ``requirements`` too (names of the library's or files,
    :func:`~hazardhunt.spec.requirements.requirements_of`).

    Raises:
        PluginError: A plug-in does not load.
        ConfigError: The periods do not fit (a decision period that is not a multiple of the
            controller's, a controller period that is not a multiple of the physics step).
    """
    try:
        simulation = Simulation.build(
            scenario,
            field,
            options.settings(),
            controller=None if controller is None else make_controller(controller),
            safety_layer=None if safety_layer is None else make_safety_layer(safety_layer),
        )
    except PeriodError as error:
        raise ConfigError(str(error)) from None
    if requirements:
        period = simulation.controller.control_period
        simulation.requirements = requirements_of(list(requirements), period)
    return simulation


def simulation_of(config: RunConfig, scenario: Scenario | None = None) -> Simulation:
    """The simulation of a run's configuration, on ``scenario`` if given (one a run recorded)."""
    return build_simulation(
        config.scenario if scenario is None else scenario,
        config.field,
        config.env,
        config.controller,
        config.safety_layer,
        config.requirements,
    )


def check_sut(config: RunConfig) -> None:
    """Exercise the run's controller and safety-layer plug-ins once on a trial episode (reset,
    then one decision of a human standing still, against a simulation of its own), so that a
    plug-in that cannot run stops the run before anything is written, instead of making every
    episode a ``sut_error``. The built-in SUT is not tried.

    Raises:
        PluginError: A plug-in does not load, or raised, hung or returned something unusable
            on the trial episode: one line naming the plug-in, the method and the error.
        ConfigError: The periods do not fit.
    """
    try_sut(config.scenario, config.field, config.env, config.controller, config.safety_layer)


def try_sut(
    scenario: str,
    field: str,
    options: EnvOptions,
    controller: PluginSpec | None,
    safety_layer: PluginSpec | None,
    before: str = "the run",
) -> None:
    """The trial episode of :func:`check_sut` for the SUT these settings describe, which
    precedes ``before``; nothing when it is the built-in one.

    Raises:
        PluginError: As :func:`check_sut`.
        ConfigError: The periods do not fit.
    """
    if controller is None and safety_layer is None:
        return
    trial = build_simulation(scenario, field, options, controller, safety_layer)
    try_plugins(trial, controller, safety_layer, before)
