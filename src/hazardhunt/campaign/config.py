"""Typed, validated configuration of a run and of a campaign (a grid of runs).

Long (over 500 lines) because every rule a configuration must satisfy before anything runs
(types, ranges, scenario files and routes, tester settings, run names) is checked here, so that
a bad campaign file is one error naming its key.
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import hashlib
import itertools
import os
import re
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    Strict,
    StrictInt,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)
from pydantic_core import InitErrorDetails, PydanticCustomError

from hazardhunt.campaign.plugins import (
    PluginSpec,
    make_classifier,
    make_controller,
    make_plugin_tester,
    make_safety_layer,
)
from hazardhunt.errors import InputError
from hazardhunt.sim.simulation import SimulationSettings, decisions_in, whole_multiple
from hazardhunt.spec.outcomes import MAX_EPISODE_DURATION, TerminationParams
from hazardhunt.spec.requirements import requirements_of
from hazardhunt.sut.plugins import PluginError
from hazardhunt.sut.route import RoutePlanningError, scenario_route
from hazardhunt.sut.safety_layer import FIELD_SETTINGS, scenario_field_shapes
from hazardhunt.testers.base import TesterParameterError
from hazardhunt.testers.registry import TESTERS, make_tester
from hazardhunt.textfiles import (
    format_validation_error,
    loads_toml,
    read_input_text,
    shown_value,
)
from hazardhunt.world.bodies import HumanParams, RobotParams
from hazardhunt.world.geometry import point_rectangle_clearance, to_body_frame
from hazardhunt.world.scenario import (
    BUILTIN_SCENARIOS,
    Scenario,
    ScenarioError,
    load_scenario,
)

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


class ConfigError(InputError):
    """A run or campaign configuration that cannot be used; the message says what is wrong."""


class _Strict(BaseModel):
    # Every float of a configuration is a finite number.
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


Seconds = Annotated[float, Strict(), Field(gt=0)]
"""A positive, finite time in s: an int or a float, not a string or a boolean."""

MIN_STALL_DURATION = 0.05
"""The shortest stall limit, in s: one physics step."""
MAX_CONTROLLER_TIMEOUT = 86_400.0
"""The longest time limit on one call of a plug-in, in s (a day): the timer cannot hold much
more."""

MAX_SEED = 2**32 - 1
"""The largest seed: a regression case stores an episode's seed, which NumPy and the
environment take up to this."""
Seed = Annotated[StrictInt, Field(ge=0, le=MAX_SEED)]
"""A run's seed: a whole number from 0 to :data:`MAX_SEED`."""

SutErrorLimit = Annotated[float, Strict(), Field(gt=0, le=1)]
"""The share of a run's episodes that, once they have ended in ``sut_error``, fails the run: a
run that did not test its system under test must not read as a pass. 1 (the default): the run
fails when every episode did."""


