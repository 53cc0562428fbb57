"""The functional core of the irrigation task for N fields at once: pure numpy, randomness passed in.

In the style of Gymnasium's functional environments: :func:`task_params` (the static parameters),
:func:`initial`, :func:`transition`, :func:`observation`, :func:`reward`, :func:`terminal`,
:func:`truncated`. Every function works on arrays of shape (N,) (one row per field) and draws randomness
only from the ``numpy.random.Generator`` it is given. The crop itself is :func:`crop_sim_ros.model.step`.

Weather lives in a :class:`SeasonTable` of M prepared seasons; each field holds the index of its season.

Observation (float32, 20 values per field, in this order)
---------------------------------------------------------
==== ===================== ========= ======================================================================
#    name                  unit      value
==== ===================== ========= ======================================================================
0    biomass_t_ha          t ha-1    above-ground biomass + noise, clipped at 0
1    thermal_time_degc_d   degC d    cumulative thermal time since sowing (TT), exact
2    days_since_sowing     d         exact
3    tmax_degc             degC      today's weather, exact ...
4    tmin_degc             degC
5    tavg_degc             degC      (TMAX + TMIN) / 2, or the measured mean if the scenario says so
6    rain_mm               mm
7    srad_mj_m2            MJ m-2
8    co2_ppm               ppm
9    vap_hpa               hPa
10   wind_m_s              m s-1
11   forecast_tmax_degc    degC      tomorrow's weather + Gaussian noise (noisy rain, radiation, CO2,
12   forecast_tmin_degc    degC      vapour pressure and wind are clipped at 0) ...
13   forecast_tavg_degc    degC
14   forecast_rain_mm      mm
15   forecast_srad_mj_m2   MJ m-2
16   forecast_co2_ppm      ppm
17   forecast_vap_hpa      hPa
18   forecast_wind_m_s     m s-1
19   paw_mm                mm        plant-available water in the root zone + noise, clipped at 0
==== ===================== ========= ======================================================================

On the last day of a season's weather there is no tomorrow: the forecast is built from today's true
weather (plus noise). After the last day (a truncated season) today's weather repeats the last day.

Reward: ``C_I * a`` every day (``C_I`` = irrigation cost per mm, negative; ``a`` = irrigation applied, mm),
plus the dry yield Y (t/ha) on the maturity (harvest) day. Terminal at maturity; truncated, not terminal,
when the season's weather (at most ``max_season_days`` days) runs out before maturity.

Normalized return: the return divided by the season's potential yield, the yield of the same season with no
water stress (S_water = 0) and no water cost (see :func:`potential_yield_t_ha`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ..model import (CropState, DailyFluxes, DailyWeather, FieldParameters, harvestable_yield_kg_ha,
                     initial_state, repeat_parameters, step)
from ..model.simple import scalar_parameters, scalar_state
from ..weather import WeatherSeries
from .scenario import ObservationNoise, Scenario

KG_PER_T = 1000.0
WEATHER_NAMES = ("tmax_degc", "tmin_degc", "tavg_degc", "rain_mm", "srad_mj_m2", "co2_ppm", "vap_hpa", "wind_m_s")
OBSERVATION_NAMES = (("biomass_t_ha", "thermal_time_degc_d", "days_since_sowing") + WEATHER_NAMES
                     + tuple(f"forecast_{name}" for name in WEATHER_NAMES) + ("paw_mm",))
OBSERVATION_UNITS = (("t/ha", "degC d", "d") + ("degC", "degC", "degC", "mm", "MJ/m2", "ppm", "hPa", "m/s") * 2
                     + ("mm",))
OBSERVATION_SIZE = len(OBSERVATION_NAMES)
TODAY = slice(3, 11)
FORECAST = slice(11, 19)
BIOMASS, PAW = 0, 19
# Column of each model input in SeasonTable.weather.
TMAX, TMIN, RAIN, SRAD = (WEATHER_NAMES.index(n) for n in ("tmax_degc", "tmin_degc", "rain_mm", "srad_mj_m2"))
# SeasonTable.model_weather columns: the DailyWeather fields in order (TMAX, TMIN, SRAD, rain, ET0).
# Bounds of a physically possible observation: noisy values below the lower bound are clipped to it.
OBSERVATION_LOW = np.array([0.0, -np.inf, 0.0] + [-np.inf, -np.inf, -np.inf, 0.0, 0.0, 0.0, 0.0, 0.0] * 2 + [0.0],
                           dtype=np.float32)
OBSERVATION_HIGH = np.full(OBSERVATION_SIZE, np.inf, dtype=np.float32)
# A season table pads every season with copies of its last day: today (index n_days) and tomorrow (n_days + 1).
_PAD_DAYS = 2


@dataclass(frozen=True)
class SeasonTable:
    """M prepared seasons as arrays.

    ================= =============== ==================================================================
    Name              Shape           Description
    ================= =============== ==================================================================
    weather           (M, D + 2, 8)   true daily weather in observation order (WEATHER_NAMES), each
                                      season padded after its last day with copies of that day
    observation_rows  (M, D + 1, 20)  float32 observation of day d without the crop's values: columns
                                      2-18 (day, today's and tomorrow's true weather) filled, 0, 1
                                      and 19 (biomass, TT, PAW) zero
    model_weather     (5, M, D + 2)   the model's daily inputs in DailyWeather order: TMAX, TMIN degC,
                                      SRAD MJ m-2, rain mm, ET0 mm (padded likewise; variable first, so
                                      that each gathers contiguously)
    et0_mm            (M, D + 2)      reference evapotranspiration, mm d-1 (padded likewise)
    n_days            (M,)            days of weather of each season (<= max_season_days)
    sowing_dates      (M,)            datetime64[D], the first day of each season
    potential_yield_t_ha (M,)         yield with no water stress (S_water = 0), t ha-1
    sources, filled   M-tuples        where each season's weather came from, what FAO-56 filled
    ================= =============== ==================================================================
    """

    weather: np.ndarray
    observation_rows: np.ndarray
    model_weather: np.ndarray
    et0_mm: np.ndarray
    n_days: np.ndarray
    sowing_dates: np.ndarray
    potential_yield_t_ha: np.ndarray
    sources: tuple[str, ...]
    filled: tuple[tuple[str, ...], ...]

    def __len__(self) -> int:
        return len(self.n_days)


def season_table(scenario: Scenario, seasons: list[WeatherSeries]) -> SeasonTable:
    """The table of ``seasons`` (already prepared by ``Scenario.prepare``) under ``scenario``'s CO2, ET0
    method and TAVG choice, with each season's potential yield."""
    if not seasons:
        raise ValueError("season_table needs at least one season")
    n_days = np.array([len(s) for s in seasons])
    width = int(n_days.max()) + _PAD_DAYS
    weather = np.empty((len(seasons), width, len(WEATHER_NAMES)))
    et0 = np.empty((len(seasons), width))
    for k, series in enumerate(seasons):
        tavg = (series.tavg_degc if scenario.observe_measured_tavg
                else 0.5 * (series.tmax_degc + series.tmin_degc))
        columns = {"tavg_degc": tavg, "co2_ppm": np.full(len(series), float(scenario.co2_ppm))}
        days = np.stack([columns[name] if name in columns else getattr(series, name) for name in WEATHER_NAMES],
                        axis=1)
        weather[k] = np.pad(days, ((0, width - len(series)), (0, 0)), mode="edge")
        et0[k] = np.pad(series.et0_mm(scenario.et0_method), (0, width - len(series)), mode="edge")
    sowing = np.array([s.dates[0] for s in seasons], dtype="datetime64[D]")
    potential = potential_yield_t_ha(scenario.field_parameters(water_stress=False), weather, et0, n_days)
    return _frozen_table(weather, et0, n_days, sowing, potential, tuple(s.source for s in seasons),
                         tuple(s.filled for s in seasons))


