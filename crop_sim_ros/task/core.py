"""The functional core of the irrigation task for N fields at once: pure numpy, randomness passed in.

In the style of Gymnasium's functional environments: :func:`task_params` (the static parameters),
:func:`initial`, :func:`transition`, :func:`observation`, :func:`reward`, :func:`terminal`,
:func:`truncated`. Every function works on arrays of shape (N,) (one row per field) and draws randomness
only from the ``numpy.random.Generator`` it is given, or takes it drawn by the caller (``noise``). The crop itself
is :func:`crop_sim_ros.model.step`.

Array namespace: the functions of a step (:func:`daily_weather`, :func:`admissible_irrigation_mm`,
:func:`transition`, :func:`observation`, :func:`reward`, :func:`terminal`, :func:`truncated`) take ``xp``:
numpy (the default: the vector environment's path), :data:`~crop_sim_ros.model.simple.SCALAR_MATH` (one field as
Python floats) or any numpy-like namespace without in-place updates, such as ``jax.numpy``
(:mod:`crop_sim_ros.task.jax_env`), where the table is any object with the arrays of a :class:`SeasonTable` the
step reads (``model_weather``, ``observation_rows``, ``et0_mm``, ``n_days``) and the observation noise is given.

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
import statistics
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from ..model import (CropState, DailyFluxes, DailyWeather, FieldParameters, harvestable_yield_kg_ha,
                     initial_state, repeat_parameters, step)
from ..model.simple import SCALAR_MATH, scalar_parameters, scalar_state
from ..weather import WeatherSeries
from .layout import (BIOMASS, DAY, FORECAST, PAPER, PAW, PAW_OBSERVED, QUOTA_OBSERVED_CAP_MM, THERMAL_TIME, TODAY,
                     WEATHER_NAMES, ObservationLayout)
from .scenario import ObservationNoise, Scenario
from .terms import FarmLimits, Range

KG_PER_T = 1000.0
# The paper's layout (the family's extended layout appends to it: see crop_sim_ros.task.layout).
OBSERVATION_NAMES = PAPER.names
OBSERVATION_UNITS = PAPER.units
OBSERVATION_SIZE = PAPER.size
# Column of each model input in SeasonTable.weather.
TMAX, TMIN, RAIN, SRAD = (WEATHER_NAMES.index(n) for n in ("tmax_degc", "tmin_degc", "rain_mm", "srad_mj_m2"))
# SeasonTable.model_weather columns: the DailyWeather fields in order (TMAX, TMIN, SRAD, rain, ET0).
# Bounds of a physically possible observation: noisy values below the lower bound are clipped to it.
OBSERVATION_LOW = PAPER.low
OBSERVATION_HIGH = PAPER.high
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
    observed[..., DAY] = np.arange(observed.shape[1])
    observed[..., TODAY] = weather[:, :-1]
    observed[..., FORECAST] = weather[:, 1:]
    observed = np.ascontiguousarray(observed)
    model = _model_weather(weather, et0_mm)
    for array in (weather, observed, model, et0_mm, n_days, sowing_dates, potential_yield_t_ha):
        array.setflags(write=False)
    return SeasonTable(weather, observed, model, et0_mm, n_days, sowing_dates, potential_yield_t_ha, sources,
                       filled)


def scenario_table(scenario: Scenario) -> SeasonTable:
    """The table of every season of ``scenario`` (built once per process and weather: resets stay cheap, and
    the family tasks that share a weather source share one table)."""
    return _weather_table(replace(scenario, name="weather", description="", noise=ObservationNoise(), economics=None,
                                  limits=FarmLimits(), irrigation_cost_per_mm=-1.25e-4, max_irrigation_mm=100.0))


@functools.lru_cache(maxsize=16)
def _weather_table(scenario: Scenario) -> SeasonTable:
    """The table of ``scenario``, whose fields that do not shape the table (name, noise, terms) are neutral."""
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
    for one field held as Python floats (``xp`` = SCALAR_MATH); another namespace (jax.numpy) gathers with
    its own indexing (any shape of indices)."""
    if xp is np:
        index = _row_index(model_weather.shape[2], season, day)
        flat = model_weather.reshape(len(model_weather), -1)
        return DailyWeather(*(np.take(variable, index) for variable in flat))
    if xp is SCALAR_MATH:
        return DailyWeather(*model_weather[:, season, day].tolist())
    days = model_weather[:, season, day]
    return DailyWeather(*(days[k] for k in range(len(DailyWeather._fields))))


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
    """The static parameters of the task for N fields.

    ======================== ========================================================================
    Name                     Description
    ======================== ========================================================================
    fields, sowing_state     the model's field parameters (N fields) and their sowing-day state
    noise_std                float32 (10,): noise std of the 8 forecast values and PAW (observation
                             order: degC, degC, degC, mm, MJ m-2, ppm, hPa, m s-1, mm), then biomass t ha-1
    max_irrigation_mm        the action's upper bound, mm d-1
    layout                   the observation layout (paper: 20 values; family: 29)
    yield_value_per_t        reward units per t ha-1 of dry yield, drawn per episode: 1 (t/ha reward) or
                             tuber price USD t-1 (fresh) / dry-matter fraction
    water_price_per_mm,      reward units per mm irrigated, each drawn per episode (the paper: C_I's
    pumping_energy_per_mm    magnitude and 0)
    event_cost               reward units per day with irrigation
    dry_matter_fraction      of fresh tubers (1 for the t/ha reward), for the observed tuber price
    quota_mm                 season allocation, mm, drawn per episode (inf: none)
    capacity_mm_per_day      most applied in one day, mm d-1 (max_irrigation_mm when unlimited)
    nominal_season_days      d, the observation's season_days_left counts down from it
    paw_dropout_probability  chance a day's PAW reading is missing; paw_sensor False: never read
    ======================== ========================================================================
    """

    fields: FieldParameters
    sowing_state: CropState
    noise_std: np.ndarray
    max_irrigation_mm: float
    layout: ObservationLayout = PAPER
    yield_value_per_t: Range = Range(1.0, 1.0)
    water_price_per_mm: Range = Range(1.25e-4, 1.25e-4)
    pumping_energy_per_mm: Range = Range(0.0, 0.0)
    event_cost: float = 0.0
    dry_matter_fraction: float = 1.0
    quota_mm: Range = Range(np.inf, np.inf)
    capacity_mm_per_day: float = np.inf
    nominal_season_days: int = 150
    paw_dropout_probability: float = 0.0
    paw_sensor: bool = True

    @functools.cached_property
    def noisy(self) -> bool:
        """Any observation noise or dropout at all (cached: the observation is on the hot path)."""
        return bool(self.noise_std.any()) or self.paw_dropout_probability > 0.0

    @functools.cached_property
    def noise_columns(self) -> int:
        """Standard normals drawn per field and day: the noise_std columns, and one more that decides the PAW
        dropout (missing when below the normal quantile of the dropout probability)."""
        return len(self.noise_std) + (self.paw_dropout_probability > 0.0)

    @functools.cached_property
    def limited(self) -> bool:
        """A capacity below the action bound or a quota: irrigation may be cut (see admissible_irrigation_mm)."""
        return self.capacity_mm_per_day < self.max_irrigation_mm or np.isfinite(self.quota_mm.high)

    @functools.cached_property
    def _dropout_z(self) -> float:
        p = self.paw_dropout_probability
        return -np.inf if p <= 0.0 else (np.inf if p >= 1.0 else statistics.NormalDist().inv_cdf(p))