class EnvOptions(_Strict):
    """Environment parameters a run or campaign may override (defaults from SPEC)."""

    decision_period: Seconds = 2.0
    """Time the human holds each action, in s: a whole multiple of the controller's period
    (0.2 s for the built-in NMPC), at most ``episode_duration``."""
    solver: Literal["fatrop", "ipopt"] = "fatrop"
    """The NMPC's solver."""
    episode_duration: Annotated[Seconds, Field(le=MAX_EPISODE_DURATION)] = 30.0
    """Simulated time after which an episode times out, in s."""
    stall_duration: Annotated[
        float, Strict(), Field(ge=MIN_STALL_DURATION, le=MAX_EPISODE_DURATION)
    ] = 10.0
    """Continuous emergency-stop time after which an episode stalls, in s."""
    controller_timeout: Annotated[float, Strict()] | None = Field(
        default=None, gt=0, le=MAX_CONTROLLER_TIMEOUT, allow_inf_nan=False
    )
    """Wall-clock limit on each call of the controller, in s (at most a day): a call that
    exceeds it ends the episode as ``sut_error``. None: no limit (a limit makes results depend
    on the machine)."""
    robot: RobotParams = RobotParams()
    """The robot's size and limits (``[env.robot]``: length, width, max_speed, ...); the
    controller receives them in ``reset``."""

    @field_validator("robot", mode="before")
    @classmethod
    def _robot_numbers(cls, value: Any) -> Any:
        # pydantic would turn true into 1.0 and "1.1" into 1.1 on their way to RobotParams.
        if not isinstance(value, dict):
            return value
        known = [field.name for field in dataclasses.fields(RobotParams)]
        for key, item in value.items():
            if key not in known:
                close = difflib.get_close_matches(str(key), known, n=1)
                hint = f" (did you mean {close[0]}?)" if close else ""
                raise invalid((key,), f"unknown key{hint}", item)
            if isinstance(item, bool) or not isinstance(item, int | float):
                raise invalid((key,), f"must be a number, not {shown_value(item)}", item)
        return value

    def settings(self) -> SimulationSettings:
        """These options as the simulation's settings (the others at their defaults)."""
        return SimulationSettings(
            decision_period=self.decision_period,
            termination=TerminationParams(self.episode_duration, self.stall_duration),
            controller_timeout=self.controller_timeout,
            solver=self.solver,
            robot=self.robot,
        )

    @model_validator(mode="after")
    def _decision_fits_episode(self) -> EnvOptions:
        if self.decision_period > self.episode_duration:
            raise invalid(
                ("decision_period",),
                f"{self.decision_period:g} s is longer than an episode (episode_duration, "
                f"{self.episode_duration:g} s)",
                self.decision_period,
            )
        return self


def invalid(location: tuple[str | int, ...], message: str, value: object) -> ValidationError:
    """A validation error of the value at ``location`` (keys below the one being validated),
    for a validator to raise: pydantic reports it under the full path of keys."""
    error = PydanticCustomError("invalid", "{message}", {"message": message})
    return ValidationError.from_exception_data(
        "configuration", [InitErrorDetails(type=error, loc=location, input=value)]
    )


def decision_period_problem(decision_period: float, control_period: float) -> str | None:
    """Why a human cannot hold each action for ``decision_period`` s against a controller
    called every ``control_period`` s; None if it can (the tolerance of the simulation's own
    check)."""
    if whole_multiple(decision_period, control_period) is not None:
        return None
    return (
        f"{decision_period:g} s is not a whole multiple of the controller's period "
        f"({control_period:g} s)"
    )


def builtin_control_period() -> float:
    """The period of the built-in NMPC, in s (its ``sample_time``)."""
    from hazardhunt.sut.nmpc import NMPCParams

    return NMPCParams().sample_time


def _check_built_in_controller(env: EnvOptions, controller: PluginSpec | None) -> None:
    """Raises a validation error at ``env.decision_period`` unless the built-in NMPC (when
    ``controller`` is None) can run with it; a plug-in's period is checked by
    :func:`check_plugins`."""
    if controller is None:
        problem = decision_period_problem(env.decision_period, builtin_control_period())
        if problem is not None:
            raise invalid(("env", "decision_period"), problem, env.decision_period)


def _scenario_version(name: str) -> tuple[int, int] | None:
    """The modification time and size of a scenario file; None for a built-in scenario or a
    file that cannot be read (whose load then reports why)."""
    if name in BUILTIN_SCENARIOS:
        return None
    try:
        stat = Path(name).stat()
    except OSError:
        return None
    return stat.st_mtime_ns, stat.st_size


@functools.lru_cache(maxsize=64)
def _load_version(name: str, version: tuple[int, int] | None) -> Scenario:
    return load_scenario(name)


def cached_scenario(name: str) -> Scenario:
    """``load_scenario(name)``, loaded once per version of the file in this process: checking
    every run of a campaign reads each scenario file once.

    Raises:
        ScenarioError: The scenario does not load.
    """
    return _load_version(name, _scenario_version(name))


