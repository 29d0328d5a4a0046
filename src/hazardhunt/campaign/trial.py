"""The trial episode a user's SUT plays before a run or an estimate writes anything.

A controller or safety-layer plug-in that cannot run at all would otherwise make every episode
a ``sut_error``: the run or estimate would test nothing and say so only at its end. One decision
of a human standing still, after a reset, finds most such plug-ins at once, with the error they
raised.
"""

from __future__ import annotations

import numpy as np

from hazardhunt.campaign.plugins import PluginSpec
from hazardhunt.sim.simulation import Simulation
from hazardhunt.sut.plugins import PluginError

TRIAL_ACTION = np.array([-1.0, 0.0])
"""The human's action on the trial episode: standing still."""


def try_plugins(
    simulation: Simulation,
    controller: PluginSpec | None,
    safety_layer: PluginSpec | None,
    before: str = "the run",
) -> None:
    """Play the trial episode in ``simulation``, whose controller and safety layer are the
    plug-ins ``controller`` and ``safety_layer`` name (None: the built-in one); ``before``
    says what it precedes.

    Raises:
        PluginError: A plug-in raised, hung or returned something unusable on the trial: one
            line naming the plug-in, the method and the error.
    """
    simulation.reset()
    simulation.decide(TRIAL_ACTION)
    summary = simulation.summary()
    tried = (
        ("controller", controller, summary.controller_errors, "control()"),
        ("safety layer", safety_layer, summary.safety_layer_errors, "update()"),
    )
    for kind, spec, errors, call in tried:
        if not errors:
            continue
        name = "the built-in one" if spec is None else repr(spec.path)
        error = errors[0]
        if call not in error and not error.startswith("reset()"):
            error = f"{call} raised {error}"
        raise PluginError(
            f"{kind} {name}: {error} (on a trial episode before {before}; nothing was run)"
        )