def scalar_task_params(params: TaskParams) -> TaskParams:
    """The first field of ``params`` held as Python floats: the one-field fast path (``xp`` = SCALAR_MATH),
    bit-identical to the array path."""
    return replace(params, fields=scalar_parameters(params.fields), sowing_state=scalar_state(params.sowing_state))


def task_params(scenario: Scenario, n_fields: int = 1) -> TaskParams:
    """The task parameters of ``n_fields`` fields of ``scenario``."""
    fields_params = repeat_parameters(scenario.field_parameters(), n_fields)
    noise: ObservationNoise = scenario.noise
    noise_std = np.append(noise.forecast_std(), [noise.paw_mm, noise.biomass_t_ha]).astype(np.float32)
    params = TaskParams(fields_params, initial_state(fields_params), noise_std, float(scenario.max_irrigation_mm),
                        water_price_per_mm=Range(-scenario.irrigation_cost_per_mm, -scenario.irrigation_cost_per_mm))
    money, limits = scenario.economics, scenario.limits
    if not scenario.is_family_task:
        return params
    price = money.tuber_price_usd_per_t
    dmf = money.tuber_dry_matter_fraction
    return replace(
        params, layout=scenario.layout, yield_value_per_t=Range(price.low / dmf, price.high / dmf),
        water_price_per_mm=money.water_price_usd_per_mm, pumping_energy_per_mm=money.pumping_energy_usd_per_mm,
        event_cost=money.event_cost_usd, dry_matter_fraction=dmf,
        quota_mm=limits.quota_mm or Range(np.inf, np.inf),
        capacity_mm_per_day=(np.inf if limits.capacity_mm_per_day is None else limits.capacity_mm_per_day),
        nominal_season_days=limits.nominal_season_days, paw_dropout_probability=limits.paw_dropout_probability,
        paw_sensor=limits.paw_sensor)