@functools.lru_cache(maxsize=64)
def _route_version_problem(
    name: str, version: tuple[int, int] | None, robot: RobotParams
) -> str | None:
    scenario = cached_scenario(name)
    human = scenario.human_start.position
    start = scenario.robot_start
    forward, left = to_body_frame(human, start.x, start.y, start.heading)
    if point_rectangle_clearance(forward, left, robot.length, robot.width) < HumanParams.radius:
        return (
            f"{scenario.source}: human.start: ({human[0]:g}, {human[1]:g}) touches the robot at "
            "its start: every episode would begin in contact; place the human farther away"
        )
    try:
        scenario_route(scenario, robot.width)
    except RoutePlanningError as error:
        keys = ["robot.start", *(f"robot.waypoints.{i}" for i in range(len(scenario.waypoints)))]
        keys.append("robot.goal")
        key = keys[error.stops[-1]] if error.stops else "robot"
        return f"{scenario.source}: {key}: the robot cannot get there: {error}"
    return None


def route_problem(name: str, robot: RobotParams) -> str | None:
    """Why the robot cannot drive the route of scenario ``name`` (naming the file and the
    route point), or why no episode of it can be played (the human starts touching the robot),
    None if it can; planned once per version of the file and robot."""
    return _route_version_problem(name, _scenario_version(name), robot)


def _check_scenario(value: str, info: ValidationInfo) -> str:
    if value in BUILTIN_SCENARIOS or _recorded(info):
        return value
    if not value.endswith(".toml"):
        raise ValueError(
            f"unknown scenario {value!r}: use one of {', '.join(BUILTIN_SCENARIOS)} or a .toml file"
        )
    # Absolute, so that replays, reports and exports find it from any working directory.
    value = str(Path(value).resolve())
    # Load it now, so that a broken scenario file stops the campaign before any run starts.
    try:
        scenario_field_shapes(cached_scenario(value))
    except ScenarioError as error:
        raise ValueError(str(error)) from None
    return value


def _check_fields(scenario: str, fields: list[str]) -> None:
    """Raises ValueError unless every field is built in or defined by the scenario."""
    from hazardhunt.sut.safety_layer import field_shape

    if all(f in FIELD_SETTINGS for f in fields):
        return
    if scenario not in BUILTIN_SCENARIOS and not Path(scenario).is_file():
        return  # the scenario's own error is reported
    loaded = cached_scenario(scenario)
    for name in fields:
        field_shape(loaded, name)


def scenario_field(cls: type, value: str, info: ValidationInfo) -> str:
    """A configuration's validator of its ``field``: built in or defined by its ``scenario``
    (``_field_ok = field_validator("field")(scenario_field)``)."""
    if "scenario" in info.data and not _recorded(info):
        _check_fields(info.data["scenario"], [value])
    return value


FILE_NAME_LIMIT = 120
"""The most characters :func:`file_name` gives: a file system takes 255 bytes in one name, and
a prefix or suffix (``class_``, ``.toml``) must fit beside it."""


def file_name(name: str, limit: int | None = FILE_NAME_LIMIT) -> str:
    """``name`` as one path component that stays where it is put: every run of characters
    but letters, digits, ``_``, ``.`` and ``-`` becomes ``_``, and leading dots go. A name
    longer than ``limit`` (None: no limit) keeps its start and ends with ``-`` and 12 hex digits
    of the SHA-256 of ``name``, so that long names that differ stay apart."""
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", name).lstrip(".") or "_"
    if limit is None or len(safe) <= limit:
        return safe
    digest = hashlib.sha256(name.encode("utf-8", "surrogatepass")).hexdigest()[:12]
    return f"{safe[: limit - len(digest) - 1]}-{digest}"


def run_id_of(scenario: str, field: str, tester: str, seed: int) -> str:
    """The name of a run's directory: its scenario's name, field, tester and seed, each made a
    safe file name (see :func:`file_name`)."""
    # Not shortened: a campaign's run folders keep the names earlier versions gave them.
    parts = (file_name(Path(scenario).stem, None), file_name(field, None), file_name(tester, None))
    return "__".join(parts) + f"__seed{seed}"


def _check_tester(value: str) -> str:
    if value not in TESTERS:
        raise ValueError(
            f"unknown tester {value!r}: use one of {', '.join(TESTERS)}, your own "
            "(package.module:Class), or a configuration of one with method = NAME"
        )
    return value


def _check_plugin_name(value: str) -> str:
    if value in TESTERS:
        raise ValueError(f"{value!r} is a built-in tester; give your own tester another name")
    return value


