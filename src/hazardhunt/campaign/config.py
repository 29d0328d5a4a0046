"""Typed, validated configuration of a run and of a campaign (a grid of runs)."""

from __future__ import annotations

import functools
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
    field_validator,
)

from hazardhunt.campaign.plugins import (
    PluginSpec,
    make_classifier,
    make_controller,
    make_plugin_tester,
    make_safety_layer,
)
from hazardhunt.sut.plugins import PluginError
from hazardhunt.sut.safety_layer import FIELD_SETTINGS
from hazardhunt.testers.registry import TESTERS, make_tester
from hazardhunt.world.bodies import RobotParams
from hazardhunt.world.scenario import format_validation_error

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


class ConfigError(ValueError):
    """A run or campaign configuration that cannot be used; the message says what is wrong."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class EnvOptions(_Strict):
    """Environment parameters a run or campaign may override (defaults from SPEC)."""

    decision_period: float = Field(default=2.0, gt=0)
    """Time the human holds each action, in s (a multiple of 0.2 s)."""
    solver: Literal["fatrop", "ipopt"] = "fatrop"
    """The NMPC's solver."""
    episode_duration: float = Field(default=30.0, gt=0)
    """Simulated time after which an episode times out, in s."""
    stall_duration: float = Field(default=10.0, gt=0)
    """Continuous emergency-stop time after which an episode stalls, in s."""
    controller_timeout: float | None = Field(default=None, gt=0, allow_inf_nan=False)
    """Wall-clock limit on each call of the controller, in s: a call that exceeds it ends the
    episode as ``sut_error``. None: no limit (a limit makes results depend on the machine)."""
    robot: RobotParams = RobotParams()
    """The robot's size and limits (``[env.robot]``: length, width, max_speed, ...); the
    controller receives them in ``reset``."""


def _check_scenario(value: str) -> str:
    from hazardhunt.world.scenario import BUILTIN_SCENARIOS, ScenarioError, load_scenario

    if value in BUILTIN_SCENARIOS:
        return value
    if not value.endswith(".toml"):
        raise ValueError(
            f"unknown scenario {value!r}: use one of {', '.join(BUILTIN_SCENARIOS)} or a .toml file"
        )
    # Load it now, so that a broken scenario file stops the campaign before any run starts.
    try:
        load_scenario(value)
    except ScenarioError as error:
        raise ValueError(str(error)) from None
    # Absolute, so that replays, reports and exports find it from any working directory.
    return str(Path(value).resolve())


def _check_fields(scenario: str, fields: list[str]) -> None:
    """Raises ValueError unless every field is built in or defined by the scenario."""
    from hazardhunt.sut.safety_layer import field_shape
    from hazardhunt.world.scenario import BUILTIN_SCENARIOS, load_scenario

    if all(f in FIELD_SETTINGS for f in fields):
        return
    if scenario not in BUILTIN_SCENARIOS and not Path(scenario).is_file():
        return  # the scenario's own error is reported
    loaded = load_scenario(scenario)
    for name in fields:
        field_shape(loaded, name)