class EpisodeTerms(NamedTuple):
    """What each field draws at the start of its episode (arrays (N,), or floats for one scalar field):
    ``yield_value_per_t`` (reward units per t ha-1 of dry yield), ``water_cost_per_mm`` (reward units per mm:
    delivered water + pumping energy) and ``quota_mm`` (the season's allocation, mm; inf = none)."""

    yield_value_per_t: np.ndarray | float
    water_cost_per_mm: np.ndarray | float
    quota_mm: np.ndarray | float


def draw_terms(params: TaskParams, rng: np.random.Generator | None, n: int | None) -> EpisodeTerms:
    """The episode terms of ``n`` fields (``n`` None: one scalar field), drawn from ``rng``. A task whose
    terms are all fixed (the paper's) draws nothing, so its random stream is unchanged."""
    ranges = (params.yield_value_per_t, params.water_price_per_mm, params.pumping_energy_per_mm, params.quota_mm)
    if rng is None and not all(r.fixed for r in ranges):
        raise ValueError("this task draws prices or quotas per episode: initial/restart need a random generator")
    value, water, energy, quota = (r.draw(rng, n) for r in ranges)
    return EpisodeTerms(value, water + energy, quota)


def given_terms(drawn: EpisodeTerms, given: dict) -> EpisodeTerms:
    """``drawn`` with the entries of ``given`` (name -> array of the same shape) in their place; ValueError
    names an unknown term or a wrong shape."""
    unknown = sorted(set(given) - set(EpisodeTerms._fields))
    if unknown:
        raise ValueError(f"terms: unknown {unknown}; known: {', '.join(EpisodeTerms._fields)}")
    values = drawn._asdict()
    for name, value in given.items():
        value = np.asarray(value, dtype=float)
        if value.shape != np.shape(values[name]) or np.isnan(value).any() or (value < 0).any():
            raise ValueError(f"terms.{name}: expected {np.shape(values[name])} non-negative numbers, got {value!r}")
        values[name] = value
    return EpisodeTerms(**values)


class TaskState(NamedTuple):
    """N fields (arrays (N,)), or one field as Python scalars: the crop (at the start of its day), the index
    of each field's season in the table, the episode's terms, the irrigation applied so far this season
    (mm) and yesterday (mm)."""

    crop: CropState
    season: np.ndarray | int
    terms: EpisodeTerms
    irrigated_mm: np.ndarray | float
    last_irrigation_mm: np.ndarray | float