ScenarioName = Annotated[str, AfterValidator(_check_scenario)]
"""A built-in scenario name or a scenario file that loads."""
FieldSetting = Annotated[str, Field(min_length=1)]
"""A protective-field setting: none, 1.25m, 2m or a field the scenario defines."""
PluginTesterName = Annotated[str, Field(min_length=1), AfterValidator(_check_plugin_name)]
"""The name of a user's tester: any but a registered tester's."""


class RunConfig(_Strict):
    """One tester x one scenario x one field setting x one seed x a budget of episodes."""

    scenario: ScenarioName
    """A built-in scenario name or a scenario file."""
    field: FieldSetting
    """Protective-field setting: none, 1.25m, 2m or a field the scenario defines."""
    # Before ``tester``: its check needs to know whether the name is a plug-in's.
    tester_plugin: PluginSpec | None = None
    """A user's tester, whose name ``tester`` is; None for a registered tester."""
    tester: str = Field(min_length=1)
    """The search method: a registered tester (``TESTERS``) or the name of a user's."""
    seed: Seed
    """Seeds every random choice of the run."""
    episodes: StrictInt = Field(gt=0)
    """Budget: number of episodes."""
    env: EnvOptions = EnvOptions()
    tester_params: dict[str, Any] = {}
    """Keyword parameters of a registered tester (for PPO: Stable-Baselines3 PPO arguments); a
    user's tester takes those of ``tester_plugin``."""
    controller: PluginSpec | None = None
    """The robot's controller; the built-in NMPC when None."""
    safety_layer: PluginSpec | None = None
    """The safety layer; the laser field of ``field`` when None."""
    classifier: PluginSpec | None = None
    """Names each failure's class; the built-in mechanism taxonomy when None."""
    sut_error_limit: SutErrorLimit = 1.0
    """The run fails (its results are not kept) once this share of its episodes has ended in
    ``sut_error``; 1: when every one did."""
    requirements: list[str] = []
    """Requirements beyond the contact rule every episode is judged by: names of hazardhunt's
    library, requirements files, or ``FILE.toml:NAME`` (``docs/requirements.md``)."""
    search_on: str | None = None
    """The name of one of ``requirements`` the episode-level testers search on (its
    violations and robustness in place of unsafe contacts and risk) and ``ppo-max`` learns
    from; None: the contact rule."""

    @field_validator("requirements")
    @classmethod
    def _requirements_read(cls, value: list[str], info: ValidationInfo) -> list[str]:
        if not _stored(info):
            requirements_of(value)  # a formula that cannot be monitored stops the run here
        return value

    _field_ok = field_validator("field")(scenario_field)

    @field_validator("tester")
    @classmethod
    def _tester_ok(cls, value: str, info: ValidationInfo) -> str:
        # A registered tester, or a configuration of one (checked with its parameters).
        if info.data.get("tester_plugin") is None:
            return value
        return _check_plugin_name(value)

    @field_validator("tester_params")
    @classmethod
    def _tester_accepts_params(cls, values: dict[str, Any], info: ValidationInfo) -> dict[str, Any]:
        if "tester" not in info.data:  # the tester's own error is reported
            return values
        if info.data.get("tester_plugin") is not None and values:
            raise ValueError("a user's tester takes the parameters of tester_plugin")
        return values

    @model_validator(mode="after")
    def _runs_as_configured(self, info: ValidationInfo) -> RunConfig:
        _check_built_in_controller(self.env, self.controller)
        if self.search_on is not None and not _stored(info):
            _check_search_on(self.search_on, self.requirements, self.tester, self.tester_params)
        if self.tester_plugin is None:
            if "method" not in self.tester_params:
                try:
                    _check_tester(self.tester)
                except ValueError as error:
                    raise invalid(("tester",), str(error), self.tester) from None
            if not _stored(info):  # building it would import a portfolio's arms of one's own
                _check_tester_params(self.tester, self.tester_params, self.env, ("tester_params",))
        problem = None if _recorded(info) else route_problem(self.scenario, self.env.robot)
        if problem is not None:
            raise invalid(("scenario",), problem, self.scenario)
        return self

    @property
    def run_id(self) -> str:
        """A file-system-safe name for the run, unique within a campaign."""
        return run_id_of(self.scenario, self.field, self.tester, self.seed)


