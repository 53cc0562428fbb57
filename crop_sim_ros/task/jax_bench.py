"""``crop-sim bench --backend jax``: field-days per second of the model and of the environment on JAX beside numpy.

The model (:func:`bench_jax_model`): :func:`crop_sim_ros.model.step`, unchanged, called with ``xp=jax.numpy`` in
one jitted ``lax.scan`` over a season, beside the numpy array path (``crop-sim bench``'s workload,
:mod:`crop_sim_ros.model_workload`), in turn, float64 then float32, each precision's final biomass compared with
numpy's float64 (the fidelity printed).

The environment (:func:`bench_jax`): for each precision (float64 with ``jax_enable_x64``, then float32), the
numpy :class:`IrrigationVectorEnv` and the JAX environment (:mod:`crop_sim_ros.task.jax_env`: ``jax.vmap`` of
``step`` over the fields, ``lax.scan`` over the days, one jitted call per run, same-step resets, the noise drawn
from the key) step the same number of fields the same number of days with a constant irrigation, in turn
(:func:`~crop_sim_ros.throughput.interleaved_best_rates`: both see the same moments' load), each the best of
``repeats`` after a warm-up (the compilation excluded, and printed apart). The numpy environment is float64 in
both sections (it has no float32 mode): it is measured again beside each JAX figure.

Imports jax: only ``crop-sim bench --backend jax`` (and ``scripts/gpu_check.py``) load this module.
"""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np

from .. import model_workload as workload
from ..model import DailyWeather, FieldParameters, initial_state, repeat_parameters, step
from ..throughput import MachineLoad, figure_line, interleaved_best_rates
from .bench import IRRIGATION_MM, _vector_run
from .jax_env import JaxIrrigationEnv, _float, _int
from .vector_env import IrrigationVectorEnv

# Synthetic seasons of the model benchmark's weather pool: field i runs season i mod this (weather differing per
# field and day, gathered from the device as the environment gathers its pool's)
MODEL_POOL_SEASONS = 1_000


def _jax_model_state(num_fields: int):
    """The sowing-day state of ``num_fields`` benchmark fields and one field's parameters, as device arrays of
    this moment's precision."""
    one = workload.benton_potato()
    dtypes = {"days_since_sowing": _int(), "maturity_day": _int(), "mature": bool}
    state = {name: jnp.broadcast_to(jnp.asarray(value, dtypes.get(name, _float())), (num_fields,))
             for name, value in initial_state(one)._asdict().items()}
    params = FieldParameters(**{name: jnp.asarray(getattr(one, name), _float())
                                for name in FieldParameters.__dataclass_fields__})
    return type(initial_state(one))(**state), params


def jax_model_run(num_fields: int, echo=print, days: int = workload.SEASON_DAYS):
    """(run_once, field-days, final_biomass) of the SIMPLE step (:func:`crop_sim_ros.model.step` unchanged, called
    with ``xp=jax.numpy``) for ``num_fields`` fields over one ``days``-day season in one jitted ``lax.scan``, each
    field's weather a season of a pool of MODEL_POOL_SEASONS synthetic seasons (``crop-sim bench``'s); compiled and
    warmed up first. ``final_biomass()``: the first pool's fields' final biomass (kg ha-1), for the fidelity."""
    pool = min(num_fields, MODEL_POOL_SEASONS)
    table = jnp.asarray(np.stack(workload.season_weather(days, pool, 0)), _float())  # (5, days, pool)
    state, params = _jax_model_state(num_fields)
    season = jnp.arange(num_fields) % pool

    @jax.jit
    def run(state):
        def day(state, d):
            weather = DailyWeather(*table[:, d, season])
            return step(params, state, weather, workload.IRRIGATION_MM, xp=jnp)[0], None

        return jax.lax.scan(day, state, jnp.arange(days))[0].biomass_kg_ha

    start = time.perf_counter()
    run(state).block_until_ready()
    echo(f"  (JAX model {jnp.zeros(()).dtype}, {num_fields:,} fields: compiled and warmed up in "
         f"{time.perf_counter() - start:.1f} s)")
    return (lambda: run(state).block_until_ready()), num_fields * days, lambda: np.asarray(run(state)[:pool])


def numpy_final_biomass(pool: int = MODEL_POOL_SEASONS, days: int = workload.SEASON_DAYS) -> np.ndarray:
    """The numpy model's final biomass (kg ha-1) of the pool's ``pool`` seasons (float64: the reference)."""
    weather = workload.season_weather(days, pool, 0)
    params = repeat_parameters(workload.benton_potato(), pool)
    state = initial_state(params)
    for d in range(days):
        state, _ = step(params, state, DailyWeather(*(w[d] for w in weather)), workload.IRRIGATION_MM)
    return state.biomass_kg_ha


def bench_jax_model(num_fields: int = 10_000, numpy_fields: int = 10_000, repeats: int = 3, echo=print) -> dict:
    """The model alone: numpy (``numpy_fields`` fields, float64) and JAX (``num_fields``, float64 then float32) in
    turn, each precision's JAX final biomass compared with numpy's (largest relative difference)."""
    results = {}
    reference = numpy_final_biomass(min(num_fields, MODEL_POOL_SEASONS))
    for x64 in (True, False):
        with jax.enable_x64(x64):
            precision = "float64" if x64 else "float32"
            run_once, work, final_biomass = jax_model_run(num_fields, echo)
            runs = {f"numpy_model_{precision}": workload.model_run(numpy_fields),
                    f"jax_model_{precision}": (run_once, work)}
            load = MachineLoad()
            rates = interleaved_best_rates(runs, repeats)
            difference = float(np.max(np.abs(final_biomass() - reference) / np.abs(reference)))
        results.update(rates)
        results[f"jax_model_{precision}_max_relative_difference"] = difference
        echo(figure_line(f"SIMPLE model, numpy float64, N = {numpy_fields:,}", rates[f"numpy_model_{precision}"],
                         "field-days", load))
        echo(figure_line(f"SIMPLE model, JAX {precision}, N = {num_fields:,} (jit+scan)",
                         rates[f"jax_model_{precision}"], "field-days", load))
        ratio = rates[f"jax_model_{precision}"].per_s / rates[f"numpy_model_{precision}"].per_s
        echo(f"  JAX {precision} / numpy: {ratio:.2f}x (wall); final biomass vs numpy float64: largest relative "
             f"difference {difference:.1e}")
    return results


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
              echo=print, numpy_fields: int | None = None) -> dict:
    """Measure and print the figures (see the module docstring); returns them by name. ``numpy_fields``: the
    numpy environment's fields, if not ``num_fields`` (a GPU's million fields would take the host minutes)."""
    numpy_fields = num_fields if numpy_fields is None else numpy_fields
    vector = IrrigationVectorEnv(numpy_fields, scenario)
    env = JaxIrrigationEnv(scenario, table=vector.seasons)
    echo(f"scenario {scenario}, {num_fields:,} fields (numpy: {numpy_fields:,}), {steps} days a run, best of "
         f"{repeats} (numpy and JAX in turn); JAX {jax.__version__} on {jax.devices()[0].platform}")
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