def initial(params: TaskParams, season, rng: np.random.Generator | None = None) -> TaskState:
    """Every field on its sowing day, in the seasons ``season`` (indices into the table, shape (N,); an
    int for scalar ``params``), with its episode terms drawn from ``rng`` (see :func:`draw_terms`)."""
    if isinstance(season, int):
        return TaskState(params.sowing_state, season, draw_terms(params, rng, None), 0.0, 0.0)
    season = np.asarray(season, dtype=np.int64)
    zeros = np.zeros(len(season))
    return TaskState(params.sowing_state, season, draw_terms(params, rng, len(season)), zeros, zeros)


def restart(params: TaskParams, state: TaskState, mask: np.ndarray, season: np.ndarray,
            rng: np.random.Generator | None = None) -> TaskState:
    """The fields selected by ``mask`` back on their sowing day in the seasons ``season`` (shape (N,)), with
    new episode terms drawn from ``rng`` for them; the others unchanged."""
    rows = np.flatnonzero(mask)  # usually a few fields: copying and overwriting them beats np.where

    def merged(new, old) -> np.ndarray:
        """``np.where(mask, new, old)``: ``new`` (an array (N,) or a scalar) in the fields of ``mask``."""
        values = np.array(old, dtype=np.result_type(new, old), copy=True)
        values[rows] = new[rows] if np.ndim(new) else new
        return values

    crop = CropState(**{name: merged(getattr(params.sowing_state, name), value)
                        for name, value in state.crop._asdict().items()})
    drawn = draw_terms(params, rng, len(rows))
    terms = []
    for old, new in zip(state.terms, drawn):
        terms.append(np.array(old, dtype=float, copy=True))
        terms[-1][rows] = new
    return TaskState(crop, merged(season, state.season), EpisodeTerms(*terms), merged(0.0, state.irrigated_mm),
                     merged(0.0, state.last_irrigation_mm))


def admissible_irrigation_mm(params: TaskParams, state: TaskState, irrigation_mm, xp=np):
    """``irrigation_mm`` (already within [0, max_irrigation_mm]) cut to the system's daily capacity and to
    the season's quota left: what the field can actually receive today."""
    if not params.limited:
        return irrigation_mm
    left = xp.maximum(state.terms.quota_mm - state.irrigated_mm, 0.0)
    return xp.minimum(xp.minimum(irrigation_mm, params.capacity_mm_per_day), left)


def daily_weather(table: SeasonTable, state: TaskState, xp=np) -> DailyWeather:
    """The model's weather of each field's current day (fields past their weather repeat its last day)."""
    return _daily_weather(table.model_weather, state.season, state.crop.days_since_sowing, xp)


def transition(params: TaskParams, table: SeasonTable, state: TaskState,
               irrigation_mm: np.ndarray, xp=np, weather: DailyWeather | None = None) -> tuple[TaskState, DailyFluxes]:
    """One day of every field with ``irrigation_mm`` (checked, admissible: see
    :func:`admissible_irrigation_mm`) applied; the next state and the day's fluxes. Fields past their
    weather (truncated) repeat its last day. ``xp``: numpy, or SCALAR_MATH for one field held as Python
    floats (:func:`scalar_task_params`). ``weather``: :func:`daily_weather` of ``state``, if the caller
    already gathered it."""
    if weather is None:
        weather = daily_weather(table, state, xp)
    crop, fluxes = step(params.fields, state.crop, weather, irrigation_mm, xp)
    return TaskState(crop, state.season, state.terms, state.irrigated_mm + irrigation_mm, irrigation_mm), fluxes


