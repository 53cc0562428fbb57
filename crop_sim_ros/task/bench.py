"""Speed of the irrigation task: single-environment steps/s and vectorised field-days/s.

``bench_env()`` prints and returns these figures (each the best of ``repeats`` timed runs, after a warm-up;
the action is a constant irrigation, episodes reset as they end), each printed with the machine's load
during its measurement (:class:`crop_sim_ros.bench.MachineLoad`):

- ``env_steps``: raw ``IrrigationEnv.step`` calls;
- ``make_steps``: steps through ``gymnasium.make`` (with its checker and order wrappers);
- ``vector_field_days``: fields x days of ``IrrigationVectorEnv`` with ``num_fields`` fields, as it runs
  by default (the noise drawn on a worker thread when a second CPU is usable);
- ``vector_one_cpu_field_days``: the same with this thread pinned to one CPU and the noise drawn on it
  (the single-core figure, as under ``taskset -c 0``).

Each is a :class:`crop_sim_ros.bench.Rate`: per second of wall time and per second of this process's CPU
time (on a shared machine the second holds better).
"""

from __future__ import annotations

import os
from pathlib import Path

import gymnasium as gym
import numpy as np

from ..bench import MachineLoad, Rate, best_rate, figure_line, measured
from . import ENV_IDS
from .env import IrrigationEnv
from .vector_env import IrrigationVectorEnv

IRRIGATION_MM = 3.0


def _single_env_rate(env, steps: int, repeats: int) -> Rate:
    action = np.array([IRRIGATION_MM], dtype=np.float32)
    env.reset(seed=0)

    def run_once():
        for _ in range(steps):
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()

    return best_rate(run_once, steps, repeats)


def _vector_rate(env: IrrigationVectorEnv, steps: int, repeats: int) -> Rate:
    actions = np.full((env.num_envs, 1), IRRIGATION_MM, dtype=np.float32)
    env.reset(seed=0)
    env.step(actions)

    def run_once():
        for _ in range(steps):
            env.step(actions)

    return best_rate(run_once, steps * env.num_envs, repeats)


def on_one_cpu(measure):
    """``measure()`` with this thread pinned to the first CPU it may use (as ``taskset -c``), then unpinned;
    returns (that CPU, the result)."""
    allowed = os.sched_getaffinity(0)
    cpu = min(allowed)
    os.sched_setaffinity(0, {cpu})
    try:
        return cpu, measure()
    finally:
        os.sched_setaffinity(0, allowed)


def bench_env(scenario: str = "benton-generated", steps: int = 20_000, num_fields: int = 10_000,
              vector_steps: int = 200, repeats: int = 3, data_dir: str | Path | None = None,
              echo=print) -> dict[str, Rate]:
    """Measure (see the module docstring) and print the figures with ``echo``; returns them."""
    env_id = next((i for i, name in ENV_IDS.items() if name == scenario), None)
    echo(f"scenario {scenario}")
    results = {"env_steps": measured(
        "IrrigationEnv.step", lambda: _single_env_rate(IrrigationEnv(scenario, data_dir), steps, repeats),
        "steps", echo)}
    if env_id is not None:
        results["make_steps"] = measured(
            f"gymnasium.make({env_id})",
            lambda: _single_env_rate(gym.make(env_id, data_dir=data_dir), steps, repeats), "steps", echo)
    vector = IrrigationVectorEnv(num_fields, scenario, data_dir)
    where = "noise thread" if vector.noise_thread else "noise inline"
    results["vector_field_days"] = measured(f"IrrigationVectorEnv, {num_fields} fields ({where})",
                                            lambda: _vector_rate(vector, vector_steps, repeats), echo=echo)
    one_cpu = IrrigationVectorEnv(num_fields, scenario, data_dir, noise_thread=False)
    load = MachineLoad()
    cpu, results["vector_one_cpu_field_days"] = on_one_cpu(lambda: _vector_rate(one_cpu, vector_steps, repeats))
    echo(figure_line(f"IrrigationVectorEnv, {num_fields} fields, CPU {cpu} only", results["vector_one_cpu_field_days"],
                     "field-days", load))
    return results


if __name__ == "__main__":
    bench_env()