def _frozen_table(weather: np.ndarray, et0_mm: np.ndarray, n_days: np.ndarray, sowing_dates: np.ndarray,
                  potential_yield_t_ha: np.ndarray, sources: tuple, filled: tuple) -> SeasonTable:
    """A SeasonTable of these arrays (read-only: tables are cached and shared) and the observed weather."""
    observed = np.zeros(weather.shape[:2] + (OBSERVATION_SIZE,), dtype=np.float32)[:, :-1]
    observed[..., 2] = np.arange(observed.shape[1])
    observed[..., TODAY] = weather[:, :-1]
    observed[..., FORECAST] = weather[:, 1:]
    observed = np.ascontiguousarray(observed)
    model = _model_weather(weather, et0_mm)
    for array in (weather, observed, model, et0_mm, n_days, sowing_dates, potential_yield_t_ha):
        array.setflags(write=False)
    return SeasonTable(weather, observed, model, et0_mm, n_days, sowing_dates, potential_yield_t_ha, sources,
                       filled)


@functools.lru_cache(maxsize=16)
def scenario_table(scenario: Scenario) -> SeasonTable:
    """The table of every season of ``scenario`` (built once per process and scenario: resets stay cheap)."""
    return season_table(scenario, scenario.load_seasons())


def _model_weather(weather: np.ndarray, et0_mm: np.ndarray) -> np.ndarray:
    """(5, M, D) model inputs in DailyWeather order from the table's weather (M, D, 8) and ET0 (M, D)."""
    return np.ascontiguousarray(np.stack([weather[:, :, TMAX], weather[:, :, TMIN], weather[:, :, SRAD],
                                          weather[:, :, RAIN], et0_mm]))