def observation(params: TaskParams, table: SeasonTable, state: TaskState, rng: np.random.Generator | None = None,
                noise: np.ndarray | None = None, xp=np) -> np.ndarray:
    """The (N, layout size) float32 observations of ``state`` (see :mod:`crop_sim_ros.task.layout`); noise
    drawn from ``rng``, or given: ``noise`` (N, ``params.noise_columns``) float32 standard normals, as ``rng``
    would draw them (unused when the task has no noise). A scalar state (one field as Python floats) gives one
    observation of shape (size,). ``xp`` other than numpy: see :func:`_observation_functional`."""
    if xp is not np:
        return _observation_functional(params, table, state, noise, xp)
    crop = state.crop
    # Day, today's and tomorrow's weather (the table's padding makes the day after the last day the last day).
    rows = table.observation_rows
    index = _row_index(rows.shape[1], state.season, crop.days_since_sowing)
    rows = rows.reshape(-1, OBSERVATION_SIZE)
    # One field: plain indexing (np.take costs ~1 us of dispatch); N fields: np.take (the fastest gather).
    obs = rows[index].copy() if isinstance(index, int) else np.take(rows, index, axis=0)
    if params.layout is not PAPER:
        obs = np.concatenate([obs, _extension(params, table, state)], axis=-1)
    obs[..., BIOMASS] = crop.biomass_kg_ha / KG_PER_T
    obs[..., THERMAL_TIME] = crop.thermal_time_degc_d
    obs[..., PAW] = crop.plant_available_water_mm
    if params.noisy:
        # Noise columns: the 8 forecast values and PAW (observation columns 11-19), then biomass, then the
        # dropout draw (if the task has dropouts).
        if noise is None:
            noise = rng.standard_normal(obs.shape[:-1] + (params.noise_columns,), dtype=np.float32)
        else:  # scaled in place below: the caller's array stays as given
            noise = np.array(noise, dtype=np.float32, copy=True).reshape(obs.shape[:-1] + (params.noise_columns,))
        if params.paw_dropout_probability > 0.0:
            missing = noise[..., -1] < params._dropout_z
            noise = noise[..., :-1]
        _per_row(np.multiply, noise, params.noise_std)
        obs[..., FORECAST.start:PAW + 1] += noise[..., :-1]
        obs[..., BIOMASS] += noise[..., -1]
        _per_row(np.maximum, obs, params.layout.low)
        if params.paw_dropout_probability > 0.0:
            obs[..., PAW] = np.where(missing, 0.0, obs[..., PAW])
            obs[..., PAW_OBSERVED] = np.where(missing, 0.0, obs[..., PAW_OBSERVED])
    if not params.paw_sensor:
        obs[..., PAW] = 0.0
    return obs


_ROWS_PER_BLOCK = 64


def _per_row(ufunc: np.ufunc, values: np.ndarray, row: np.ndarray) -> None:
    """``values[i] = ufunc(values[i], row)`` for every row of ``values`` (N, k), in place. A C-contiguous
    batch goes as blocks of 64 rows against ``row`` tiled 64 times: numpy's inner loop then runs over a block,
    not over one short row whose call costs more than its arithmetic (the same numbers, several times faster)."""
    whole = len(values) - len(values) % _ROWS_PER_BLOCK if values.ndim == 2 and values.flags.c_contiguous else 0
    if whole:
        blocks = values[:whole].reshape(-1, _ROWS_PER_BLOCK * values.shape[1])
        ufunc(blocks, np.tile(row, _ROWS_PER_BLOCK), out=blocks)
    ufunc(values[whole:], row, out=values[whole:])


