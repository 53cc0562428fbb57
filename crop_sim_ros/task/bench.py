"""Speed of the irrigation task: single-environment steps/s and vectorised field-days/s.

``bench_env()`` prints and returns three figures (each the best of ``repeats`` timed runs, after a warm-up;
the action is a constant irrigation, episodes reset as they end):

- ``env_steps_per_s``: raw ``IrrigationEnv.step`` calls per second;
- ``make_steps_per_s``: steps per second through ``gymnasium.make`` (with its checker and order wrappers);
- ``vector_field_days_per_s``: fields x days per second of ``IrrigationVectorEnv`` with ``num_fields`` fields.
"""

from __future__ import annotations

import time
from pathlib import Path

import gymnasium as gym
import numpy as np

from . import ENV_IDS
from .env import IrrigationEnv
from .vector_env import IrrigationVectorEnv

IRRIGATION_MM = 3.0


def _single_env_rate(env, steps: int, repeats: int) -> float:
    action = np.array([IRRIGATION_MM], dtype=np.float32)
    env.reset(seed=0)
    best = 0.0
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(steps):
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
        best = max(best, steps / (time.perf_counter() - start))
    return best


def _vector_rate(env: IrrigationVectorEnv, steps: int, repeats: int) -> float:
    actions = np.full((env.num_envs, 1), IRRIGATION_MM, dtype=np.float32)
    env.reset(seed=0)
    env.step(actions)
    best = 0.0
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(steps):
            env.step(actions)
        best = max(best, steps * env.num_envs / (time.perf_counter() - start))
    return best


def bench_env(scenario: str = "benton-generated", steps: int = 20_000, num_fields: int = 10_000,
              vector_steps: int = 200, repeats: int = 3, data_dir: str | Path | None = None,
              echo=print) -> dict[str, float]:
    """Measure (see the module docstring) and print the figures with ``echo``; returns them."""
    env_id = next((i for i, name in ENV_IDS.items() if name == scenario), None)
    results = {"env_steps_per_s": _single_env_rate(IrrigationEnv(scenario, data_dir), steps, repeats)}
    if env_id is not None:
        results["make_steps_per_s"] = _single_env_rate(gym.make(env_id, data_dir=data_dir), steps, repeats)
    vector = IrrigationVectorEnv(num_fields, scenario, data_dir)
    results["vector_field_days_per_s"] = _vector_rate(vector, vector_steps, repeats)
    echo(f"scenario {scenario}")
    echo(f"  IrrigationEnv.step:                 {results['env_steps_per_s']:>12,.0f} steps/s")
    if "make_steps_per_s" in results:
        echo(f"  gymnasium.make({env_id}): {results['make_steps_per_s']:>12,.0f} steps/s")
    echo(f"  IrrigationVectorEnv, {num_fields} fields:  {results['vector_field_days_per_s']:>12,.0f} field-days/s")
    return results


if __name__ == "__main__":
    bench_env()
