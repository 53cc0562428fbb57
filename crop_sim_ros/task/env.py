"""The irrigation task as a Gymnasium environment: one field, one simulated day per step."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from ..model.simple import SCALAR_MATH
from ..usage import shown
from ..weather import WeatherSeries
from . import core
from .scenario import Scenario, get_scenario

# Keys of ``info`` (reset and step); the ROS simulator node and the agents rely on them: keep them stable.
STATE_INFO_KEYS = ("day", "date", "season", "weather_source", "weather_filled", "true_biomass_t_ha", "true_paw_mm",
                   "thermal_time_degc_d", "fsolar", "yield_t_ha", "mature", "potential_yield_t_ha",
                   "yield_value_per_t", "water_cost_per_mm", "quota_mm")
STEP_INFO_KEYS = ("irrigation_requested_mm", "irrigation_applied_mm", "irrigation_clipped", "rain_mm", "runoff_mm",
                  "drainage_mm", "transpiration_mm", "et0_mm", "arid", "episode_return", "normalized_return")


# What an irrigation amount may be: Python or numpy integers and floats (never bool, str, Decimal, Fraction or
# objects, which float() would quietly accept). Array dtype kinds: float, signed and unsigned integer.
_NUMBER_TYPES = (float, int, np.floating, np.integer)
NUMERIC_DTYPE_KINDS = "fiu"


def irrigation_mm(action) -> float:
    """The irrigation amount (mm) of one action: a real number, or a numeric array or list of exactly one.
    TypeError for a non-numeric action (a string, bool, Decimal, Fraction, an object array), ValueError for
    more than one value. The common cases (a float32 array of shape (1,), a float) are checked first: this
    runs on every step."""
    if isinstance(action, np.ndarray):
        if action.dtype.kind not in NUMERIC_DTYPE_KINDS:
            raise TypeError(f"action must be a number of mm, got an array of dtype {action.dtype}")
        if action.size != 1:
            raise ValueError(f"action must be one irrigation amount in mm, got an array of shape {action.shape}")
        return float(action.item())
    if type(action) in (list, tuple):
        if len(action) != 1:
            raise ValueError(f"action must be one irrigation amount in mm, got {len(action)} values")
        if isinstance(action[0], (np.ndarray, list, tuple)):
            return irrigation_mm(action[0])
        action = action[0]
    if not isinstance(action, _NUMBER_TYPES) or isinstance(action, (bool, np.bool_)):
        raise TypeError(f"action must be a number of mm (int or float), got {type(action).__name__} {shown(action)}")
    return float(action)


def reset_options(options, known: tuple[str, ...]) -> dict[str, Any]:
    """A copy of ``reset``'s ``options``: a mapping (or None) whose keys are all in ``known``. TypeError for
    anything else than a mapping, ValueError naming the unknown keys."""
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise TypeError(f"reset options must be a dict, got {type(options).__name__}")
    unknown = [key for key in options if key not in known]
    if unknown:
        raise ValueError(f"unknown reset options {shown(unknown)}; known: {', '.join(known)}")
    return dict(options)


def season_indices(value, count: int, shape: tuple[int, ...] = ()) -> np.ndarray:
    """reset's ``season`` option as an array of ``shape`` (a scalar also fills a shape (N,)): whole numbers (Python
    or numpy integers; never a bool, a float such as 1.7 or a string such as "3") in 0..count-1. TypeError or
    ValueError naming the option."""
    given = np.asarray(value) if not isinstance(value, (bool, np.bool_)) else None
    if given is None or given.dtype.kind not in "iu":
        raise TypeError(f"season: expected a whole number (int), got {type(value).__name__} {shown(value)}")
    if given.shape not in ((), shape):
        raise ValueError(f"season: expected one index or an array of shape {shape}, got shape {given.shape}")
    if given.size and (given.min() < 0 or given.max() >= count):
        raise ValueError(f"season: indices must be in 0..{count - 1}")
    return np.broadcast_to(given.astype(np.int64), shape)


def weather_option(value, name: str = "weather") -> WeatherSeries:
    """reset's ``weather`` option (or an item of the vector environment's ``weathers``): a WeatherSeries;
    TypeError naming the option otherwise."""
    if not isinstance(value, WeatherSeries):
        raise TypeError(f"{name}: expected a WeatherSeries, got {type(value).__name__}")
    return value


class IrrigationEnv(gym.Env[np.ndarray, np.ndarray]):
    """
    ## Description

    A field of one crop (by default Russet Burbank potato on the Benton County, WA soil) grows through one
    season under the SIMPLE crop model (Zhao et al. 2019). Each step is one day: the agent decides how
    much to irrigate today, knowing the crop's state, today's weather and a noisy forecast of tomorrow's.
    Water costs a little; the harvest at maturity pays the dry yield. This is the task of Ashcraft & Karra
    (2021), "Machine Learning aided Crop Yield Optimization", with the unit defects of its code fixed.

    ## Action Space

    ``Box(0, 100, (1,), float32)``: irrigation applied today, mm (the upper bound is the scenario's
    ``max_irrigation_mm``). It enters the water balance with the day's rain (and runs off like rain).
    A value outside the box is clipped to it and flagged in ``info["irrigation_clipped"]``; NaN or an
    infinite value raises ValueError. The action is a Python or numpy int or float, or a numeric array or
    list of one; anything else (a string, a bool, Decimal, Fraction, an object array) raises TypeError.

    ## Observation Space

    ``Box(low, inf, (20,), float32)``; noise is Gaussian, with the standard deviations of the scenario
    (defaults: the paper's Table 2); a noisy value below its physical bound is clipped to the bound.

    | Num | Observation                          | Unit   | Noise std (default) | Low  |
    |-----|--------------------------------------|--------|---------------------|------|
    | 0   | above-ground biomass                 | t/ha   | 0.01                | 0    |
    | 1   | thermal time since sowing (TT)       | degC d | -                   | -inf |
    | 2   | days since sowing                    | d      | -                   | 0    |
    | 3   | today's TMAX                         | degC   | -                   | -inf |
    | 4   | today's TMIN                         | degC   | -                   | -inf |
    | 5   | today's TAVG = (TMAX + TMIN) / 2     | degC   | -                   | -inf |
    | 6   | today's rain                         | mm     | -                   | 0    |
    | 7   | today's solar radiation SRAD         | MJ/m2  | -                   | 0    |
    | 8   | today's CO2                          | ppm    | -                   | 0    |
    | 9   | today's vapour pressure VAP          | hPa    | -                   | 0    |
    | 10  | today's wind at 2 m                  | m/s    | -                   | 0    |
    | 11  | forecast of tomorrow's TMAX          | degC   | 3                   | -inf |
    | 12  | forecast of tomorrow's TMIN          | degC   | 2                   | -inf |
    | 13  | forecast of tomorrow's TAVG          | degC   | 2                   | -inf |
    | 14  | forecast of tomorrow's rain          | mm     | 3                   | 0    |
    | 15  | forecast of tomorrow's SRAD          | MJ/m2  | 1                   | 0    |
    | 16  | forecast of tomorrow's CO2           | ppm    | 1                   | 0    |
    | 17  | forecast of tomorrow's VAP           | hPa    | 1                   | 0    |
    | 18  | forecast of tomorrow's wind          | m/s    | 6                   | 0    |
    | 19  | plant-available water in the root zone (PAW) | mm | 1                | 0    |

    TAVG is the measured daily mean instead when the scenario sets ``observe_measured_tavg``. On the last
    day of the weather there is no tomorrow: the forecast is built from today's true weather.

    ## Rewards

    ``irrigation_cost_per_mm * a`` every day (default -1.25e-4 per mm; ``a`` = irrigation applied, mm),
    plus the dry yield (t/ha, harvest index times biomass) on the day the crop matures. ``info`` carries
    the running ``episode_return`` and ``normalized_return`` (the return over ``potential_yield_t_ha``, the
    yield of the same season with no water stress and no water cost).

    ## Starting State

    The sowing day: biomass 1 kg/ha, TT 0, a full root zone (PAW = AWC x RZD, 120 mm on the Benton soil).
    The season's weather is drawn from the scenario's seasons with the reset's generator (a pool of
    generated seasons, or a list of real ones), unless ``reset(options=...)`` names it.

    ## Episode End

    - Termination: the crop matures (TT passes Tsum, the canopy senesces, or the harvest date).
    - Truncation: the season's weather (at most ``max_season_days`` days) runs out before maturity. A
      registered id also has ``max_episode_steps``, the scenario's longest season in days (200 for every
      built-in scenario): ``gymnasium.make`` wraps the environment in a ``TimeLimit`` of that many steps (one
      step is one day), and ``gymnasium.make_vec`` gives the vector environment the same limit.
    Stepping after either raises RuntimeError; call ``reset``.

    ## Arguments

    ```python
    gymnasium.make("crop-sim/benton-generated-v0")         # task "benton-generated" (no data file)
    gymnasium.make("crop-sim/benton-2000-v0")              # the paper's season, AgWeatherNet Benton E. 2000
    IrrigationEnv(scenario="heldout", data_dir=None)        # a Scenario or a built-in scenario's name
    env.reset(seed=0)                                       # seeds the weather draw and all noise
    env.reset(options={"season": 2})                        # the scenario's season 2
    env.reset(options={"weather": weather_series})          # a given WeatherSeries, sown on its first day
    ```

    A season is a whole number (an int or a numpy integer: 1.7, "3" and True are refused), a weather a
    WeatherSeries, and any other option key is refused (TypeError or ValueError naming the option).

    Every built-in scenario is registered as ``crop-sim/<name>-v0`` (``crop_sim_ros.task.gym_id``).
    ``data_dir``: where the scenario's weather files are (default ``../shared/data`` next to the
    repository). Same seed and same actions give the same episode, bit for bit.

    ``info`` keys, on reset and every step (the state after the day): ``day`` (days since sowing),
    ``date`` (ISO), ``season`` (index in the scenario, -1 for a given weather), ``weather_source``,
    ``weather_filled`` (what FAO-56's missing-data rules filled), ``true_biomass_t_ha``, ``true_paw_mm``,
    ``thermal_time_degc_d``, ``fsolar``, ``yield_t_ha`` (harvest index x biomass: the harvested yield once
    mature), ``mature``, ``potential_yield_t_ha``. On every step also, for the day just simulated:
    ``irrigation_requested_mm``, ``irrigation_applied_mm``, ``irrigation_clipped``, ``rain_mm``,
    ``runoff_mm``, ``drainage_mm``, ``transpiration_mm``, ``et0_mm``, ``arid``, and ``episode_return``,
    ``normalized_return``.

    ## Version History

    - v0: first version (SIMPLE of Zhao et al. 2019; observation and reward of Ashcraft & Karra 2021 with
      biomass in t/ha, CO2 sensitivity per 100 ppm, Benton site ET0, season ended by maturity).
    """

    metadata = {"render_modes": []}

    def __init__(self, scenario: str | Scenario = "benton-generated", data_dir: str | Path | None = None):
        self.scenario = scenario if isinstance(scenario, Scenario) else get_scenario(scenario, data_dir)
        self.seasons = core.scenario_table(self.scenario)
        self.params = core.task_params(self.scenario)
        # One field as Python floats: the model's scalar path, bit-identical to the array path and ~6x faster.
        self._one = core.scalar_task_params(self.params)
        self.action_space = gym.spaces.Box(0.0, self.scenario.max_irrigation_mm, (1,), np.float32)
        self.observation_space = gym.spaces.Box(self.params.layout.low, self.params.layout.high, dtype=np.float32)
        self._table = self.seasons
        self._state: core.TaskState | None = None
        self._season = -1
        self._ended = False
        self._return = 0.0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = reset_options(options, ("weather", "season"))
        weather, season = options.get("weather"), options.get("season")
        if weather is not None and season is not None:
            raise ValueError("reset options: give weather or season, not both")
        if weather is not None:
            self._table = core.season_table(self.scenario, [self.scenario.prepare(weather_option(weather))])
            self._season = -1
        else:
            self._table = self.seasons
            if season is None:
                season = int(self.np_random.integers(len(self.seasons)))
            self._season = int(season_indices(season, len(self.seasons)))
        self._state = core.initial(self._one, max(self._season, 0), self.np_random)
        k = self._state.season
        # What stays the same all season, computed once per reset (the step is the hot path).
        self._dates = np.datetime_as_string(self._table.sowing_dates[k]
                                            + np.arange(self._table.observation_rows.shape[1])).tolist()
        self._season_info = {"season": self._season, "weather_source": self._table.sources[k],
                             "weather_filled": self._table.filled[k],
                             "potential_yield_t_ha": float(self._table.potential_yield_t_ha[k]),
                             **core.terms_info(self._state)}
        self._ended = False
        self._return = 0.0
        return self._observe(), self._state_info()

    def step(self, action):
        if self._state is None:
            raise RuntimeError("call reset() before step()")
        if self._ended:
            raise RuntimeError("the season has ended (terminated or truncated); call reset()")
        requested = irrigation_mm(action)
        if not math.isfinite(requested):
            raise ValueError(f"irrigation must be a finite number of mm, got {requested}")
        applied = core.admissible_irrigation_mm(self._one, self._state,
                                                min(max(requested, 0.0), self.scenario.max_irrigation_mm), SCALAR_MATH)
        state = self._state
        self._state, fluxes = core.transition(self._one, self._table, state, applied, SCALAR_MATH)
        reward = core.reward(self._one, state, applied, self._state, SCALAR_MATH)
        terminated = core.terminal(self._state)
        truncated = bool(core.truncated(self._table, self._state, SCALAR_MATH))
        self._ended = terminated or truncated
        self._return += reward
        info = self._state_info()
        info.update(irrigation_requested_mm=requested, irrigation_applied_mm=applied,
                    irrigation_clipped=applied != requested,
                    rain_mm=float(self._table.weather[state.season, info["day"] - 1, core.RAIN]),
                    runoff_mm=fluxes.runoff_mm, drainage_mm=fluxes.drainage_mm,
                    transpiration_mm=fluxes.transpiration_mm, et0_mm=fluxes.et0_mm,
                    arid=fluxes.arid, episode_return=self._return,
                    normalized_return=self._return / (self._season_info["potential_yield_t_ha"]
                                                      * state.terms.yield_value_per_t))
        return self._observe(), reward, terminated, truncated, info

    def _observe(self) -> np.ndarray:
        return core.observation(self._one, self._table, self._state, self.np_random)

    def _state_info(self) -> dict[str, Any]:
        crop = self._state.crop
        return {**core.crop_info(self._one, crop), "date": self._dates[crop.days_since_sowing], **self._season_info}