def _observation_functional(params: TaskParams, table, state: TaskState, noise, xp) -> np.ndarray:
    """:func:`observation` in a namespace without in-place updates (jax.numpy), the noise given: the same
    float32 values in the same order of operations (the crop's values rounded to float32, the scaled noise
    added in float32, then the lower bounds, the dropouts and the missing sensor), for state arrays of any
    shape (a field's scalars under ``jax.vmap``, or (N,))."""
    crop = state.crop
    f32 = xp.float32
    rows = table.observation_rows[state.season, crop.days_since_sowing]

    def column(values):
        return xp.asarray(values, dtype=f32)[..., None]

    parts = [column(crop.biomass_kg_ha / KG_PER_T), column(crop.thermal_time_degc_d), rows[..., DAY:PAW],
             column(crop.plant_available_water_mm)]
    if params.layout is not PAPER:
        parts.append(_extension(params, table, state, xp))
    obs = xp.concatenate(parts, axis=-1)
    size = params.layout.size
    columns = np.arange(size)
    if params.noisy:
        # numpy rounds the product noise x std to float32, then the sum. A compiler may fuse a float32 multiply
        # and add into one multiply-add (one rounding: XLA on CPU does), so where the namespace offers a wider
        # float the product is formed there and rounded to float32 explicitly (``round_to_float32``: an
        # operation the compiler keeps), and the sum formed there too: the same values as numpy's.
        noise = xp.asarray(noise, dtype=f32)
        wide = xp.zeros(()).dtype
        round_to_float32 = getattr(xp, "round_to_float32", lambda values: values.astype(f32).astype(wide))
        scaled = round_to_float32(noise[..., :len(params.noise_std)].astype(wide) * params.noise_std.astype(wide))
        zeros = xp.zeros(scaled.shape[:-1] + (FORECAST.start - 1,), dtype=wide)
        after = xp.zeros(scaled.shape[:-1] + (size - PAW - 1,), dtype=wide)
        added = obs.astype(wide) + xp.concatenate([scaled[..., -1:], zeros, scaled[..., :-1], after], axis=-1)
        obs = xp.maximum(added.astype(f32), params.layout.low)
        if params.paw_dropout_probability > 0.0:
            missing = (noise[..., -1] < params._dropout_z)[..., None]
            obs = xp.where(missing & ((columns == PAW) | (columns == PAW_OBSERVED)), f32(0.0), obs)
    if not params.paw_sensor:
        obs = xp.where(columns == PAW, f32(0.0), obs)
    return obs


def _extension(params: TaskParams, table: SeasonTable, state: TaskState, xp=np) -> np.ndarray:
    """The family's extra observation values (layout columns 20-28) of ``state``, float32."""
    terms = state.terms
    day = state.crop.days_since_sowing
    if xp is np:
        et0 = np.take(table.et0_mm, _row_index(table.et0_mm.shape[1], state.season, day))
    else:
        et0 = table.et0_mm[state.season, day]
    left = xp.minimum(xp.maximum(xp.asarray(terms.quota_mm) - state.irrigated_mm, 0.0), QUOTA_OBSERVED_CAP_MM)
    values = (xp.asarray(terms.yield_value_per_t) * params.dry_matter_fraction, terms.water_cost_per_mm,
              params.event_cost, left, xp.maximum(params.nominal_season_days - xp.asarray(day), 0),
              xp.minimum(params.capacity_mm_per_day, params.max_irrigation_mm), 1.0 if params.paw_sensor else 0.0,
              state.last_irrigation_mm, et0)
    shape = xp.shape(day)
    return xp.stack([xp.broadcast_to(xp.asarray(v, dtype=xp.float32), shape) for v in values], axis=-1)


def reward(params: TaskParams, state: TaskState, irrigation_mm: np.ndarray, next_state: TaskState,
           xp=np) -> np.ndarray:
    """The value of the dry yield (t ha-1 x yield value per t) on the day the field matures, minus the
    water's cost (mm x cost per mm) and the event cost of a day with irrigation. Paper task: C_I * a + Y."""
    harvest = next_state.crop.mature & xp.logical_not(state.crop.mature)
    yield_t_ha = harvestable_yield_kg_ha(params.fields, next_state.crop) / KG_PER_T
    cost = state.terms.water_cost_per_mm * irrigation_mm
    if params.event_cost:
        cost = cost + params.event_cost * (irrigation_mm > 0.0)
    return xp.where(harvest, state.terms.yield_value_per_t * yield_t_ha, 0.0) - cost


def terms_info(state: TaskState) -> dict:
    """The episode's terms as ``info`` entries: reward units per t/ha of dry yield, per mm, and the quota (mm)."""
    return {"yield_value_per_t": state.terms.yield_value_per_t, "water_cost_per_mm": state.terms.water_cost_per_mm,
            "quota_mm": state.terms.quota_mm}


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
    """The field's weather (at most max_season_days days) ran out before maturity. ``xp`` other than numpy:
    ``table.n_days`` an array of that namespace."""
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
