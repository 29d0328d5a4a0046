"""The two reward formulations of the study (paper Eqs. 7 and 8), per decision step."""

from __future__ import annotations

from typing import Literal

RewardKind = Literal["acc", "max"]
REWARD_KINDS: tuple[RewardKind, ...] = ("acc", "max")


def decision_reward(
    kind: RewardKind, step_risk_sum: float, episode_max_risk: float, last: bool
) -> float:
    """Reward of one decision step.

    Args:
        kind: ``"acc"`` sums the risks of the physics steps within the decision step;
            ``"max"`` gives 0 until the episode's last decision step, which receives the
            largest risk of the whole episode.
        step_risk_sum: The risk summed over the physics steps within this decision step.
        episode_max_risk: Largest risk of the episode so far, this decision step included.
        last: Whether this decision step ends the episode (terminated or truncated).
    """
    if kind == "acc":
        return float(step_risk_sum)
    if kind == "max":
        return float(episode_max_risk) if last else 0.0
    raise ValueError(f"unknown reward {kind!r}; choose one of {list(REWARD_KINDS)}")
