"""A user's plug-in as configuration names it (an import path and keyword parameters), and how
each kind is built from it: controller, safety layer, tester and failure classifier.

Configuration only names plug-ins; nothing is imported while it is validated. They are built
where they are used (a run builds its own) and checked once where a campaign file or a command
line is read (:func:`hazardhunt.campaign.config.check_plugins`).
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict

from hazardhunt.spec.failure_classes import FailureClassifier, MechanismClassifier
from hazardhunt.sut.plugins import build, build_controller, build_safety_layer
from hazardhunt.sut.protocols import Controller, SafetyLayer
from hazardhunt.testers.base import Tester
from hazardhunt.testers.registry import build_tester
from hazardhunt.world.bodies import RobotParams


class PluginSpec(BaseModel):
    """A user's plug-in: an import path and its keyword parameters."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    path: str
    """``package.module:Class`` (or a factory function)."""
    params: dict[str, Any] = {}
    """Keyword parameters of the class."""
    search_path: list[str] = []
    """Directories the module is imported from besides ``sys.path`` (hazardhunt adds the
    campaign file's directory and the working directory)."""


def make_controller(spec: PluginSpec) -> Controller:
    """The controller ``spec`` names (see :func:`hazardhunt.sut.plugins.build_controller`)."""
    return build_controller(spec.path, spec.params, spec.search_path)


def make_safety_layer(spec: PluginSpec) -> SafetyLayer:
    """The safety layer ``spec`` names (see :func:`hazardhunt.sut.plugins.build_safety_layer`)."""
    return build_safety_layer(spec.path, spec.params, spec.search_path)


def make_plugin_tester(spec: PluginSpec, seed: int) -> Tester:
    """The tester ``spec`` names, for a run with ``seed`` (see
    :func:`hazardhunt.testers.registry.build_tester`)."""
    return build_tester(spec.path, seed, spec.params, spec.search_path)


def make_classifier(
    spec: PluginSpec | None, robot: RobotParams = RobotParams()
) -> FailureClassifier:
    """The failure classifier ``spec`` names, or without one the built-in
    :class:`~hazardhunt.spec.failure_classes.MechanismClassifier` for ``robot``.

    Raises:
        PluginError: The plug-in does not load or does not fit the FailureClassifier protocol.
    """
    if spec is None:
        return MechanismClassifier(robot=robot)
    classifier: FailureClassifier = build(
        "failure classifier", spec.path, spec.params, FailureClassifier, spec.search_path
    )
    return classifier
