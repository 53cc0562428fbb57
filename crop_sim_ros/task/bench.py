"""Speed of the irrigation task: single-environment steps/s and vectorised field-days/s.

``bench_env()`` prints and returns these figures (each the best of ``repeats`` timed runs, after a warm-up;
the action is a constant irrigation, episodes reset as they end), each printed with the machine's load
during its measurement (:class:`crop_sim_ros.bench.MachineLoad`):

- ``env_steps_per_s``: raw ``IrrigationEnv.step`` calls per second;
- ``make_steps_per_s``: steps per second through ``gymnasium.make`` (with its checker and order wrappers);
- ``vector_field_days_per_s``: fields x days per second of ``IrrigationVectorEnv`` with ``num_fields``
  fields, as it runs by default (the noise drawn on a worker thread when a second CPU is usable);
- ``vector_one_cpu_field_days_per_s``: the same with this thread pinned to one CPU and the noise drawn on
  it (the single-core figure, as under ``taskset -c 0``), and ``vector_one_cpu_per_cpu_second``: field-days
  per second of this process's CPU time in that run (what an unshared core would give).
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

from ..bench import MachineLoad, figure_line, measured
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


def _vector_rate(env: IrrigationVectorEnv, steps: int, repeats: int) -> tuple[float, float]:
    """Best field-days per second of wall time, and per second of this process's CPU time in that run."""
    actions = np.full((env.num_envs, 1), IRRIGATION_MM, dtype=np.float32)
    env.reset(seed=0)
    env.step(actions)
    best = (0.0, 0.0)
    for _ in range(repeats):
        start, cpu = time.perf_counter(), time.process_time()
        for _ in range(steps):
            env.step(actions)
        wall, cpu = time.perf_counter() - start, time.process_time() - cpu
        best = max(best, (steps * env.num_envs / wall, steps * env.num_envs / max(cpu, 1e-9)))
    return best


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
              echo=print) -> dict[str, float]:
    """Measure (see the module docstring) and print the figures with ``echo``; returns them."""
    env_id = next((i for i, name in ENV_IDS.items() if name == scenario), None)
    echo(f"scenario {scenario}")
    results = {"env_steps_per_s": measured(
        "IrrigationEnv.step", lambda: _single_env_rate(IrrigationEnv(scenario, data_dir), steps, repeats),
        "steps/s", echo)}
    if env_id is not None:
        results["make_steps_per_s"] = measured(
            f"gymnasium.make({env_id})",
            lambda: _single_env_rate(gym.make(env_id, data_dir=data_dir), steps, repeats), "steps/s", echo)
    vector = IrrigationVectorEnv(num_fields, scenario, data_dir)
    where = "noise thread" if vector.noise_thread else "noise inline"
    results["vector_field_days_per_s"] = measured(
        f"IrrigationVectorEnv, {num_fields} fields ({where})",
        lambda: _vector_rate(vector, vector_steps, repeats)[0], "field-days/s", echo)
    one_cpu = IrrigationVectorEnv(num_fields, scenario, data_dir, noise_thread=False)
    load = MachineLoad()
    cpu, (wall_rate, per_cpu_second) = on_one_cpu(lambda: _vector_rate(one_cpu, vector_steps, repeats))
    echo(figure_line(f"IrrigationVectorEnv, {num_fields} fields, one CPU", wall_rate, "field-days/s", load))
    echo(f"    (pinned to CPU {cpu}, noise on the main thread; {per_cpu_second:,.0f} field-days per second of "
         f"this process's CPU time)")
    results["vector_one_cpu_field_days_per_s"] = wall_rate
    results["vector_one_cpu_per_cpu_second"] = per_cpu_second
    return results


if __name__ == "__main__":
    bench_env()
