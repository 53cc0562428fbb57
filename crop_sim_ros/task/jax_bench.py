"""``crop-sim bench --backend jax``: field-days per second of the JAX environment beside the numpy vector env.

For each precision (float64 with ``jax_enable_x64``, then float32), the numpy :class:`IrrigationVectorEnv` and the
JAX environment (:mod:`crop_sim_ros.task.jax_env`: ``jax.vmap`` of ``step`` over the fields, ``lax.scan`` over the
days, one jitted call per run, same-step resets, the noise drawn from the key) step the same number of fields
the same number of days with a constant irrigation, in turn (:func:`~crop_sim_ros.throughput.interleaved_best_rates`:
both see the same moments' load), each the best of ``repeats`` after a warm-up (the compilation excluded, and
printed apart). The numpy environment is float64 in both sections (it has no float32 mode): it is measured again
beside each JAX figure. Imports jax: only ``crop-sim bench --backend jax`` loads this module.
"""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp

from ..throughput import MachineLoad, figure_line, interleaved_best_rates
from .bench import IRRIGATION_MM, _vector_run
from .jax_env import JaxIrrigationEnv
from .vector_env import IrrigationVectorEnv


def _jax_run(env: JaxIrrigationEnv, num_fields: int, steps: int, echo):
    """(run_once, field-days) of ``steps`` days of ``num_fields`` fields of ``env`` in one jitted call (the state
    carried from run to run, as the numpy env's), compiled and warmed up first."""
    params = env.default_params

    @jax.jit
    def reset(key):
        return jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(key, num_fields), params)

    @jax.jit
    def run(key, state):
        def day(carry, _):
            key, state = carry
            key, sub = jax.random.split(key)
            _, state, reward, _, _ = jax.vmap(env.step, in_axes=(0, 0, None, None))(
                jax.random.split(sub, num_fields), state, IRRIGATION_MM, params)
            return (key, state), reward.sum()

        (key, state), rewards = jax.lax.scan(day, (key, state), None, length=steps)
        return key, state, rewards.sum()

    start = time.perf_counter()
    carried = [jax.random.key(1), reset(jax.random.key(0))[1]]

    def run_once():
        key, state, total = run(*carried)
        total.block_until_ready()
        carried[:] = [key, state]

    run_once()
    echo(f"  (JAX {jnp.zeros(()).dtype}: compiled and warmed up in {time.perf_counter() - start:.1f} s)")
    return run_once, steps * num_fields


def bench_jax(scenario: str = "benton-generated", num_fields: int = 10_000, steps: int = 200, repeats: int = 3,
              echo=print) -> dict:
    """Measure and print the figures (see the module docstring); returns them by name."""
    vector = IrrigationVectorEnv(num_fields, scenario)
    env = JaxIrrigationEnv(scenario, table=vector.seasons)
    echo(f"scenario {scenario}, {num_fields} fields, {steps} days a run, best of {repeats} (numpy and JAX in turn); "
         f"JAX {jax.__version__} on {jax.devices()[0].platform}")
    results = {}
    for x64 in (True, False):
        with jax.enable_x64(x64):
            precision = "float64" if x64 else "float32"
            runs = {f"numpy_vector_{precision}": _vector_run(vector, steps),
                    f"jax_{precision}": _jax_run(env, num_fields, steps, echo)}
            load = MachineLoad()
            rates = interleaved_best_rates(runs, repeats)
        results.update(rates)
        where = "noise thread" if vector.noise_thread else "noise inline"
        echo(figure_line(f"IrrigationVectorEnv (numpy float64, {where})", rates[f"numpy_vector_{precision}"],
                         "field-days", load))
        echo(figure_line(f"JaxIrrigationEnv ({precision}, jit+vmap+scan)", rates[f"jax_{precision}"], "field-days",
                         load))
        ratio = rates[f"jax_{precision}"].per_s / rates[f"numpy_vector_{precision}"].per_s
        echo(f"  JAX {precision} / numpy: {ratio:.2f}x (wall)")
    return results


if __name__ == "__main__":
    bench_jax()
