"""The two reward formulations of the study (paper Eqs. 7 and 8), per decision step."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

RewardKind = Literal["acc", "max"]
REWARD_KINDS: tuple[RewardKind, ...] = ("acc", "max")


def decision_reward(
    kind: RewardKind, step_risks: Sequence[float], episode_max_risk: float, last: bool
) -> float:
    """Reward of one decision step.

    Args:
        kind: ``"acc"`` sums the risks of the physics steps within the decision step;
            ``"max"`` gives 0 until the episode's last decision step, which receives the
            largest risk of the whole episode.
        step_risks: Risks of the physics steps within this decision step.
        episode_max_risk: Largest risk of the episode so far, this decision step included.
        last: Whether this decision step ends the episode (terminated or truncated).
    """
    if kind == "acc":
        return float(sum(step_risks))
    if kind == "max":
        return float(episode_max_risk) if last else 0.0
    raise ValueError(f"unknown reward {kind!r}; choose one of {list(REWARD_KINDS)}")
