"""The irrigation task for N fields at once, as a ``gymnasium.vector.VectorEnv`` over the batched model.

Every field is an independent :class:`~crop_sim_ros.task.env.IrrigationEnv` episode; one call of ``step``
advances all of them by one day with one call of the batched SIMPLE step. Seasons come from the
scenario's cached table (generated once per process), so an autoreset costs an index draw.

Autoreset: ``AutoresetMode.NEXT_STEP`` (Gymnasium's default: the step after an episode ends resets that
field, ignores its action and returns reward 0) or ``AutoresetMode.SAME_STEP`` (the ending step returns
the new season's first observation; the final one is in ``infos["final_obs"]``, an (N, 20) array valid
where ``infos["_final_obs"]``, and the final infos in ``infos["final_info"]``).

Randomness: one generator for all fields (``reset(seed=...)``; the observation noise from an SFC64 stream
seeded by it, drawn a step ahead on a worker thread when the process may use a second CPU, see
:class:`PrefetchedNormal` and ``noise_thread``): the same seed and actions give the same batch, bit for
bit, with or without the thread. Without observation noise, field i equals a single ``IrrigationEnv`` on the same
season with the same actions; with noise it draws from the shared stream instead of its own.

``infos``: arrays of shape (N,) (each with its ``_key`` mask, all True): ``day``, ``season`` (index into
``env.seasons``, or beyond it for the weathers given to ``reset``), ``true_biomass_t_ha``,
``true_paw_mm``, ``thermal_time_degc_d``, ``fsolar``, ``yield_t_ha``, ``mature``,
``potential_yield_t_ha``; after a step also ``irrigation_requested_mm``, ``irrigation_applied_mm``,
``irrigation_clipped``, ``rain_mm``, ``runoff_mm``, ``drainage_mm``, ``transpiration_mm``, ``et0_mm``,
``arid`` (their mask is False for a field that NEXT_STEP autoreset on that step: its action was ignored),
``episode_return``, ``normalized_return`` (running; 0 on a field's first day).
"""

from __future__ import annotations

import os
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ..model import DailyFluxes
from . import core
from .env import NUMERIC_DTYPE_KINDS, reset_options, season_indices, weather_option
from .scenario import Scenario, get_scenario


MAX_FIELDS = 1_000_000  # fields of one vector env: about 2 GB of working arrays


class PrefetchedNormal:
    """Standard normal float32 draws for the observation noise, made one step ahead on a worker thread.

    Ten normals per field and day are the largest single cost of a batched step; numpy releases the GIL
    while it fills an array, so the next step's block is drawn while this step's model and bookkeeping
    run. Every call consumes exactly one block of ``(rows, columns)`` from one SFC64 stream (about 30 %
    faster than numpy's default PCG64) and returns its first ``shape[0]`` rows, so the values depend only
    on the seed and the sequence of calls, never on the threads' timing. Below ``MIN_ROWS_TO_PREFETCH``
    rows the hand-off costs more than it saves, and blocks are drawn in place (the same values); so they
    are with ``thread=False`` (on one CPU the worker only takes turns with the main thread).
    """

    MIN_ROWS_TO_PREFETCH = 2048
    _executor: ThreadPoolExecutor | None = None
    _executor_pid = -1  # a forked child (e.g. SB3's SubprocVecEnv) needs its own worker thread

    def __init__(self, seed: int, rows: int, columns: int, thread: bool = True):
        self._stream = np.random.Generator(np.random.SFC64(seed))
        self._shape = (rows, columns)
        self._next: Future | None = None
        if thread and rows >= self.MIN_ROWS_TO_PREFETCH:
            if PrefetchedNormal._executor_pid != os.getpid():
                PrefetchedNormal._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="noise")
                PrefetchedNormal._executor_pid = os.getpid()
            self._next = self._submit()

    def _submit(self) -> Future:
        return PrefetchedNormal._executor.submit(self._stream.standard_normal, self._shape, np.float32)

    def standard_normal(self, shape: tuple[int, ...], dtype=np.float32) -> np.ndarray:
        if dtype != np.float32 or len(shape) != 2 or shape[1] != self._shape[1] or shape[0] > self._shape[0]:
            raise ValueError(f"noise of shape {shape} ({np.dtype(dtype)}) from blocks of {self._shape} float32")
        if self._next is None:
            block = self._stream.standard_normal(self._shape, np.float32)
        else:
            block = self._next.result()
            self._next = self._submit()
        return block[:shape[0]]


