"""One bundle of simulation settings: the simulation, the environment, a run's configuration
and the command line all take it, and every field of a run's environment is reachable from
``hazardhunt run``."""

import json

import gymnasium as gym
import pandas as pd
import pytest

from hazardhunt import ENV_ID
from hazardhunt.campaign.config import EnvOptions
from hazardhunt.sim.simulation import Simulation, SimulationSettings
from hazardhunt.spec.outcomes import TerminationParams
from hazardhunt.sut.pursuit import PursuitController
from hazardhunt.world.bodies import RobotParams
from tests.helpers import hazardhunt


def test_the_configuration_s_options_are_the_simulation_s_settings():
    options = EnvOptions(decision_period=1.0, episode_duration=12.0, stall_duration=4.0)
    settings = options.settings()
    assert settings.termination == TerminationParams(12.0, 4.0)
    simulation = Simulation.build("crossing", "none", settings, controller=PursuitController())
    assert simulation.settings == settings
    assert simulation.horizon == 12


def test_a_change_to_one_setting_keeps_the_others():
    base = SimulationSettings(robot=RobotParams(max_speed=0.8))
    simulation = Simulation.build(
        "crossing", "none", base, controller=PursuitController(), decision_period=0.4
    )
    assert simulation.settings.decision_period == 0.4
    assert simulation.robot_params.max_speed == 0.8


def test_the_decision_period_as_third_argument_still_works_with_a_warning():
    with pytest.warns(FutureWarning, match="decision_period="):
        earlier = Simulation.build("crossing", "none", 1.0, controller=PursuitController())
    assert earlier.settings == SimulationSettings(decision_period=1.0)


def test_gymnasium_make_takes_any_setting():
    env = gym.make(ENV_ID, scenario="crossing", field="none", decision_period=1.0)
    assert env.unwrapped.simulation.decision_period == 1.0
    env.close()


def test_every_environment_option_is_reachable_from_the_command_line(tmp_path):
    out = tmp_path / "run"
    done = hazardhunt(
        "run", "--scenario", "crossing", "--field", "none", "--tester", "random",
        "--episodes", 3, "--out", out, "--controller", "hazardhunt.sut.pursuit:PursuitController",
        "--episode-duration", 8, "--stall-duration", 3, "--decision-period", 1.0,
        "--robot", "max_speed=0.9",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    env = json.loads((out / "config.json").read_text())["run"]["env"]
    assert env["episode_duration"] == 8.0
    assert env["stall_duration"] == 3.0
    assert env["robot"]["max_speed"] == 0.9
    episodes = pd.read_parquet(out / "episodes.parquet")
    assert episodes["sim_time"].max() <= 8.0 + 1e-9


def test_run_has_an_option_for_every_field_of_the_environment():
    shown = hazardhunt("run", "--help")
    for name in EnvOptions.model_fields:
        assert f"--{name.replace('_', '-')}" in shown.stdout, name
