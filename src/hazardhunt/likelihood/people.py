"""Models of the people on the floor: distributions over human behaviours with exact likelihoods.

A :class:`HumanModel` is a product of independent random variables (its ``dimensions``, each a
:class:`~hazardhunt.likelihood.distributions.Dimension`) and a rule that turns one draw of them
into the human's behaviour in an episode (``policy``). What hazardhunt estimates is the
probability of a failure per encounter when people behave as the model says: the adversarial
testers stay as they are, the model is what "how likely" is measured against.

The default, :class:`WalkerModel`, reads ``people.toml`` (shipped with hazardhunt; a file of the
same form replaces it): a person sets off after a delay, walks to one of the floor's places along
the aisles at a walking speed of their own, may pause once, and either looks out for the robot
or crosses without looking.

A model of one's own is a class named by import path (``package.module:Class``), called with
the scenario (``Class(scenario=...)``), with the members of :class:`HumanModel`.
"""

from __future__ import annotations

import functools
import math
import os
import reprlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

from hazardhunt.errors import HazardhuntError, InputError
from hazardhunt.likelihood.distributions import (
    Dimension,
    DistributionError,
    check_ranges,
    dimension,
    dimensions,
    log_prob,
    sample,
)
from hazardhunt.sim.simulation import Action, Policy, Simulation, UnusableActionError, human_action
from hazardhunt.sut.guard import is_plugin_fault, raised
from hazardhunt.sut.plugins import build
from hazardhunt.textfiles import TOMLDecodeError, loads_toml, read_input_text
from hazardhunt.world.bodies import HumanParams
from hazardhunt.world.floor import FloorMap
from hazardhunt.world.geometry import point_rectangle_clearance
from hazardhunt.world.scenario import Scenario

DEFAULT_MODEL = "shopfloor"
"""The name of the built-in model of people (``people.toml``)."""

CHECK_SAMPLES = 64
"""Draws on which a model's ``log_prob`` must be finite before anything runs."""

STAND = np.array([-1.0, 0.0], dtype=np.float32)
"""The normalised action of a human who stands still."""

BEHAVIOUR_RANGES = {
    "speed": (0.0, HumanParams().max_speed),
    "start_delay": (0.0, math.inf),
    "pauses": (0.0, 1.0),
    "pause_after": (0.0, math.inf),
    "pause_duration": (0.0, math.inf),
    "looks": (0.0, 1.0),
}
"""The values each behaviour may take (m/s, s, yes or no, s, s, yes or no): a walker faster
than the simulated human can walk would be slowed to its largest speed, a negative delay or
duration played as none, so that the estimate would be of another model than the file's."""


class ModelError(InputError):
    """A model of people that cannot be used; the message names the file or plug-in."""


class ModelPlayError(HazardhuntError):
    """A model of people of one's own that raised, or gave the human an action that is not two
    finite numbers, while an encounter was played; the message names the plug-in."""


@runtime_checkable
class HumanModel(Protocol):
    """A distribution over the human's behaviour in an encounter."""

    @property
    def dimensions(self) -> Sequence[Dimension]:
        """The independent random variables of a behaviour, in order."""
        ...

    def policy(self, values: Mapping[str, float], simulation: Simulation) -> Policy:
        """The human's behaviour for one draw of the dimensions: the next normalised action
        from the simulation's state (deterministic: the same values play the same episode)."""
        ...


def model_sample(model: HumanModel, rng: np.random.Generator) -> dict[str, float]:
    """One behaviour drawn from ``model``."""
    return sample(model.dimensions, rng)


def model_log_prob(model: HumanModel, values: Mapping[str, float]) -> float:
    """The log-likelihood of a behaviour under ``model``."""
    return log_prob(model.dimensions, values)


def check_model(name: str, model: HumanModel, seed: int = 0) -> None:
    """Draw :data:`CHECK_SAMPLES` behaviours and check that each has a finite log-likelihood.

    Raises:
        ModelError: A dimension's log-likelihood is not finite on one of its own draws.
    """
    rng = np.random.default_rng(seed)
    for _ in range(CHECK_SAMPLES):
        try:
            values = model_sample(model, rng)
            finite_log_prob(f"people model {name}", model.dimensions, values)
        except ModelError:
            raise
        except BaseException as error:  # a dimension of one's own may raise anything
            if not is_plugin_fault(error):
                raise
            raise ModelError(
                f"people model {name}: drawing a behaviour raised {raised(error)}"
            ) from error


