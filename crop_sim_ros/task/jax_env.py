"""The irrigation task on JAX: a gymnax-style environment of one field, jit-able and vmap-able.

The same task as :class:`~crop_sim_ros.task.vector_env.IrrigationVectorEnv`, from the same functional core
(:mod:`crop_sim_ros.task.core`, called with ``xp=jax.numpy``) and the same crop model
(:func:`crop_sim_ros.model.step`, unchanged), in the API of gymnax (and so of PureJaxRL- and evosax-style code):

.. code-block:: python

    import jax
    import jax.numpy as jnp
    from crop_sim_ros.task.jax_env import make_jax_env

    env = make_jax_env("benton-quota")            # every registered task, by name
    params = env.default_params                   # its weather pool, on the device
    keys = jax.random.split(jax.random.key(0), 1024)
    obs, state = jax.vmap(env.reset, in_axes=(0, None))(keys, params)              # 1024 fields
    obs, state, reward, done, info = jax.jit(jax.vmap(env.step, in_axes=(0, 0, 0, None)))(
        keys, state, jnp.full(1024, 3.0), params)

One environment is one field (state: scalars); ``jax.vmap`` makes a batch. The weather pool is
:class:`EnvParams` (the scenario's season table as device arrays: each field gathers its day of its season);
give ``params_of(table, max_steps, env.task)`` for another pool. :meth:`JaxIrrigationEnv.step` resets a field whose season ended on
the same step (gymnax's rule: the returned observation and state are the new season's; ``reward`` and ``done``
the ending step's; ``info`` holds ``terminated``, ``truncated`` and ``discount``);
:meth:`JaxIrrigationEnv.step_env` does not. Randomness: the new season, its drawn terms (prices, quota) and the
observation noise come from the key; :meth:`JaxIrrigationEnv.reset_with` and :meth:`JaxIrrigationEnv.step_with`
take them given instead (the same noise as the numpy environment gives the same observations).

Precision: float64 when ``jax_enable_x64`` is on (on every task, given the same noise: the observation bit for
bit, the reward within 3e-16 relative of the numpy environment's, termination and truncation the same), float32
otherwise; the observation is float32 either way, as the numpy environment's. Actions are mm of
irrigation, clipped to [0, max_irrigation_mm] and cut to the capacity and quota left as the numpy environment
does; under ``jit`` nothing can be refused, so a NaN action gives NaN (check actions outside).

This module imports jax: ``crop_sim_ros.task`` never imports it (``pip install crop_sim_ros[jax]``).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from ..model import CropState, FieldParameters
from . import core
from .scenario import Scenario, get_scenario, longest_season_days, scenario_names

__all__ = ["Box", "EnvParams", "JaxIrrigationEnv", "TaskNumbers", "make_jax_env", "params_of", "task_numbers"]


class _JaxMath:
    """jax.numpy, and ``round_to_float32``: float64 values rounded to float32 precision as an operation XLA keeps
    (``lax.reduce_precision``), so that a float32 product is not fused with the next addition (see
    :func:`crop_sim_ros.task.core._observation_functional`); float32 values unchanged."""

    def __getattr__(self, name: str):
        return getattr(jnp, name)

    @staticmethod
    def round_to_float32(values):
        if values.dtype == jnp.float32:
            return values
        return jax.lax.reduce_precision(values, exponent_bits=8, mantissa_bits=23)


JAX_MATH = _JaxMath()


class TaskNumbers(NamedTuple):
    """The task's numbers (a pytree of scalars and arrays, traced under ``jit``): the field's model parameters
    (name -> value, :class:`~crop_sim_ros.model.FieldParameters`) and sowing-day state, the observation noise's
    std (float32, see :class:`~crop_sim_ros.task.core.TaskParams`), and the terms: the ranges each episode draws
    from (low == high: fixed), the dry-matter fraction, the daily capacity (mm d-1) and the nominal season."""

    fields: dict
    sowing_state: CropState
    noise_std: jax.Array
    yield_value_per_t: jax.Array       # (2,) low, high
    water_price_per_mm: jax.Array      # (2,)
    pumping_energy_per_mm: jax.Array   # (2,)
    quota_mm: jax.Array                # (2,)
    dry_matter_fraction: jax.Array
    capacity_mm_per_day: jax.Array
    nominal_season_days: jax.Array


class EnvParams(NamedTuple):
    """The environment's parameters (a pytree of device arrays): the weather pool of M seasons, as the
    :class:`~crop_sim_ros.task.core.SeasonTable` arrays the step reads, the episode's step limit (what
    ``gymnasium.make`` puts in a ``TimeLimit``: the task's longest season) and the task's numbers."""

    observation_rows: jax.Array    # (M, D + 1, 20) float32
    model_weather: jax.Array       # (5, M, D + 2) float
    et0_mm: jax.Array              # (M, D + 2) float
    n_days: jax.Array              # (M,) int
    potential_yield_t_ha: jax.Array  # (M,) float
    max_steps_in_episode: jax.Array  # () int
    task: TaskNumbers


def task_numbers(task: core.TaskParams) -> TaskNumbers:
    """The numbers of ``task`` (its first field) as device arrays (float64 with ``jax_enable_x64``)."""
    one = core.scalar_task_params(task)
    f, i = _float(), _int()
    sow = one.sowing_state
    dtypes = {"days_since_sowing": i, "maturity_day": i, "mature": bool}
    crop = CropState(**{name: jnp.asarray(value, dtypes.get(name, f)) for name, value in sow._asdict().items()})
    ranges = (task.yield_value_per_t, task.water_price_per_mm, task.pumping_energy_per_mm, task.quota_mm)
    fields = {name: jnp.asarray(getattr(one.fields, name), f) for name in FieldParameters.__dataclass_fields__}
    return TaskNumbers(fields, crop, jnp.asarray(task.noise_std, jnp.float32),
                       *(jnp.asarray([r.low, r.high], f) for r in ranges),
                       jnp.asarray(task.dry_matter_fraction, f), jnp.asarray(task.capacity_mm_per_day, f),
                       jnp.asarray(task.nominal_season_days, i))


def params_of(table: core.SeasonTable, max_steps_in_episode: int, task: core.TaskParams) -> EnvParams:
    """``table`` and ``task``'s numbers as device arrays (float64 when ``jax_enable_x64`` is on, else float32)."""
    return EnvParams(jnp.asarray(table.observation_rows), jnp.asarray(table.model_weather),
                     jnp.asarray(table.et0_mm), jnp.asarray(table.n_days), jnp.asarray(table.potential_yield_t_ha),
                     jnp.asarray(max_steps_in_episode), task_numbers(task))