class CampaignConfig(_Strict):
    """A grid of runs: every scenario x field x tester x seed, each with ``episodes``."""

    scenarios: list[ScenarioName] = Field(min_length=1)
    fields: list[FieldSetting] = Field(min_length=1)
    # Before ``testers``: their check needs to know the plug-ins' names.
    tester_plugins: dict[PluginTesterName, PluginSpec] = {}
    """Users' testers by name (in a campaign file, a ``[tester.NAME]`` table with a ``path``)."""
    testers: list[str] = Field(min_length=1)
    """Registered testers and names of ``tester_plugins``."""
    seeds: list[Seed] = Field(min_length=1)
    episodes: StrictInt = Field(gt=0)
    env: EnvOptions = EnvOptions()
    tester: dict[str, dict[str, Any]] = {}
    """Per registered tester its keyword parameters, e.g. ``[tester.ppo-max]``; or a
    configuration of a registered tester under a name of its own, e.g. ``[tester.cem-aim]``
    with ``method = "cem"``."""
    controller: PluginSpec | None = None
    """The robot's controller of every run (``[controller]``); the built-in NMPC when None."""
    safety_layer: PluginSpec | None = None
    """The safety layer of every run (``[safety_layer]``); the laser field when None."""
    classifier: PluginSpec | None = None
    """The failure classifier of every run (``[classifier]``); the built-in one when None."""
    sut_error_limit: SutErrorLimit = 1.0
    """A run fails once this share of its episodes has ended in ``sut_error`` (see
    :attr:`RunConfig.sut_error_limit`)."""
    requirements: list[str] = []
    """Requirements beyond the contact rule every run judges its episodes by (see
    :attr:`RunConfig.requirements`); a file is found next to the campaign file."""
    search_on: str | None = None
    """The requirement the testers search on (:attr:`RunConfig.search_on`)."""

    @field_validator("requirements")
    @classmethod
    def _requirements_read(cls, value: list[str]) -> list[str]:
        requirements_of(value)
        return value

    @field_validator("fields")
    @classmethod
    def _fields_ok(cls, values: list[str], info: ValidationInfo) -> list[str]:
        for scenario in [] if _recorded(info) else info.data.get("scenarios", []):
            _check_fields(scenario, values)
        return values

    @field_validator("tester")
    @classmethod
    def _testers_known(cls, values: dict[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
        for name, params in values.items():
            if "method" not in params:
                try:
                    _check_tester(name)
                except ValueError as error:
                    raise invalid((name,), str(error), name) from None
        return values

    @field_validator("scenarios", "fields", "testers")
    @classmethod
    def _distinct(cls, values: list[str]) -> list[str]:
        repeated = sorted({value for value in values if values.count(value) > 1})
        if repeated:
            raise ValueError(f"must be distinct; {', '.join(map(repr, repeated))} is given twice")
        return values

    @field_validator("seeds")
    @classmethod
    def _seeds_ok(cls, values: list[int]) -> list[int]:
        if any(v < 0 for v in values):
            raise ValueError("seeds must be non-negative")
        if len(set(values)) != len(values):
            raise ValueError("seeds must be distinct")
        return values

    @model_validator(mode="after")
    def _runs_as_configured(self, info: ValidationInfo) -> CampaignConfig:
        _check_built_in_controller(self.env, self.controller)
        for index, name in enumerate(self.testers):
            if name not in self.tester_plugins and "method" not in self.tester.get(name, {}):
                try:
                    _check_tester(name)
                except ValueError as error:
                    raise invalid(("testers", index), str(error), name) from None
        for name in dict.fromkeys([] if _stored(info) else [*self.tester, *self.testers]):
            if name not in self.tester_plugins:  # built, as a stored campaign's are not
                _check_tester_params(name, self.tester.get(name, {}), self.env, ("tester", name))
        if self.search_on is not None and not _stored(info):
            for name in self.testers:  # as each run would check it, but naming the file's key
                params = self.tester.get(name, {})
                _check_search_on(self.search_on, self.requirements, name, params)
        for index, scenario in enumerate([] if _recorded(info) else self.scenarios):
            problem = route_problem(scenario, self.env.robot)
            if problem is not None:
                raise invalid(("scenarios", index), problem, scenario)
        self._check_run_ids()
        return self

    @property
    def unused_tester_tables(self) -> list[str]:
        """The names of ``[tester.NAME]`` tables whose tester ``testers`` does not list: their
        settings reach no run (a tester taken out of the list for now, or a misspelt entry)."""
        tables = [*self.tester, *self.tester_plugins]
        return [name for name in dict.fromkeys(tables) if name not in self.testers]

    def _check_run_ids(self) -> None:
        """Raises a validation error naming the key of two names that give one run id."""
        seen: dict[str, tuple[str, str, str]] = {}
        keys = ("scenarios", "fields", "testers")
        for names in itertools.product(self.scenarios, self.fields, self.testers):
            run_id = run_id_of(*names, seed=0)
            other = seen.setdefault(run_id, names)
            if other != names:
                key, first, second = next(
                    (key, a, b) for key, a, b in zip(keys, other, names, strict=True) if a != b
                )
                raise invalid(
                    (key,),
                    f"{first!r} and {second!r} give the same run directory "
                    f"{run_id.removesuffix('__seed0')!r}; rename one",
                    second,
                )

    def runs(self, context: dict[str, Any] | None = None) -> list[RunConfig]:
        """The runs of the grid, in a stable order, checked in ``context`` (:data:`RECORDED`
        for a stored campaign whose runs recorded their scenarios)."""
        return [
            RunConfig.model_validate(
                {
                    "scenario": scenario,
                    "field": field,
                    "tester_plugin": self.tester_plugins.get(tester),
                    "tester": tester,
                    "seed": seed,
                    "episodes": self.episodes,
                    "env": self.env,
                    "tester_params": self.tester.get(tester, {}),
                    "controller": self.controller,
                    "safety_layer": self.safety_layer,
                    "classifier": self.classifier,
                    "sut_error_limit": self.sut_error_limit,
                    "requirements": self.requirements,
                    "search_on": self.search_on,
                },
                context=context,
            )
            for scenario in self.scenarios
            for field in self.fields
            for tester in self.testers
            for seed in self.seeds
        ]


STORED = {"stored": True}
"""The validation context of a configuration read back from a run directory: a record of what
ran, whose requirement files need not be where they were (the run's violations carry their
formulas), and whose testers are not built to check their settings (a portfolio's arm of
one's own would be imported: results are data, never code)."""


RECORDED = {**STORED, "scenario_recorded": True}
"""The validation context of a stored run configuration whose run recorded the scenario it
played (``scenario.json``), and of a stored campaign configuration (which says what ran, each
run its scenario): scenario files are not read, as they may have changed or gone (results
someone sent, a project folder moved)."""


def _stored(info: ValidationInfo) -> bool:
    return isinstance(info.context, dict) and bool(info.context.get("stored"))


def _recorded(info: ValidationInfo) -> bool:
    return isinstance(info.context, dict) and bool(info.context.get("scenario_recorded"))


def _check_search_on(
    name: str, requirements: list[str], tester: str, params: dict[str, Any]
) -> None:
    """Raises a validation error at ``search_on`` unless it names one of the requirements and
    the tester can search on it: an episode-level tester, or ``ppo-max`` (whose reward becomes
    the requirement's; not ``ppo-acc``, which sums the risk per decision, nor a novelty bonus,
    which pays for new contacts)."""
    names = [requirement.name for requirement in requirements_of(requirements)]
    if name not in names:
        known = ", ".join(names) or "none: name one with requirements / --requirement"
        raise invalid(("search_on",), f"is not one of the run's requirements ({known})", name)
    method = params.get("method", tester)
    registered = TESTERS.get(method) if isinstance(method, str) else None
    if registered is None or isinstance(registered.factory, type):
        return  # an episode-level tester, or one of the user's own
    try:
        built = make_tester(method, 0, {k: v for k, v in params.items() if k != "method"})
    except TesterParameterError:
        return  # reported as the parameter's own error
    if getattr(built, "reward", "max") != "max" or getattr(built, "novelty", 0.0) > 0.0:
        raise invalid(
            ("search_on",),
            f"tester {tester!r} learns from the risk summed per decision or from new "
            "contacts; search on a requirement with ppo-max (the requirement becomes its "
            "maximum-style reward) or an episode-level tester (portfolio, cem, qd)",
            name,
        )


def _check_tester_params(
    tester: str, params: dict[str, Any], env: EnvOptions, location: tuple[str | int, ...]
) -> None:
    """Raises a validation error at ``location`` + the parameter's key when the registered
    tester ``tester`` does not accept ``params``, or cannot search episodes of this length
    (its ``check_horizon``). Builds the tester once (which builds no model)."""
    try:
        built = make_tester(tester, 0, params)
    except TesterParameterError as error:
        raise invalid((*location, error.key), error.problem, params.get(error.key)) from None
    except ValueError:
        return  # an unknown tester: reported where it is named
    check = getattr(built, "check_horizon", None)
    if check is None:
        return
    try:
        check(decisions_in(env.episode_duration, env.decision_period))
    except TesterParameterError as error:
        raise invalid((*location, error.key), error.problem, params.get(error.key)) from None


def load_campaign(path: Path, classifier: PluginSpec | None = None) -> CampaignConfig:
    """Read and validate a campaign file and check its plug-ins; relative scenario file paths are
    relative to it.

    Args:
        path: The campaign file.
        classifier: A failure classifier that replaces the file's ``[classifier]``.

    Raises:
        ConfigError: Naming the file, the field and what is wrong.
    """
    try:
        data = loads_toml(read_input_text(path))
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such campaign file") from None
    except IsADirectoryError:
        raise ConfigError(f"{path}: is a directory, not a campaign file") from None
    except OSError as error:
        raise ConfigError(f"{path}: cannot be read: {error.strerror}") from None
    except UnicodeDecodeError as error:
        raise ConfigError(f"{path}: not a text file: {error.reason}") from None
    except tomllib.TOMLDecodeError as error:
        raise ConfigError(f"{path}: not valid TOML: {error}") from error
    scenarios = data.get("scenarios")
    if isinstance(scenarios, list):
        # A scenario file named in a campaign file is found next to the campaign file.
        data["scenarios"] = [
            str(path.parent / name)
            if isinstance(name, str) and name.endswith(".toml") and not Path(name).is_absolute()
            else name
            for name in scenarios
        ]
    requirements = data.get("requirements")
    if isinstance(requirements, list):
        # A requirements file named in a campaign file is found next to the campaign file.
        data["requirements"] = [
            str(path.parent / name)
            if isinstance(name, str) and ".toml" in name and not Path(name).is_absolute()
            else name
            for name in requirements
        ]
    if classifier is not None:
        data["classifier"] = classifier.model_dump()
    # A plug-in's module is found next to the campaign file or in the working directory.
    search_path = [str(path.parent.resolve()), str(Path.cwd())]
    for key in ("controller", "safety_layer", "classifier"):
        if isinstance(data.get(key), dict) and "search_path" not in data[key]:
            data[key]["search_path"] = search_path
    data["tester_plugins"] = _tester_plugins(path, data.get("tester"), search_path)
    try:
        config = CampaignConfig.model_validate(data)
    except ValidationError as error:
        raise ConfigError(f"{path}: {format_validation_error(error, CampaignConfig)}") from error
    try:
        check_plugins(config)
    except ConfigError as error:
        raise ConfigError(f"{path}: {error}") from None
    return config


def _tester_plugins(
    path: Path, tables: object, search_path: list[str]
) -> dict[str, dict[str, Any]]:
    """Takes the ``[tester.NAME]`` tables that have a ``path`` (a user's tester) out of
    ``tables``; returns them as ``tester_plugins``: the path, and the other keys as parameters."""
    if not isinstance(tables, dict):
        return {}
    plugins = {}
    for name in [n for n, table in tables.items() if isinstance(table, dict) and "path" in table]:
        params = tables.pop(name)
        import_path = params.pop("path")
        try:
            _check_plugin_name(name)
        except ValueError as error:
            raise ConfigError(f"{path}: tester.{name}: {error}") from None
        if not isinstance(import_path, str):
            raise ConfigError(
                f"{path}: tester.{name}.path: must be a string 'package.module:Class'"
            )
        plugins[name] = {"path": import_path, "params": params, "search_path": search_path}
    return plugins


def read_stored_campaign(path: Path) -> CampaignConfig | None:
    """The campaign configuration a results directory keeps in ``path`` (its
    ``campaign.json``), or None if that file cannot be read as one. It is read through the
    model, so a file written by an earlier version, which lacks the settings added since,
    takes their defaults and compares equal to the same campaign written today; its scenario
    files are not read (:data:`RECORDED`)."""
    try:
        return CampaignConfig.model_validate_json(path.read_bytes(), context=RECORDED)
    except (OSError, ValidationError):
        return None


def first_difference(stored: BaseModel, given: BaseModel) -> str:
    """The first setting in which two configurations of one kind differ, as ``key: there X,
    here Y`` (``stored`` is there, ``given`` here); a setting within a table is named by its
    dotted path (``estimator.method: there 'mc', here 'ce'``)."""
    there: Any = stored.model_dump(mode="json")
    here: Any = given.model_dump(mode="json")
    path = []
    while isinstance(there, dict) and isinstance(here, dict):
        key = next((k for k in (*there, *here) if there.get(k) != here.get(k)), None)
        if key is None:
            break
        path.append(key)
        there, here = there.get(key), here.get(key)
    return f"{'.'.join(path) or 'settings'}: there {there!r}, here {here!r}"


def check_output_location(out: Path, option: str = "--out") -> None:
    """Raises ConfigError unless results can be written to ``out``: it is a directory or can be
    made one (its nearest existing ancestor is a directory) that this process may write.
    Nothing is left behind (a probe file is created there and removed at once).

    Args:
        out: The run or campaign directory.
        option: How the user named it, for the message.
    """
    existing = out.absolute()
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise ConfigError(f"{option}: {existing} is a file, not a directory")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise ConfigError(f"{option}: cannot write in {existing} (read-only, or no permission)")
    try:  # what permissions do not tell: a read-only or virtual file system (/proc)
        with tempfile.TemporaryFile(dir=existing):
            pass
    except OSError as error:
        raise ConfigError(f"{option}: cannot write in {existing}: {error.strerror}") from None


def check_plugins(config: RunConfig | CampaignConfig) -> None:
    """Build every plug-in ``config`` names once, so that a bad one stops a run or campaign
    before anything runs. Validating a configuration builds no plug-in (only the registered
    testers, once each, to check their parameters); this is called where a command line or a
    campaign file is read.

    Raises:
        ConfigError: Naming the configuration's key and the problem.
    """
    for key, spec, build in _plugins(config):
        try:
            plugin = build(spec)
        except PluginError as error:
            raise ConfigError(f"{key}: {error}") from None
        if key == "controller":
            # build_controller has checked that it is a positive number.
            period = float(getattr(plugin, "control_period", 0.0))
            problem = decision_period_problem(config.env.decision_period, period)
            if problem is not None:
                raise ConfigError(f"env.decision_period: {problem}")


def _plugins(
    config: RunConfig | CampaignConfig,
) -> list[tuple[str, PluginSpec, Callable[[PluginSpec], object]]]:
    """Every plug-in of ``config``: its key, its specification and what builds it."""
    if isinstance(config, RunConfig):
        seed, testers = config.seed, {"tester": config.tester_plugin}
    else:
        seed = config.seeds[0]
        testers = {f"tester.{name}": spec for name, spec in config.tester_plugins.items()}
    named: list[tuple[str, PluginSpec | None, Callable[[PluginSpec], object]]] = [
        ("controller", config.controller, make_controller),
        ("safety_layer", config.safety_layer, make_safety_layer),
        ("classifier", config.classifier, make_classifier),
        *(
            (key, spec, functools.partial(make_plugin_tester, seed=seed))
            for key, spec in testers.items()
        ),
    ]
    return [(key, spec, build) for key, spec, build in named if spec is not None]
