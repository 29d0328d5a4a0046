"""Typed, validated configuration of a run and of a campaign (a grid of runs)."""

from __future__ import annotations

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

from hazardhunt.campaign.plugins import PluginSpec, make_controller, make_safety_layer
from hazardhunt.sut.plugins import PluginError
from hazardhunt.sut.safety_layer import FIELD_SETTINGS
from hazardhunt.testers.registry import TESTERS, make_tester
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
    from hazardhunt.world.scenario import BUILTIN_SCENARIOS, field_shape, load_scenario

    if all(f in FIELD_SETTINGS for f in fields):
        return
    if scenario not in BUILTIN_SCENARIOS and not Path(scenario).is_file():
        return  # the scenario's own error is reported
    loaded = load_scenario(scenario)
    for name in fields:
        field_shape(loaded, name)


def _check_tester(value: str) -> str:
    if value not in TESTERS:
        raise ValueError(f"unknown tester {value!r}: use one of {', '.join(TESTERS)}")
    return value


ScenarioName = Annotated[str, AfterValidator(_check_scenario)]
"""A built-in scenario name or a scenario file that loads."""
FieldSetting = Annotated[str, Field(min_length=1)]
"""A protective-field setting: none, 1.25m, 2m or a field the scenario defines."""
TesterName = Annotated[str, AfterValidator(_check_tester)]
"""A registered tester (``hazardhunt.testers.TESTERS``)."""


class RunConfig(_Strict):
    """One tester x one scenario x one field setting x one seed x a budget of episodes."""

    scenario: ScenarioName
    """A built-in scenario name or a scenario file."""
    field: FieldSetting
    """Protective-field setting: none, 1.25m, 2m or a field the scenario defines."""
    tester: TesterName
    """The search method: a registered tester (``TESTERS``)."""
    seed: int = Field(ge=0)
    """Seeds every random choice of the run."""
    episodes: int = Field(gt=0)
    """Budget: number of episodes."""
    env: EnvOptions = EnvOptions()
    tester_params: dict[str, Any] = {}
    """Keyword parameters of the tester (for PPO: Stable-Baselines3 PPO arguments)."""
    controller: PluginSpec | None = None
    """The robot's controller; the built-in NMPC when None."""
    safety_layer: PluginSpec | None = None
    """The safety layer; the laser field of ``field`` when None."""

    @field_validator("field")
    @classmethod
    def _field_ok(cls, value: str, info: ValidationInfo) -> str:
        if "scenario" in info.data:
            _check_fields(info.data["scenario"], [value])
        return value

    @field_validator("tester_params")
    @classmethod
    def _tester_accepts_params(cls, values: dict[str, Any], info: ValidationInfo) -> dict[str, Any]:
        if "tester" in info.data:  # else the tester's own error is reported
            _check_tester_params(info.data["tester"], values)
        return values

    @property
    def run_id(self) -> str:
        """A file-system-safe name for the run, unique within a campaign."""
        scenario = re.sub(r"[^A-Za-z0-9_.-]+", "_", Path(self.scenario).stem)
        return f"{scenario}__{self.field}__{self.tester}__seed{self.seed}"


class CampaignConfig(_Strict):
    """A grid of runs: every scenario x field x tester x seed, each with ``episodes``."""

    scenarios: list[ScenarioName] = Field(min_length=1)
    fields: list[FieldSetting] = Field(min_length=1)
    testers: list[TesterName] = Field(min_length=1)
    seeds: list[int] = Field(min_length=1)
    episodes: int = Field(gt=0)
    env: EnvOptions = EnvOptions()
    tester: dict[TesterName, dict[str, Any]] = {}
    """Per-tester keyword parameters, e.g. ``[tester.ppo-max]``."""
    controller: PluginSpec | None = None
    """The robot's controller of every run (``[controller]``); the built-in NMPC when None."""
    safety_layer: PluginSpec | None = None
    """The safety layer of every run (``[safety_layer]``); the laser field when None."""

    @field_validator("fields")
    @classmethod
    def _fields_ok(cls, values: list[str], info: ValidationInfo) -> list[str]:
        for scenario in info.data.get("scenarios", []):
            _check_fields(scenario, values)
        return values

    @field_validator("tester")
    @classmethod
    def _testers_accept_params(
        cls, values: dict[TesterName, dict[str, Any]]
    ) -> dict[TesterName, dict[str, Any]]:
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
                tester=tester,
                seed=seed,
                episodes=self.episodes,
                env=self.env,
                tester_params=self.tester.get(tester, {}),
                controller=self.controller,
                safety_layer=self.safety_layer,
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


def load_campaign(path: Path) -> CampaignConfig:
    """Read and validate a campaign file and check its plug-ins; relative scenario file paths are
    relative to it.

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
    # A plug-in's module is found next to the campaign file or in the working directory.
    for key in ("controller", "safety_layer"):
        if isinstance(data.get(key), dict) and "search_path" not in data[key]:
            data[key]["search_path"] = [str(path.parent.resolve()), str(Path.cwd())]
    try:
        config = CampaignConfig.model_validate(data)
    except ValidationError as error:
        raise ConfigError(f"{path}: {format_validation_error(error)}") from error
    try:
        check_plugins(config)
    except ConfigError as error:
        raise ConfigError(f"{path}: {error}") from None
    return config


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
    named: list[tuple[str, PluginSpec | None, Callable[[PluginSpec], object]]] = [
        ("controller", config.controller, make_controller),
        ("safety_layer", config.safety_layer, make_safety_layer),
    ]
    return [(key, spec, build) for key, spec, build in named if spec is not None]