def finite_log_prob(
    model: str, dims: Sequence[Dimension], values: Mapping[str, float], which: str = ""
) -> float:
    """The log-likelihood of a draw of ``model``'s ``dims`` (``which`` says which, for a
    message).

    Raises:
        ModelError: A dimension's log-likelihood is not finite on it.
    """
    total = 0.0
    for dim in dims:
        value = dim.log_prob(values[dim.name])
        if not math.isfinite(value):
            raise ModelError(
                f"{model}: {dim.name}: log_prob is {value} on its own draw "
                f"{values[dim.name]!r}{which}"
            )
        total += value
    return total


class PluginModel:
    """A model of people of one's own (an import path), called through guards: what its
    ``policy`` or the policy it returns raises (``SystemExit`` too), a policy that is not
    callable and an action that is not two finite numbers are a :class:`ModelPlayError` naming
    it, never an episode played."""

    def __init__(self, path: str, model: HumanModel) -> None:
        """Raises ModelError: its ``dimensions`` raise, or are not Dimensions."""
        self.path = path
        self.model = model
        try:
            dims = model.dimensions
        except BaseException as error:  # a plug-in may raise anything
            if not is_plugin_fault(error):
                raise
            raise ModelError(f"people model {path!r}: dimensions raised {raised(error)}") from None
        if not isinstance(dims, Sequence) or not all(isinstance(d, Dimension) for d in dims):
            raise ModelError(
                f"people model {path!r}: dimensions must be a sequence of "
                "hazardhunt.likelihood.distributions.Dimension"
            )
        self.dimensions: tuple[Dimension, ...] = tuple(dims)

    def policy(self, values: Mapping[str, float], simulation: Simulation) -> Policy:
        """The model's policy for ``values``, its every action checked.

        Raises:
            ModelPlayError: ``policy()`` raised, or returned something that is not callable.
        """
        try:
            policy = self.model.policy(values, simulation)
        except BaseException as error:  # a plug-in may raise anything
            if not is_plugin_fault(error):
                raise
            raise ModelPlayError(
                f"people model {self.path!r}: policy() raised {raised(error)}"
            ) from error
        if not callable(policy):
            raise ModelPlayError(
                f"people model {self.path!r}: policy() returned {reprlib.repr(policy)}, not a "
                "policy (a callable that gives the human's next action from the simulation)"
            )
        return functools.partial(_checked_action, self.path, policy)


def _checked_action(path: str, policy: Policy, simulation: Simulation) -> Action:
    """``policy``'s next action.

    Raises:
        ModelPlayError: It raised, or the action is not two finite numbers.
    """
    try:
        return human_action(policy(simulation))
    except UnusableActionError as error:
        raise ModelPlayError(
            f"people model {path!r}: its policy's action at {simulation.sim_time:g} s: {error}"
        ) from None
    except BaseException as error:  # a plug-in may raise anything
        if not is_plugin_fault(error):
            raise
        raise ModelPlayError(
            f"people model {path!r}: its policy raised {raised(error)} at {simulation.sim_time:g} s"
        ) from error


def try_model(model: HumanModel, simulation: Simulation, seed: int) -> None:
    """Play the first decision of one of ``model``'s behaviours (drawn with ``seed``) in
    ``simulation`` (reset here), so that a model that cannot play stops an estimate before it
    writes anything.

    Raises:
        ModelError: The model's policy raised or gave an unusable action (:class:`ModelPlayError`).
    """
    values = model_sample(model, np.random.default_rng(seed))
    simulation.reset()
    try:
        model.policy(values, simulation)(simulation)
    except ModelPlayError as error:
        raise ModelError(
            f"{error} (on a trial draw before the estimate; nothing was written)"
        ) from None


@dataclass(frozen=True)
class Place:
    """Where people walk to."""

    name: str
    x: float
    y: float


@dataclass(frozen=True)
class Walking:
    """How a walker moves, besides what the model draws."""

    look_distance: float = 3.0
    """A person who looks waits while the robot comes towards them closer than this, in m."""
    look_angle_deg: float = 60.0
    """... within this angle of where they walk, in degrees."""
    arrive_distance: float = 0.3
    """A person this close to their place stands there, in m."""


