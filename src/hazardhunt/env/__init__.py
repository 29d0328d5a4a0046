"""The Gymnasium environment: the workplace and its SUT behind the standard env API."""

from hazardhunt.env.agv import AGVEnv
from hazardhunt.env.observation import OBSERVATION_FEATURES

__all__ = ["OBSERVATION_FEATURES", "AGVEnv"]