class IrrigationVectorEnv(VectorEnv):
    """N fields of one scenario (see the module docstring and :class:`IrrigationEnv` for spaces and rewards).

    ``reset(options=...)``: ``{"season": indices (N,)}`` puts field i in season ``indices[i]`` of the
    scenario; ``{"terms": {"quota_mm": (N,), ...}}`` sets the first episode's drawn terms (any of
    ``yield_value_per_t``, ``water_cost_per_mm``, ``quota_mm``: paired comparisons on the same terms);
    ``{"weathers": [WeatherSeries] * N}`` grows field i in the given series (sown on its first
    day). Later autoresets draw from the scenario's seasons again. Seasons are whole numbers (one index for
    every field, or one per field), other option keys are refused. ``step(actions)``: one amount (mm) per field,
    shape (N,) or (N, 1); any other shape is refused (never reshaped).

    ``noise_thread``: draw the observation noise a step ahead on a worker thread (default: when this
    process may run on more than one CPU, ``os.sched_getaffinity``); False draws it on the calling thread.
    The values are the same either way.

    ``max_episode_steps``: a field's season is truncated after this many days (what ``TimeLimit`` does to one
    environment; ``gymnasium.make_vec`` passes the registered value); None: only when its weather runs out.
    """

    def __init__(self, num_envs: int = 1, scenario: str | Scenario = "benton-generated",
                 data_dir: str | Path | None = None, autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
                 noise_thread: bool | None = None, max_episode_steps: int | None = None):
        self.scenario = scenario if isinstance(scenario, Scenario) else get_scenario(scenario, data_dir)
        self.num_envs = int(num_envs)
        if not 1 <= self.num_envs <= MAX_FIELDS:
            raise ValueError(f"num_envs must be in 1..{MAX_FIELDS:,} (one field's state, weather gathers and noise "
                             f"cost about 2 kB), got {num_envs}")
        self.autoreset_mode = AutoresetMode(autoreset_mode)
        if max_episode_steps is not None and (isinstance(max_episode_steps, bool) or not (
                isinstance(max_episode_steps, (int, np.integer)) and max_episode_steps >= 1)):
            raise ValueError(f"max_episode_steps must be a whole number of days >= 1 or None, got {max_episode_steps!r}")
        self.max_episode_steps = None if max_episode_steps is None else int(max_episode_steps)
        self.noise_thread = len(os.sched_getaffinity(0)) > 1 if noise_thread is None else bool(noise_thread)
        if self.autoreset_mode == AutoresetMode.DISABLED:
            raise ValueError("IrrigationVectorEnv supports AutoresetMode.NEXT_STEP and SAME_STEP")
        self.metadata = {"autoreset_mode": self.autoreset_mode, "render_modes": []}
        self.render_mode = None
        self.seasons = core.scenario_table(self.scenario)
        self.params = core.task_params(self.scenario, self.num_envs)
        self.single_action_space = gym.spaces.Box(0.0, self.scenario.max_irrigation_mm, (1,), np.float32)
        self.single_observation_space = gym.spaces.Box(self.params.layout.low, self.params.layout.high,
                                                       dtype=np.float32)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self._table = self.seasons
        self._state: core.TaskState | None = None
        self._autoreset = np.zeros(self.num_envs, dtype=bool)
        self._returns = np.zeros(self.num_envs)
        self._all = np.ones(self.num_envs, dtype=bool)

    @property
    def field_seasons(self) -> np.ndarray:
        """The pool position (index into ``seasons``) of each field's current season (N,); after an autoreset,
        the new season's. RuntimeError before the first reset."""
        if self._state is None:
            raise RuntimeError("field_seasons: reset the environment first")
        return np.asarray(self._state.season).copy()

    @property
    def field_days(self) -> np.ndarray:
        """Each field's day of its current season (N,), 0 on the sowing day; after an autoreset, 0.
        RuntimeError before the first reset."""
        if self._state is None:
            raise RuntimeError("field_days: reset the environment first")
        return np.asarray(self._state.crop.days_since_sowing, dtype=np.int64).copy()

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self._noise_rng = PrefetchedNormal(int(self.np_random.integers(2**63)), self.num_envs,
                                           self.params.noise_columns, self.noise_thread)
        options = reset_options(options, ("weathers", "season", "terms"))
        weathers, season, terms = options.get("weathers"), options.get("season"), options.get("terms")
        if weathers is not None and season is not None:
            raise ValueError("reset options: give weathers or season, not both")
        if terms is not None and not isinstance(terms, dict):
            raise TypeError(f"terms: expected a dict of arrays by name, got {type(terms).__name__}")
        self._table = self.seasons
        if weathers is not None:
            if not isinstance(weathers, (list, tuple)):
                raise TypeError(f"weathers: expected a list of {self.num_envs} WeatherSeries, got "
                                f"{type(weathers).__name__}")
            if len(weathers) != self.num_envs:
                raise ValueError(f"weathers: {len(weathers)} series for {self.num_envs} fields")
            given = core.season_table(self.scenario, [self.scenario.prepare(weather_option(w, "weathers[]"))
                                                      for w in weathers])
            self._table = core.stack_tables([self.seasons, given])
            season = len(self.seasons) + np.arange(self.num_envs)
        elif season is None:
            season = self._draw_seasons(self.num_envs)
        else:
            season = season_indices(season, len(self.seasons), (self.num_envs,))
        self._state = core.initial(self.params, season, self.np_random)
        if terms is not None:
            self._state = self._state._replace(terms=core.given_terms(self._state.terms, terms))
        self._autoreset[:] = False
        self._returns[:] = 0.0
        obs = core.observation(self.params, self._table, self._state, self._noise_rng)
        return obs, self._state_infos(self._state)

    def step(self, actions):
        if self._state is None:
            raise RuntimeError("call reset() before step()")
        given = np.asarray(actions)
        if given.dtype.kind not in NUMERIC_DTYPE_KINDS:  # float() would take strings, bools, Decimal objects
            raise TypeError(f"actions must be numbers of mm (int or float), got an array of dtype {given.dtype}")
        if given.shape not in ((self.num_envs,), (self.num_envs, 1)):  # (2, 4) for 8 fields is a mistake
            raise ValueError(f"actions must hold one irrigation amount per field: shape ({self.num_envs},) or "
                             f"({self.num_envs}, 1), got {given.shape}")
        requested = given.astype(np.float64).reshape(-1)
        if not (np.isfinite(requested.min()) and np.isfinite(requested.max())):  # NaN propagates to both
            raise ValueError(f"irrigation must be finite mm, got a non-finite value for fields "
                             f"{np.flatnonzero(~np.isfinite(requested))[:10].tolist()}")
        state = self._state
        applied = core.admissible_irrigation_mm(self.params, state,
                                                np.clip(requested, 0.0, self.scenario.max_irrigation_mm))
        weather = core.daily_weather(self._table, state)
        next_state, fluxes = core.transition(self.params, self._table, state, applied, weather=weather)
        rain_mm = weather.rain_mm
        rewards = core.reward(self.params, state, applied, next_state)
        terminations = core.terminal(next_state)
        truncations = core.truncated(self._table, next_state)
        if self.max_episode_steps is not None:  # as TimeLimit: a season's step count is its day count
            truncations = truncations | (next_state.crop.days_since_sowing >= self.max_episode_steps)
        self._returns += rewards
        stepped = self._all
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            resetting = self._autoreset
            if resetting.any():
                next_state = self._restart(next_state, resetting)
                rewards[resetting] = 0.0
                terminations = terminations & ~resetting
                truncations = truncations & ~resetting
                stepped = ~resetting
            self._autoreset = terminations | truncations
            obs = core.observation(self.params, self._table, next_state, self._noise_rng)
            infos = self._step_infos(next_state, fluxes, requested, applied, rain_mm, stepped)
        else:
            ended = terminations | truncations
            obs = core.observation(self.params, self._table, next_state, self._noise_rng)
            infos = self._step_infos(next_state, fluxes, requested, applied, rain_mm, stepped)
            if ended.any():
                infos["final_obs"], infos["_final_obs"] = obs.copy(), ended
                infos["final_info"], infos["_final_info"] = dict(infos), ended
                next_state = self._restart(next_state, ended)
                obs[ended] = core.observation(self.params, self._table, _take(next_state, ended), self._noise_rng)
                infos.update(self._state_infos(next_state))
        self._state = next_state
        return obs, rewards, terminations, truncations, infos

    def _draw_seasons(self, count: int) -> np.ndarray:
        return self.np_random.integers(len(self.seasons), size=count)

    def _restart(self, state: core.TaskState, mask: np.ndarray) -> core.TaskState:
        """The fields of ``mask`` on the sowing day of a newly drawn season, their returns zeroed."""
        season = np.zeros(self.num_envs, dtype=np.int64)
        season[mask] = self._draw_seasons(int(mask.sum()))
        self._returns[mask] = 0.0
        return core.restart(self.params, state, mask, season, self.np_random)

    def _state_infos(self, state: core.TaskState) -> dict[str, np.ndarray]:
        values = {
            **core.crop_info(self.params, state.crop),
            "season": state.season,
            "potential_yield_t_ha": self._table.potential_yield_t_ha[state.season],
            **core.terms_info(state),
            "episode_return": self._returns.copy(),
        }
        values["normalized_return"] = values["episode_return"] / (values["potential_yield_t_ha"]
                                                                 * state.terms.yield_value_per_t)
        return self._with_masks(values)

    def _step_infos(self, state: core.TaskState, fluxes: DailyFluxes, requested: np.ndarray, applied: np.ndarray,
                    rain_mm: np.ndarray, stepped: np.ndarray) -> dict[str, np.ndarray]:
        """State infos and the day's step infos, the latter masked (``_key``) by ``stepped``."""
        infos = self._state_infos(state)
        infos.update(self._with_masks({
            "irrigation_requested_mm": requested,
            "irrigation_applied_mm": applied,
            "irrigation_clipped": applied != requested,
            "rain_mm": rain_mm,
            "runoff_mm": fluxes.runoff_mm,
            "drainage_mm": fluxes.drainage_mm,
            "transpiration_mm": fluxes.transpiration_mm,
            "et0_mm": fluxes.et0_mm,
            "arid": fluxes.arid,
        }, stepped))
        return infos

    def _with_masks(self, values: dict[str, np.ndarray], mask: np.ndarray | None = None) -> dict[str, np.ndarray]:
        values.update({f"_{key}": self._all if mask is None else mask for key in list(values)})
        return values


def _take(state: core.TaskState, mask: np.ndarray) -> core.TaskState:
    return core.TaskState(state.crop.take(mask), state.season[mask], core.EpisodeTerms(*(t[mask] for t in state.terms)),
                          state.irrigated_mm[mask], state.last_irrigation_mm[mask])