def _row_index(table_days: int, season, day):
    """Index of (season, day) in a table flattened over seasons x days (np.take beats 2-D fancy indexing)."""
    return season * table_days + day


def _daily_weather(model_weather: np.ndarray, season, day, xp=np) -> DailyWeather:
    """The model's weather of day ``day`` of season ``season``: index arrays of shape (N,), or two ints
    for one field held as Python floats (``xp`` = SCALAR_MATH)."""
    if xp is np:
        index = _row_index(model_weather.shape[2], season, day)
        flat = model_weather.reshape(len(model_weather), -1)
        return DailyWeather(*(np.take(variable, index) for variable in flat))
    return DailyWeather(*model_weather[:, season, day].tolist())


def potential_yield_t_ha(params: FieldParameters, weather: np.ndarray, et0_mm: np.ndarray,
                         n_days: np.ndarray) -> np.ndarray:
    """Yield, t ha-1, of each of M seasons grown by ``params`` (one field; give it S_water = 0 for the
    potential) without irrigation: at maturity, or at the end of the weather if the crop never matures."""
    m = len(n_days)
    fields_params = repeat_parameters(params, m)
    state = initial_state(fields_params)
    season = np.arange(m)
    potential = np.full(m, np.nan)
    model_weather = _model_weather(weather, et0_mm)
    for d in range(int(n_days.max())):
        state, _ = step(fields_params, state, _daily_weather(model_weather, season, np.full(m, d)), 0.0)
        ends = np.isnan(potential) & (state.mature | (d + 1 >= n_days))
        potential[ends] = harvestable_yield_kg_ha(fields_params, state)[ends] / KG_PER_T
    return potential


@dataclass(frozen=True)
class TaskParams:
    """The static parameters of the task for N fields: the model's field parameters (N fields), their
    sowing-day state, the observation noise and the reward's cost."""

    fields: FieldParameters
    sowing_state: CropState
    noise_std: np.ndarray  # float32 (10,): the 8 forecast values and PAW (observation order), then biomass
    irrigation_cost_per_mm: float
    max_irrigation_mm: float

    @functools.cached_property
    def noisy(self) -> bool:
        """Any observation noise at all (cached: the observation is on the hot path)."""
        return bool(self.noise_std.any())


def scalar_task_params(params: TaskParams) -> TaskParams:
    """The first field of ``params`` held as Python floats: the one-field fast path (``xp`` = SCALAR_MATH),
    bit-identical to the array path."""
    return TaskParams(scalar_parameters(params.fields), scalar_state(params.sowing_state), params.noise_std,
                      params.irrigation_cost_per_mm, params.max_irrigation_mm)


def task_params(scenario: Scenario, n_fields: int = 1) -> TaskParams:
    """The task parameters of ``n_fields`` fields of ``scenario``."""
    fields_params = repeat_parameters(scenario.field_parameters(), n_fields)
    noise: ObservationNoise = scenario.noise
    noise_std = np.append(noise.forecast_std(), [noise.paw_mm, noise.biomass_t_ha]).astype(np.float32)
    return TaskParams(fields_params, initial_state(fields_params), noise_std, float(scenario.irrigation_cost_per_mm),
                      float(scenario.max_irrigation_mm))


@dataclass(frozen=True)
class TaskState:
    """N fields: the crop (at the start of its day) and the index of each field's season in the table."""

    crop: CropState
    season: np.ndarray | int


def initial(params: TaskParams, season) -> TaskState:
    """Every field on its sowing day, in the seasons ``season`` (indices into the table, shape (N,); an
    int for scalar ``params``)."""
    if isinstance(season, int):
        return TaskState(params.sowing_state, season)
    return TaskState(params.sowing_state, np.asarray(season, dtype=np.int64))


def restart(params: TaskParams, state: TaskState, mask: np.ndarray, season: np.ndarray) -> TaskState:
    """The fields selected by ``mask`` back on their sowing day in the seasons ``season`` (shape (N,));
    the others unchanged."""
    crop = CropState(**{name: np.where(mask, getattr(params.sowing_state, name), value)
                        for name, value in state.crop._asdict().items()})
    return TaskState(crop, np.where(mask, season, state.season))