def _check_tester(value: str) -> str:
    if value not in TESTERS:
        raise ValueError(
            f"unknown tester {value!r}: use one of {', '.join(TESTERS)} or your own "
            "(package.module:Class)"
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
TesterName = Annotated[str, AfterValidator(_check_tester)]
"""A registered tester (``hazardhunt.testers.TESTERS``)."""
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
    seed: int = Field(ge=0)
    """Seeds every random choice of the run."""
    episodes: int = Field(gt=0)
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

    @field_validator("field")
    @classmethod
    def _field_ok(cls, value: str, info: ValidationInfo) -> str:
        if "scenario" in info.data:
            _check_fields(info.data["scenario"], [value])
        return value

    @field_validator("tester")
    @classmethod
    def _tester_ok(cls, value: str, info: ValidationInfo) -> str:
        if info.data.get("tester_plugin") is None:
            return _check_tester(value)
        return _check_plugin_name(value)

    @field_validator("tester_params")
    @classmethod
    def _tester_accepts_params(cls, values: dict[str, Any], info: ValidationInfo) -> dict[str, Any]:
        if "tester" not in info.data:  # the tester's own error is reported
            return values
        if info.data.get("tester_plugin") is not None:
            if values:
                raise ValueError("a user's tester takes the parameters of tester_plugin")
        else:
            _check_tester_params(info.data["tester"], values)
        return values

    @property
    def run_id(self) -> str:
        """A file-system-safe name for the run, unique within a campaign."""
        scenario, tester = (
            re.sub(r"[^A-Za-z0-9_.-]+", "_", name)
            for name in (Path(self.scenario).stem, self.tester)
        )
        return f"{scenario}__{self.field}__{tester}__seed{self.seed}"


class CampaignConfig(_Strict):
    """A grid of runs: every scenario x field x tester x seed, each with ``episodes``."""

    scenarios: list[ScenarioName] = Field(min_length=1)
    fields: list[FieldSetting] = Field(min_length=1)
    # Before ``testers``: their check needs to know the plug-ins' names.
    tester_plugins: dict[PluginTesterName, PluginSpec] = {}
    """Users' testers by name (in a campaign file, a ``[tester.NAME]`` table with a ``path``)."""
    testers: list[str] = Field(min_length=1)
    """Registered testers and names of ``tester_plugins``."""
    seeds: list[int] = Field(min_length=1)
    episodes: int = Field(gt=0)
    env: EnvOptions = EnvOptions()
    tester: dict[TesterName, dict[str, Any]] = {}
    """Per registered tester its keyword parameters, e.g. ``[tester.ppo-max]``."""
    controller: PluginSpec | None = None
    """The robot's controller of every run (``[controller]``); the built-in NMPC when None."""
    safety_layer: PluginSpec | None = None
    """The safety layer of every run (``[safety_layer]``); the laser field when None."""
    classifier: PluginSpec | None = None
    """The failure classifier of every run (``[classifier]``); the built-in one when None."""

    @field_validator("fields")
    @classmethod
    def _fields_ok(cls, values: list[str], info: ValidationInfo) -> list[str]:
        for scenario in info.data.get("scenarios", []):
            _check_fields(scenario, values)
        return values

    @field_validator("testers")
    @classmethod
    def _testers_known(cls, values: list[str], info: ValidationInfo) -> list[str]:
        for name in values:
            if name not in info.data.get("tester_plugins", {}):
                _check_tester(name)
        return values

    @field_validator("tester")
    @classmethod
    def _testers_accept_params(cls, values: dict[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
        for name, params in values.items():
            _check_tester_params(name, params)
        return values

    @field_validator("seeds")
    @classmethod
    def _seeds_ok(cls, values: list[int]) -> list[int]:
        if any(v < 0 for v in values):
            raise ValueError("seeds must be non-negative")
        if len(set(values)) != len(values):
            raise ValueError("seeds must be distinct")
        return values

    def runs(self) -> list[RunConfig]:
        """The runs of the grid, in a stable order."""
        return [
            RunConfig(
                scenario=scenario,
                field=field,
                tester_plugin=self.tester_plugins.get(tester),
                tester=tester,
                seed=seed,
                episodes=self.episodes,
                env=self.env,
                tester_params=self.tester.get(tester, {}),
                controller=self.controller,
                safety_layer=self.safety_layer,
                classifier=self.classifier,
            )
            for scenario in self.scenarios
            for field in self.fields
            for tester in self.testers
            for seed in self.seeds
        ]


def _check_tester_params(tester: str, params: dict[str, Any]) -> None:
    """Raises ValueError when tester ``tester`` does not accept ``params``."""
    if params:
        make_tester(tester, 0, params)  # builds no model: only checks the parameters


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
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such campaign file") from None
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
        raise ConfigError(f"{path}: {format_validation_error(error)}") from error
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


def check_plugins(config: RunConfig | CampaignConfig) -> None:
    """Build every plug-in ``config`` names once, so that a bad one stops a run or campaign
    before anything runs. Validating a configuration builds nothing; this is called where a
    command line or a campaign file is read.

    Raises:
        ConfigError: Naming the configuration's key and the problem.
    """
    for key, spec, build in _plugins(config):
        try:
            build(spec)
        except PluginError as error:
            raise ConfigError(f"{key}: {error}") from None


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
