"""What stepping two envs in lockstep costs PPO with ``n_envs = 2``, from one env's decisions.

SB3 steps its vectorised envs together: a step of two envs lasts as long as the slower of
the two decisions (an env that ends its episode also resets within the step), and PPO's update
and its policy run while the env workers wait. This script times each decision of one env
(CPU time, undisturbed by other work on the machine) under uniform random actions, then pairs
decisions at random: the mean of one decision against the mean of the slower of two is the
share of the env workers' time that does work in lockstep.

    python benchmarks/lockstep.py --episodes 40
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from hazardhunt.env.agv import AGVEnv


def decision_times(episodes: int, seed: int, scenario: str, field: str) -> np.ndarray:
    """CPU seconds of every decision (the reset after an episode counted in its last one)."""
    env = AGVEnv(scenario, field, reward="max")
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    times = []
    for _ in range(episodes):
        done = False
        while not done:
            started = time.process_time()
            _, _, terminated, truncated, _ = env.step(rng.uniform(-1, 1, 2).astype(np.float32))
            done = terminated or truncated
            if done:
                env.reset()
            times.append(time.process_time() - started)
    return np.asarray(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=40)
    parser.add_argument("--scenario", default="crossing")
    parser.add_argument("--field", default="1.25m")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    times = decision_times(args.episodes, args.seed, args.scenario, args.field)
    pairs = np.random.default_rng(args.seed).choice(times, size=(100_000, 2))
    slower = pairs.max(axis=1).mean()
    print(
        f"{len(times)} decisions: mean {1000 * times.mean():.2f} ms, median "
        f"{1000 * np.median(times):.2f} ms, p95 {1000 * np.percentile(times, 95):.2f} ms; "
        f"the slower of two: mean {1000 * slower:.2f} ms; work share of the env workers in "
        f"lockstep {times.mean() / slower:.2f}"
    )


if __name__ == "__main__":
    main()