class WalkerModel:
    """People who walk with a purpose between the floor's places (``people.toml``)."""

    def __init__(self, scenario: Scenario, file: str | Path | None = None) -> None:
        """Read the model for ``scenario``'s floor from ``file`` (the built-in one when None).

        Raises:
            ModelError: The file does not read, a distribution or a place is invalid, or it has
                no places for the scenario's floor.
        """
        where, text = _model_text(file)
        try:
            data = loads_toml(text)
        except TOMLDecodeError as error:
            raise ModelError(f"{where}: not valid TOML: {error}") from None
        unknown = sorted(set(data) - {"behaviour", "walking", "places"})
        if unknown:
            raise ModelError(f"{where}: unknown table(s) {', '.join(unknown)}")
        behaviour = data.get("behaviour", {})
        if not isinstance(behaviour, Mapping):
            raise ModelError(f"{where}: behaviour: must be a table, not {behaviour!r}")
        wanted = {"speed", "start_delay", "pauses", "pause_after", "pause_duration", "looks"}
        if missing := sorted(wanted - set(behaviour)):
            raise ModelError(f"{where}: behaviour: missing {', '.join(missing)}")
        if extra := sorted(set(behaviour) - wanted):
            raise ModelError(f"{where}: behaviour: unknown {', '.join(extra)}")
        try:
            dims = dimensions(f"{where}: behaviour", behaviour)
            check_ranges(f"{where}: behaviour", dims, BEHAVIOUR_RANGES)
        except DistributionError as error:
            raise ModelError(str(error)) from None
        self.walking = _walking(where, data.get("walking", {}))
        self.places = _places(where, scenario, data.get("places", {}))
        weights = [weight for _, weight in self.places]
        destination = dimension(
            where, "destination", {"distribution": "categorical", "weights": weights}
        )
        self.dimensions: tuple[Dimension, ...] = (*dims, destination)
        self.source = where

    def policy(self, values: Mapping[str, float], simulation: Simulation) -> Policy:
        place, _ = self.places[int(values["destination"])]
        return WalkerPolicy(values, place, self.walking, simulation)


def _model_text(file: str | Path | None) -> tuple[str, str]:
    if file is None:
        text = resources.files("hazardhunt.likelihood").joinpath("people.toml").read_text()
        return "people.toml (built-in)", text
    path = Path(file)
    try:
        return str(path), read_input_text(path)
    except (OSError, UnicodeDecodeError) as error:
        raise ModelError(f"{path}: cannot read the model of people: {error}") from None


def _walking(where: str, table: Any) -> Walking:
    if not isinstance(table, Mapping):
        raise ModelError(f"{where}: walking: must be a table")
    known = {"look_distance", "look_angle_deg", "arrive_distance"}
    if extra := sorted(set(table) - known):
        raise ModelError(f"{where}: walking: unknown {', '.join(extra)}")
    for key, value in table.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not value >= 0:
            raise ModelError(f"{where}: walking: {key} must be a number >= 0, not {value!r}")
    return Walking(**{key: float(value) for key, value in table.items()})


def _places(where: str, scenario: Scenario, table: Any) -> list[tuple[Place, float]]:
    floor = scenario.floor
    if not isinstance(table, Mapping):
        raise ModelError(f"{where}: places: must be a table, not {table!r}")
    entries = table.get(floor.name)
    if not entries:
        raise ModelError(
            f"{where}: no [[places.{floor.name}]] for the floor of scenario {scenario.name!r}: "
            "write a model file with the places people walk to on it (docs/risk.md)"
        )
    if not isinstance(entries, list):
        raise ModelError(
            f"{where}: places.{floor.name}: must be a list of places ([[places.{floor.name}]]), "
            f"not {entries!r}"
        )
    places = [_place(f"{where}: places.{floor.name}[{i}]", floor, e) for i, e in enumerate(entries)]
    if not any(weight > 0 for _, weight in places):
        raise ModelError(f"{where}: places.{floor.name}: the weights must not all be 0")
    return places