def transition(params: TaskParams, table: SeasonTable, state: TaskState,
               irrigation_mm: np.ndarray, xp=np) -> tuple[TaskState, DailyFluxes]:
    """One day of every field with ``irrigation_mm`` (checked, within [0, max]) applied; the next state and
    the day's fluxes. Fields past their weather (truncated) repeat its last day. ``xp``: numpy, or
    SCALAR_MATH for one field held as Python floats (:func:`scalar_task_params`)."""
    weather = _daily_weather(table.model_weather, state.season, state.crop.days_since_sowing, xp)
    crop, fluxes = step(params.fields, state.crop, weather, irrigation_mm, xp)
    return TaskState(crop, state.season), fluxes


def observation(params: TaskParams, table: SeasonTable, state: TaskState, rng: np.random.Generator) -> np.ndarray:
    """The (N, 20) float32 observations of ``state`` (see the module table); noise drawn from ``rng``.
    A scalar state (one field as Python floats) gives one observation of shape (20,)."""
    crop = state.crop
    # Day, today's and tomorrow's weather (the table's padding makes the day after the last day the last day).
    rows = table.observation_rows
    index = _row_index(rows.shape[1], state.season, crop.days_since_sowing)
    rows = rows.reshape(-1, OBSERVATION_SIZE)
    # One field: plain indexing (np.take costs ~1 us of dispatch); N fields: np.take (the fastest gather).
    obs = rows[index].copy() if isinstance(index, int) else np.take(rows, index, axis=0)
    obs[..., BIOMASS] = crop.biomass_kg_ha / KG_PER_T
    obs[..., 1] = crop.thermal_time_degc_d
    obs[..., PAW] = crop.plant_available_water_mm
    if params.noisy:
        # Noise columns: the 8 forecast values and PAW (observation columns 11-19), then biomass.
        noise = rng.standard_normal(obs.shape[:-1] + (len(params.noise_std),), dtype=np.float32)
        noise *= params.noise_std
        obs[..., FORECAST.start:] += noise[..., :-1]
        obs[..., BIOMASS] += noise[..., -1]
        np.maximum(obs, OBSERVATION_LOW, out=obs)
    return obs


def reward(params: TaskParams, state: TaskState, irrigation_mm: np.ndarray, next_state: TaskState,
           xp=np) -> np.ndarray:
    """C_I * irrigation every day, plus the dry yield (t/ha) on the day the field matures."""
    harvest = next_state.crop.mature & xp.logical_not(state.crop.mature)
    yield_t_ha = harvestable_yield_kg_ha(params.fields, next_state.crop) / KG_PER_T
    return params.irrigation_cost_per_mm * irrigation_mm + xp.where(harvest, yield_t_ha, 0.0)


def crop_info(params: TaskParams, crop: CropState) -> dict:
    """The true crop state as ``info`` entries (d, t/ha, mm, degC d), for one field (scalars) or N (arrays)."""
    return {
        "day": crop.days_since_sowing,
        "true_biomass_t_ha": crop.biomass_kg_ha / KG_PER_T,
        "true_paw_mm": crop.plant_available_water_mm,
        "thermal_time_degc_d": crop.thermal_time_degc_d,
        "fsolar": crop.fsolar,
        "yield_t_ha": harvestable_yield_kg_ha(params.fields, crop) / KG_PER_T,
        "mature": crop.mature,
    }


def terminal(state: TaskState) -> np.ndarray:
    """The field's crop reached maturity (or harvest)."""
    return state.crop.mature


def truncated(table: SeasonTable, state: TaskState, xp=np) -> np.ndarray:
    """The field's weather (at most max_season_days days) ran out before maturity."""
    return xp.logical_not(state.crop.mature) & (state.crop.days_since_sowing >= table.n_days[state.season])


def stack_tables(tables: list[SeasonTable]) -> SeasonTable:
    """One table holding the seasons of ``tables`` in order (padded to the longest)."""
    width = max(t.weather.shape[1] for t in tables)

    def pad(array: np.ndarray) -> np.ndarray:
        return np.pad(array, ((0, 0), (0, width - array.shape[1])) + ((0, 0),) * (array.ndim - 2), mode="edge")

    return _frozen_table(np.concatenate([pad(t.weather) for t in tables]),
                         np.concatenate([pad(t.et0_mm) for t in tables]), np.concatenate([t.n_days for t in tables]),
                         np.concatenate([t.sowing_dates for t in tables]),
                         np.concatenate([t.potential_yield_t_ha for t in tables]),
                         sum((t.sources for t in tables), ()), sum((t.filled for t in tables), ()))