class Box:
    """gymnax's ``spaces.Box``: ``low``, ``high``, ``shape``, ``dtype``, ``sample(key)``, ``contains(x)``."""

    def __init__(self, low, high, shape: tuple[int, ...], dtype=jnp.float32):
        self.low, self.high, self.shape, self.dtype = low, high, tuple(shape), dtype

    def sample(self, key: jax.Array) -> jax.Array:
        """Uniform in [low, high] where both are finite; standard normal above a finite low bound else."""
        low = jnp.broadcast_to(jnp.asarray(self.low, self.dtype), self.shape)
        high = jnp.broadcast_to(jnp.asarray(self.high, self.dtype), self.shape)
        uniform = jax.random.uniform(key, self.shape, self.dtype)
        bounded = jnp.isfinite(low) & jnp.isfinite(high)
        return jnp.where(bounded, low + uniform * (high - low),
                         jnp.where(jnp.isfinite(low), low, 0.0) + jax.random.normal(key, self.shape, self.dtype) ** 2)

    def contains(self, x) -> jax.Array:
        x = jnp.asarray(x)
        return jnp.logical_and(jnp.all(x >= self.low), jnp.all(x <= self.high)) & (x.shape == self.shape)

    def __repr__(self) -> str:
        return f"Box(shape={self.shape}, dtype={jnp.dtype(self.dtype).name})"


def _float() -> jnp.dtype:
    """The float dtype of this moment's JAX configuration (float64 with ``jax_enable_x64``)."""
    return jnp.zeros(()).dtype


def _int() -> jnp.dtype:
    return jnp.zeros((), dtype=int).dtype