def _place(at: str, floor: FloorMap, entry: Any) -> tuple[Place, float]:
    if not isinstance(entry, Mapping) or set(entry) != {"name", "x", "y", "weight"}:
        raise ModelError(f"{at}: must have exactly name, x, y and weight")
    x, y, weight = entry["x"], entry["y"], entry["weight"]
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (x, y, weight)):
        raise ModelError(f"{at}: x, y and weight must be numbers")
    point = np.array([float(x), float(y)])
    if not floor.on_floor(point) or floor.inside_obstacle(point):
        raise ModelError(f"{at}: ({x}, {y}) is not on the free floor")
    if not (math.isfinite(weight) and weight >= 0):
        raise ModelError(f"{at}.weight: must be a number >= 0, not {weight!r}")
    return Place(str(entry["name"]), float(x), float(y)), float(weight)


class WalkerPolicy:
    """One walker's behaviour in an episode: stand until ``start_delay``, walk to the place
    (round the shelves), pause once if ``pauses``, wait for the robot if ``looks``."""

    def __init__(
        self,
        values: Mapping[str, float],
        place: Place,
        walking: Walking,
        simulation: Simulation,
    ) -> None:
        self.target = np.array([place.x, place.y])
        self.speed = float(values["speed"])
        self.start = float(values["start_delay"])
        pauses = round(values["pauses"]) == 1
        pause_at = self.start + float(values["pause_after"])
        self.pause = (pause_at, pause_at + float(values["pause_duration"])) if pauses else None
        self.looks = round(values["looks"]) == 1
        self.walking = walking
        human = simulation.human_params
        self.grid = simulation.scenario.floor.walk_grid(human.radius)
        self.max_speed, self.max_turn = human.max_speed, human.max_turn_rate
        self.period = simulation.decision_period

    def __call__(self, simulation: Simulation) -> Action:
        now = simulation.sim_time
        if now < self.start - 1e-9:
            return STAND
        if self.pause is not None and self.pause[0] - 1e-9 <= now < self.pause[1] - 1e-9:
            return STAND
        x, y, heading = simulation.human_pose
        here = np.array([x, y])
        if math.hypot(*(self.target - here)) <= self.walking.arrive_distance:
            return STAND
        point, _ = self.grid.waypoint(here, self.target)
        wanted = math.atan2(point[1] - y, point[0] - x)
        error = (wanted - heading + math.pi) % math.tau - math.pi
        turn = float(np.clip(error / (self.max_turn * self.period), -1.0, 1.0))
        speed = self.speed * max(math.cos(error), 0.0)  # turn first, then walk
        if self.looks and self._robot_coming(simulation, wanted):
            speed = 0.0
        return np.array([2.0 * speed / self.max_speed - 1.0, turn], dtype=np.float32)

    def _robot_coming(self, simulation: Simulation, walking_to: float) -> bool:
        """The robot moves and is near, within the look angle of where the person walks."""
        robot, params = simulation.robot, simulation.robot_params
        if robot.speed <= 0.05:
            return False
        x, y, _ = simulation.human_pose
        cos, sin = math.cos(robot.heading), math.sin(robot.heading)
        dx, dy = x - robot.x, y - robot.y
        forward, left = cos * dx + sin * dy, -sin * dx + cos * dy
        gap = point_rectangle_clearance(forward, left, params.length, params.width)
        if gap > self.walking.look_distance:
            return False
        bearing = math.atan2(robot.y - y, robot.x - x)
        off = abs((bearing - walking_to + math.pi) % math.tau - math.pi)
        return off <= math.radians(self.walking.look_angle_deg)


def load_model(spec: str | None, scenario: Scenario) -> HumanModel:
    """The model of people ``spec`` names for ``scenario``: None or ``shopfloor`` for the
    built-in one, a ``.toml`` file of the same form, or the import path of one's own
    (``package.module:Class``, called as ``Class(scenario=...)``, a :class:`PluginModel`). Its
    log-likelihood is checked on draws of its own (:func:`check_model`).

    Raises:
        ModelError: It does not load or its log-likelihood is not finite on its own draws.
        PluginError: A plug-in does not load or lacks a member of :class:`HumanModel`.
    """
    if spec is None or spec == DEFAULT_MODEL:
        model: HumanModel = WalkerModel(scenario)
    elif spec.endswith(".toml"):
        model = WalkerModel(scenario, spec)
    else:
        built = build("people model", spec, {"scenario": scenario}, HumanModel, [os.getcwd()])
        model = PluginModel(spec, built)
    check_model(spec or DEFAULT_MODEL, model)
    return model
