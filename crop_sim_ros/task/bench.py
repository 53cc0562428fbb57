"""Speed of the irrigation task: single-environment steps/s and vectorised field-days/s.

``bench_env()`` prints and returns these figures (each the best of ``repeats`` timed runs, after a warm-up;
the action is a constant irrigation, episodes reset as they end), each printed with the machine's load
during its measurement (:class:`crop_sim_ros.throughput.MachineLoad`):

- ``env_steps``: raw ``IrrigationEnv.step`` calls;
- ``make_steps``: steps through ``gymnasium.make`` (with its checker and order wrappers);
- ``vector_field_days``: fields x days of ``IrrigationVectorEnv`` with ``num_fields`` fields, as it runs
  by default (the noise drawn on a worker thread when a second CPU is usable);
- ``vector_one_cpu_field_days``: the same with this thread pinned to one CPU and the noise drawn on it
  (the single-core figure, as under ``taskset -c 0``);
- ``model_floor_field_days``, ``noise_floor_field_days``: on that CPU, in turn with the vector figure
  (so all three see the same load), the two costs no speed work on the environment can remove: the
  batched SIMPLE step alone, and drawing the observation noise alone (10 float32 normals per field-day
  from the env's SFC64 stream);
- ``one_cpu_bound_field_days``: 1 / (1/model + 1/noise), the most the vector env can reach on this CPU
  with the current noise scheme (any other scheme would change every result computed so far).

Each is a :class:`crop_sim_ros.throughput.Rate`: per second of wall time and per second of this process's CPU
time (on a shared machine the second holds better).
"""

from __future__ import annotations

import os
from pathlib import Path

import gymnasium as gym
import numpy as np

from ..throughput import MachineLoad, Rate, best_rate, figure_line, interleaved_best_rates, measured
from ..model import step
from . import core, gym_id
from .env import IrrigationEnv
from .vector_env import IrrigationVectorEnv, PrefetchedNormal

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


def _vector_run(env: IrrigationVectorEnv, steps: int):
    """(run_once, field-days) of ``steps`` steps of ``env`` (reset, warmed up)."""
    actions = np.full((env.num_envs, 1), IRRIGATION_MM, dtype=np.float32)
    env.reset(seed=0)
    env.step(actions)

    def run_once():
        for _ in range(steps):
            env.step(actions)

    return run_once, steps * env.num_envs


def _model_run(env: IrrigationVectorEnv, steps: int):
    """(run_once, field-days) of the model step alone on ``env``'s fields: ``steps`` days in random seasons
    of its table, from sowing (again after the shortest season's days), the weather gathered beforehand."""
    irrigation_mm = np.full(env.num_envs, IRRIGATION_MM)
    state = core.initial(env.params, np.random.default_rng(0).integers(len(env.seasons), size=env.num_envs))
    days = []
    for _ in range(min(steps, int(env.seasons.n_days.min()))):
        days.append(core.daily_weather(env.seasons, state))
        state, _ = core.transition(env.params, env.seasons, state, irrigation_mm, weather=days[-1])

    def run_once():
        for day in range(steps):
            if day % len(days) == 0:
                crop = env.params.sowing_state
            crop, _ = step(env.params.fields, crop, days[day % len(days)], irrigation_mm)

    return run_once, steps * env.num_envs


def _noise_run(env: IrrigationVectorEnv, steps: int):
    """(run_once, field-days) of drawing the observation noise alone, as the env draws it on one CPU."""
    noise = PrefetchedNormal(0, env.num_envs, env.params.noise_columns, thread=False)
    shape = (env.num_envs, env.params.noise_columns)

    def run_once():
        for _ in range(steps):
            noise.standard_normal(shape)

    return run_once, steps * env.num_envs


def _vector_rate(env: IrrigationVectorEnv, steps: int, repeats: int) -> Rate:
    return best_rate(*_vector_run(env, steps), repeats)


def one_cpu_bound(model: Rate, noise: Rate) -> Rate:
    """The most a step costing the model's time plus the noise's time can reach (field-days/s)."""
    return Rate(*(1.0 / (1.0 / m + 1.0 / n) for m, n in zip(model, noise)))


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
    env_id = gym_id(scenario)
    echo(f"scenario {scenario}")
    results = {"env_steps": measured(
        "IrrigationEnv.step", lambda: _single_env_rate(IrrigationEnv(scenario, data_dir), steps, repeats),
        "steps", echo)}
    results["make_steps"] = measured(
        f"gymnasium.make({env_id})",
        lambda: _single_env_rate(gym.make(env_id, data_dir=data_dir), steps, repeats), "steps", echo)
    vector = IrrigationVectorEnv(num_fields, scenario, data_dir)
    where = "noise thread" if vector.noise_thread else "noise inline"
    results["vector_field_days"] = measured(f"IrrigationVectorEnv, {num_fields} fields ({where})",
                                            lambda: _vector_rate(vector, vector_steps, repeats), echo=echo)
    one_cpu = IrrigationVectorEnv(num_fields, scenario, data_dir, noise_thread=False)
    runs = {"vector_one_cpu_field_days": _vector_run(one_cpu, vector_steps),
            "model_floor_field_days": _model_run(one_cpu, vector_steps),
            "noise_floor_field_days": _noise_run(one_cpu, vector_steps)}
    load = MachineLoad()
    cpu, rates = on_one_cpu(lambda: interleaved_best_rates(runs, repeats))
    results.update(rates)
    results["one_cpu_bound_field_days"] = one_cpu_bound(rates["model_floor_field_days"],
                                                        rates["noise_floor_field_days"])
    labels = {"vector_one_cpu_field_days": f"IrrigationVectorEnv, {num_fields} fields, CPU {cpu} only",
              "model_floor_field_days": f"  floor: model step alone, CPU {cpu}",
              "noise_floor_field_days": f"  floor: noise alone ({one_cpu.params.noise_columns} normals/field-day)",
              "one_cpu_bound_field_days": "  bound 1/(1/model + 1/noise) on this CPU"}
    for key, label in labels.items():
        echo(figure_line(label, results[key], "field-days", load))
    return results


if __name__ == "__main__":
    bench_env()