class JaxIrrigationEnv:
    """One field of ``scenario`` (a task name or a :class:`Scenario`) in gymnax's API (see the module docstring).

    ``table``: the weather pool (default: the scenario's, as the numpy environments use it).

    Every number of the task is in :class:`EnvParams` (traced); the environment object holds only what shapes
    the computation (the observation layout, the noise columns, whether irrigation may be cut, the PAW sensor,
    the dropout probability, the event cost and the action bound). Two environments with the same shape compare
    equal, so ``jax.jit(env.step)`` compiles once for all the tasks of that shape (given pools of one size).
    """

    def __init__(self, scenario: str | Scenario = "benton-generated", data_dir: str | Path | None = None,
                 table: core.SeasonTable | None = None, max_steps_in_episode: int | None = None):
        if isinstance(scenario, Scenario):
            self.scenario = scenario
        else:
            if scenario not in scenario_names():
                raise ValueError(f"{scenario!r} is not a built-in task; known: {', '.join(scenario_names())}")
            self.scenario = get_scenario(scenario, data_dir)
        self.task = core.task_params(self.scenario, 1)
        self._table = table
        if max_steps_in_episode is None:
            max_steps_in_episode = (longest_season_days(self.scenario.name) if self.scenario.name in scenario_names()
                                    else self.scenario.max_season_days)
        self.max_steps_in_episode = int(max_steps_in_episode)
        task = self.task
        self._shape = (task.layout, bool(task.noisy), int(task.noise_columns), bool(task.limited),
                       float(task.paw_dropout_probability), bool(task.paw_sensor), float(task.event_cost),
                       float(task.max_irrigation_mm))
        self._params: dict[str, EnvParams] = {}

    def __eq__(self, other) -> bool:
        return type(other) is type(self) and other._shape == self._shape

    def __hash__(self) -> int:
        return hash(self._shape)

    # --- gymnax's API ------------------------------------------------------------------------------------------

    @property
    def name(self) -> str:
        return f"crop-sim/{self.scenario.name}"

    @property
    def num_actions(self) -> int:
        return 1

    @property
    def seasons(self) -> core.SeasonTable:
        """The weather pool as numpy arrays (loaded or generated on first use, cached per process)."""
        if self._table is None:
            self._table = core.scenario_table(self.scenario)
        return self._table

    @property
    def default_params(self) -> EnvParams:
        """The scenario's weather pool and numbers on the device (one copy per float precision)."""
        key = str(_float())
        if key not in self._params:
            self._params[key] = params_of(self.seasons, self.max_steps_in_episode, self.task)
        return self._params[key]

    def observation_space(self, params: EnvParams | None = None) -> Box:
        layout = self.task.layout
        return Box(layout.low, layout.high, (layout.size,), jnp.float32)

    def action_space(self, params: EnvParams | None = None) -> Box:
        return Box(0.0, self.task.max_irrigation_mm, (), _float())

    def reset(self, key: jax.Array, params: EnvParams | None = None) -> tuple[jax.Array, core.TaskState]:
        """A field on the sowing day of a season drawn from the pool, with its terms drawn; (obs, state)."""
        return self.reset_env(key, self.default_params if params is None else params)

    def step(self, key: jax.Array, state: core.TaskState, action, params: EnvParams | None = None):
        """One day; a season that ends is replaced by a new one on the same step (see the module docstring).
        Returns (obs, state, reward, done, info). Draws two days of noise at once (the day's and a new season's
        first) and one block of uniforms: few random calls keep the compilation short."""
        params = self.default_params if params is None else params
        key_noise, key_draws = jax.random.split(key)
        noise = jax.random.normal(key_noise, (2, self.task.noise_columns), jnp.float32)
        obs_step, state_step, reward, terminated, truncated, info = self.step_with(state, action, noise[0], params)
        done = terminated | truncated
        obs_reset, state_reset = self._reset_from(jax.random.uniform(key_draws, (5,), _float()), noise[1], params)
        state = jax.tree.map(lambda new, old: jnp.where(done, new, old), state_reset, state_step)
        obs = jnp.where(done, obs_reset, obs_step)
        return obs, state, reward, done, self._info(info, terminated, truncated)

    def reset_env(self, key: jax.Array, params: EnvParams) -> tuple[jax.Array, core.TaskState]:
        key_draws, key_noise = jax.random.split(key)
        return self._reset_from(jax.random.uniform(key_draws, (5,), _float()), self.draw_noise(key_noise), params)

    def _reset_from(self, uniform: jax.Array, noise: jax.Array, params: EnvParams):
        """A new season from five uniforms in [0, 1) (the season, uniform over the pool, then the four terms)."""
        m = params.n_days.shape[0]
        season = jnp.minimum(jnp.floor(uniform[0] * m).astype(_int()), m - 1)
        return self.reset_with(season, self.draw_terms(uniform[1:], params), noise, params)

    def step_env(self, key: jax.Array, state: core.TaskState, action, params: EnvParams):
        """One day without the reset: (obs, state, reward, done, info)."""
        obs, state, reward, terminated, truncated, info = self.step_with(state, action, self.draw_noise(key), params)
        return obs, state, reward, terminated | truncated, self._info(info, terminated, truncated)

    @staticmethod
    def _info(info: dict, terminated, truncated) -> dict:
        return {**info, "terminated": terminated, "truncated": truncated,
                "discount": jnp.where(terminated, 0.0, 1.0).astype(_float())}

    # --- randomness --------------------------------------------------------------------------------------------

    def draw_noise(self, key: jax.Array) -> jax.Array:
        """One day's observation noise: ``task.noise_columns`` float32 standard normals (as the numpy
        environment draws per field and day)."""
        return jax.random.normal(key, (self.task.noise_columns,), jnp.float32)

    def draw_terms(self, uniform: jax.Array, params: EnvParams) -> core.EpisodeTerms:
        """The episode's terms from four uniforms in [0, 1): each uniform in its range (a fixed range gives its
        value)."""
        n = params.task
        ranges = (n.yield_value_per_t, n.water_price_per_mm, n.pumping_energy_per_mm, n.quota_mm)
        value, water, energy, quota = (jnp.where(low == high, low, low + u * (high - low))  # no inf - inf
                                       for (low, high), u in zip(ranges, uniform))
        return core.EpisodeTerms(value, water + energy, quota)

    # --- the pure functions, randomness given ------------------------------------------------------------------

    def task_params(self, params: EnvParams) -> core.TaskParams:
        """The core's task parameters of one field: the numbers of ``params`` (traced), the shape of ``self``."""
        n = params.task
        one = replace(self.task, fields=FieldParameters(**n.fields), sowing_state=n.sowing_state,
                      noise_std=n.noise_std, dry_matter_fraction=n.dry_matter_fraction,
                      capacity_mm_per_day=n.capacity_mm_per_day, nominal_season_days=n.nominal_season_days)
        # What the core decides in Python, from the static shape (a cached property is read from __dict__ first).
        vars(one).update(noisy=self.task.noisy, noise_columns=self.task.noise_columns, limited=self.task.limited,
                         _dropout_z=self.task._dropout_z)
        return one

    def initial_state(self, season, terms: core.EpisodeTerms, params: EnvParams) -> core.TaskState:
        """The field on its sowing day in pool season ``season`` with episode terms ``terms``."""
        f = _float()
        terms = core.EpisodeTerms(*(jnp.asarray(t, f) for t in terms))
        zero = jnp.zeros((), f)
        return core.TaskState(params.task.sowing_state, jnp.asarray(season, _int()), terms, zero, zero)

    def reset_with(self, season, terms: core.EpisodeTerms, noise, params: EnvParams):
        """(obs, state) of :meth:`initial_state`, the observation noise given."""
        state = self.initial_state(season, terms, params)
        return core.observation(self.task_params(params), params, state, noise=noise, xp=JAX_MATH), state

    def step_with(self, state: core.TaskState, action, noise, params: EnvParams):
        """One day, the observation noise given, no reset: (obs, state, reward, terminated, truncated, info)."""
        one = self.task_params(params)
        requested = jnp.reshape(jnp.asarray(action, _float()), ())
        applied = core.admissible_irrigation_mm(one, state, jnp.clip(requested, 0.0, one.max_irrigation_mm), jnp)
        weather = core.daily_weather(params, state, jnp)
        next_state, fluxes = core.transition(one, params, state, applied, jnp, weather=weather)
        reward = core.reward(one, state, applied, next_state, jnp)
        terminated = core.terminal(next_state)
        truncated = core.truncated(params, next_state, jnp) | (
            next_state.crop.days_since_sowing >= params.max_steps_in_episode)
        obs = core.observation(one, params, next_state, noise=noise, xp=JAX_MATH)
        info = {"irrigation_applied_mm": applied, "rain_mm": weather.rain_mm,
                "yield_t_ha": core.harvestable_yield_kg_ha(one.fields, next_state.crop) / core.KG_PER_T,
                "potential_yield_t_ha": params.potential_yield_t_ha[next_state.season]}
        return obs, next_state, reward, terminated, truncated, info

    def __repr__(self) -> str:
        return f"JaxIrrigationEnv({self.scenario.name!r})"


def make_jax_env(name: str, data_dir: str | Path | None = None, **kwargs: Any) -> JaxIrrigationEnv:
    """The JAX environment of the registered task ``name`` (a task name as ``--task`` takes it, or its
    Gymnasium id ``crop-sim/<name>-v0``); ValueError for any other name."""
    if isinstance(name, str) and name.startswith("crop-sim/"):
        from . import task_name
        name = task_name(name)
    if not isinstance(name, str) or name not in scenario_names():
        raise ValueError(f"{name!r} is not a built-in task; known: {', '.join(scenario_names())}")
    return JaxIrrigationEnv(name, data_dir, **kwargs)
