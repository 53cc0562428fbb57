"""Scenarios of the irrigation task, as data: crop, soil, site, weather source, observation noise, costs.

A scenario is a small YAML file in ``crop_sim_ros/task/scenarios/`` (package data) read into a frozen
:class:`Scenario`; :func:`get_scenario` finds one by name. Weather files are named relative to the data
directory (``data_dir``; by default :func:`default_data_dir`: ``$CROP_SIM_DATA_DIR``, else the ``shared/data``
beside the checkout, never copied into it).

Weather sources (``weather.kind``):

- ``generator``: a pool of ``n_seasons`` seasons drawn at once by the seeded weather generator
  (``crop_sim_ros.weather.generator``) with seed ``seed``, sown on ``sowing_date``; ``reset`` picks one.
  ``n_seasons: 1`` is a single fixed generated season. ``warming_degc`` (default 0, at most 10 either way)
  raises the generator's mean TMAX and TMIN by that much (a delta-change climate scenario,
  ``crop_sim_ros.weather.generator.warmed``); ``drying_degc`` (likewise) raises its mean dew-point depression
  (TMIN - dew point: drier air, ``dried``; only for a generator fitted with humidity data);
  ``diurnal_range_degc`` (likewise) widens TMAX - TMIN, TMAX up and TMIN down by half each (``widened``);
  ``rain_factor`` (default 1, in [0, 3]) multiplies every wet day's rain (``rain_scaled``); ``radiation_factor``
  (default 1, in [0.5, 2]) every monthly mean and standard deviation of SRAD, each day still capped at clear-sky
  radiation (clearer skies, ``brightened``). ``spread`` (instead of those) gives ranges from which every season
  draws its own warming, drying, rain factor and sowing delay after ``sowing_date``, uniformly (``ClimateSpread``:
  ``spread: {warming_degc: [0, 8], sowing_delay_days: [0, 61]}``; domain randomisation across climates). Needs
  no file.
- ``file``: one weather file (``path``, ``format``), the season starting on ``sowing_date``.
- ``seasons``: several (file, format, sowing date) seasons; ``reset`` picks one (or the one asked for).
  A ``file`` or ``seasons`` source may name its site's ``climate``: the fitted generator of that site (what a
  climate outlook reads on these real seasons, and whose seasons a planner draws there), e.g. ``maricopa``.
- ``mixture``: the seasons of several built-in scenarios (``mixture: [benton-generated, gainesville-generated]``),
  each prepared as its own scenario prepares it (its sowing date, site and season length): training across
  climates.

A scenario file is read by :mod:`crop_sim_ros.safe_yaml` (a regular file of at most 64 KiB, no YAML aliases,
nesting at most 32 deep, no duplicate keys) and checked by a strict schema derived from these dataclasses
(:mod:`crop_sim_ros.task.schema`, with the ranges of BOUNDS): a number is a number (not true/false, not text;
an integer where a float belongs is that float), finite and in its range, a name one of its choices, every
required field present and no unknown one; one ValueError lists every problem with its path
(``limits.quota_mm: true is not a finite number in [0, 10000]``), never quoting more of the file than a short
name. A scenario file may derive from another (``base: NAME``, a built-in name or a YAML path beside it): it
takes the base's fields and replaces those it names (``noise``, ``economics`` and ``limits`` field by field),
in a chain of at most MAX_BASE_CHAIN (32) files without a cycle; a base that is not a scenario file is refused
by its name, never its contents. The
task family's scenarios (``benton-money``, ``benton-quota``, ``benton-capacity``, ``benton-sensing``,
``benton-blind``, ``climates-quota``, ``climates3-quota``, ``climates4-quota``, ``climates6-quota``,
``climates8-quota``, ``climates10-quota``, ``climates12-quota``, ``climates-spread-quota``, ``benton-early-quota``,
``benton-early-pivot``, ``benton-early-warm-quota``, ``maricopa-late-quota``, ``maricopa-sown-spread-quota``,
``climates-hot-quota``) derive from ``benton-generated`` this way; their terms are documented in
:mod:`crop_sim_ros.task.terms`.

File formats: ``agweathernet`` (AgWeatherNet daily CSV), ``dssat`` (DSSAT .WTH), ``csv`` (the plain daily CSV of
``crop_sim_ros.weather.csv_readers.read_plain_csv``).

Every season runs from its sowing date for at most ``max_season_days`` days (fewer if the weather ends
first). Sizes are bounded so that a typo cannot exhaust the memory: ``max_season_days`` at most
MAX_SEASON_DAYS (730, two years), a generator's ``n_seasons`` at most MAX_GENERATED_SEASONS (10,000), and
their product at most MAX_GENERATED_DAYS (2,000,000 season-days: about 0.7 GB and 15 s to generate here).
Missing vapour pressure and wind (the DSSAT files of Paterson, WA have neither) are filled by
FAO-56's missing-data rules (``WeatherSeries.with_fao56_fills``: e_a from TMIN, wind 2 m/s); the
environment reports the fills in ``info["weather_filled"]``.

Built-in scenarios: ``benton-generated`` (the default; generated Benton County weather), ``benton-2000``
(the seed paper's season: AgWeatherNet Benton E., 2000), ``paterson-1992`` .. ``paterson-1995`` (held-out
real seasons of the SIMPLE input set, DSSAT WAPA9201..9501.WTH, sowing dates of its Treatment.csv), and
``heldout`` (the five real seasons together, for evaluation). Other climates: ``gainesville-generated`` and
``maricopa-generated`` (generated weather of Gainesville, FL and Maricopa, AZ, sown in their winter
planting seasons), ``gainesville-real`` and ``maricopa-real`` (their distinct real years, sown on the same
dates); ``benton-early-generated`` (Benton County sown March 1, the early end of its planting window);
``maricopa-late-generated`` and ``maricopa-late-real`` (Maricopa sown February 28, the late end of its window);
``benton-late-generated`` (Benton sown May 1); ``benton-early-warm-generated``, ``benton-warm-generated``,
``benton-late-warm-generated`` and ``gainesville-warm-generated`` (4 degC warmer, delta-change);
``benton-spread-generated`` (every season its own delta-changed Benton climate and sowing date). Every
built-in scenario grows Russet Burbank potato on the Benton County soil at 369 ppm CO2 (the 2000 global mean;
the held-out seasons keep it so that only the weather differs from training).
"""

from __future__ import annotations

import functools
import math
import os
import warnings
from dataclasses import dataclass, fields, replace
from datetime import date
from pathlib import Path
from typing import Any

import numpy as np

from ..model import FieldParameters, Management, UnknownNameError, crop_library, field_parameters
from ..model.et0 import ET0_METHODS
from ..safe_yaml import read_yaml
from ..weather import GENERATOR_NAMES, Site, WeatherError, WeatherSeries, read_agweathernet_csv, read_dssat_wth
from ..weather.csv_readers import read_plain_csv
from ..weather.generator import (MAX_DELTA_DEGC, MAX_RADIATION_FACTOR, MAX_RAIN_FACTOR, MAX_SOWING_DELAY_DAYS,
                                 MIN_RADIATION_FACTOR, MIN_RAIN_FACTOR, ClimateSpread, climate_name,
                                 climate_parameters, generate_seasons, generate_spread_seasons)
from .layout import EXTENDED, PAPER, ObservationLayout
from .schema import Rules, shown, validated
from .terms import (MAX_EVENT_COST_USD, MAX_NOMINAL_SEASON_DAYS, MAX_PRICE_USD_PER_T, MAX_QUOTA_MM,
                    MAX_WATER_COST_USD_PER_MM, Economics, FarmLimits, check_number as _check_number)

# The environment variable that names the reference data directory (see default_data_dir).
DATA_DIR_ENV = "CROP_SIM_DATA_DIR"
# Where an installed package keeps the reference data (share/crop_sim_ros/<this>), found through the ament index.
INSTALLED_DATA_SUBDIR = "data"
# crop_sim_ros/task/scenario.py -> parents[1] is the package directory.
PACKAGE_DIR = Path(__file__).resolve().parents[1]
SCENARIO_DIR = Path(__file__).with_name("scenarios")
WEATHER_KINDS = ("generator", "file", "seasons", "mixture")
WEATHER_FORMATS = ("agweathernet", "dssat", "csv")
# The weather generator's parameter sets (one per climate, crop_sim_ros/weather/<name>_generator.json).
GENERATOR_PARAMETERS = GENERATOR_NAMES
# Every weather variable the task needs each day (the model's four plus what ET0 and the observation use).
TASK_WEATHER_VARIABLES = ("tmax_degc", "tmin_degc", "srad_mj_m2", "rain_mm", "vap_hpa", "wind_m_s")
# Upper bounds of the sizes a scenario sets (see the module docstring).
MAX_SEASON_DAYS = 730
MAX_GENERATED_SEASONS = 10_000
MAX_GENERATED_DAYS = 2_000_000
MAX_NOISE_STD = 1e6  # any observation noise standard deviation, in its variable's unit (float32 stays finite)
MIN_ELEVATION_M, MAX_ELEVATION_M = -500.0, 9000.0  # a site's elevation (the Dead Sea shore to above Everest)
MAX_SEED = 2**63 - 1
MAX_BASE_CHAIN = 32  # files in a chain of ``base:`` (the built-ins use 3 at most)
# The ranges of a scenario's numbers (the schema's, and the checks of the dataclasses built in code).
BOUNDS: dict[str, tuple[float | None, float | None]] = {
    "co2_ppm": (0.0, 5000.0), "irrigation_cost_per_mm": (None, 0.0), "max_irrigation_mm": (0.0, 1000.0),
    "max_season_days": (1, MAX_SEASON_DAYS), "noise.*": (0.0, MAX_NOISE_STD),
    "site.latitude_deg": (-90.0, 90.0), "site.longitude_deg": (-180.0, 360.0),
    "site.elevation_m": (MIN_ELEVATION_M, MAX_ELEVATION_M),
    "weather.seed": (0, MAX_SEED), "weather.n_seasons": (1, MAX_GENERATED_SEASONS),
    **{f"weather.{name}": (-MAX_DELTA_DEGC, MAX_DELTA_DEGC) for name in ("warming_degc", "drying_degc",
                                                                          "diurnal_range_degc")},
    "weather.rain_factor": (MIN_RAIN_FACTOR, MAX_RAIN_FACTOR),
    "weather.radiation_factor": (MIN_RADIATION_FACTOR, MAX_RADIATION_FACTOR),
    "weather.spread.warming_degc": (-MAX_DELTA_DEGC, MAX_DELTA_DEGC),
    "weather.spread.drying_degc": (-MAX_DELTA_DEGC, MAX_DELTA_DEGC),
    "weather.spread.rain_factor": (MIN_RAIN_FACTOR, MAX_RAIN_FACTOR),
    "weather.spread.sowing_delay_days": (0, MAX_SOWING_DELAY_DAYS),
    "economics.tuber_price_usd_per_t": (0.0, MAX_PRICE_USD_PER_T),
    "economics.tuber_dry_matter_fraction": (0.05, 1.0),
    "economics.water_price_usd_per_mm": (0.0, MAX_WATER_COST_USD_PER_MM),
    "economics.pumping_energy_usd_per_mm": (0.0, MAX_WATER_COST_USD_PER_MM),
    "economics.event_cost_usd": (0.0, MAX_EVENT_COST_USD),
    "limits.quota_mm": (0.0, MAX_QUOTA_MM), "limits.capacity_mm_per_day": (0.0, 1000.0),
    "limits.nominal_season_days": (1, MAX_NOMINAL_SEASON_DAYS), "limits.paw_dropout_probability": (0.0, 1.0),
}


def _check_count(name: str, value: Any, high: int) -> None:
    """ValueError unless ``value`` is a whole number in 1..high."""
    if (isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating))
            or not (math.isfinite(value) and value == int(value) and 1 <= value <= high)):
        raise ValueError(f"{name}: {value!r} is not a whole number in 1..{high}")


@dataclass(frozen=True)
class ObservationNoise:
    """Standard deviations of the Gaussian observation noise (Ashcraft & Karra 2021, Table 2).

    ============== ======== ===================================================================
    Name           Unit     Noise on
    ============== ======== ===================================================================
    biomass_t_ha   t ha-1   today's biomass (the paper's "1", read as 1 g m-2 = 0.01 t ha-1)
    paw_mm         mm       today's plant-available water
    tmax_degc      degC     tomorrow's forecast TMAX
    tmin_degc      degC     tomorrow's forecast TMIN
    tavg_degc      degC     tomorrow's forecast TAVG
    rain_mm        mm       tomorrow's forecast rain
    srad_mj_m2     MJ m-2   tomorrow's forecast radiation
    co2_ppm        ppm      tomorrow's forecast CO2
    vap_hpa        hPa      tomorrow's forecast vapour pressure
    wind_m_s       m s-1    tomorrow's forecast wind
    ============== ======== ===================================================================
    """

    biomass_t_ha: float = 0.01
    paw_mm: float = 1.0
    tmax_degc: float = 3.0
    tmin_degc: float = 2.0
    tavg_degc: float = 2.0
    rain_mm: float = 3.0
    srad_mj_m2: float = 1.0
    co2_ppm: float = 1.0
    vap_hpa: float = 1.0
    wind_m_s: float = 6.0

    def __post_init__(self) -> None:
        for item in fields(self):
            object.__setattr__(self, item.name, _check_number(f"noise.{item.name}", getattr(self, item.name),
                                                              *BOUNDS["noise.*"]))

    @classmethod
    def none(cls) -> "ObservationNoise":
        """No noise at all: the observation is the true state and the true tomorrow."""
        return cls(**{item.name: 0.0 for item in fields(cls)})

    def forecast_std(self) -> np.ndarray:
        """The 8 forecast standard deviations in observation order (TMAX TMIN TAVG RAIN SRAD CO2 VAP WIND)."""
        return np.array([self.tmax_degc, self.tmin_degc, self.tavg_degc, self.rain_mm, self.srad_mj_m2,
                         self.co2_ppm, self.vap_hpa, self.wind_m_s])


@dataclass(frozen=True)
class SeasonFile:
    """One real season: a weather file (relative to the data directory, or absolute), its format, the sowing date."""

    path: str
    format: str
    sowing_date: date

    def __post_init__(self) -> None:
        if self.format not in WEATHER_FORMATS:
            raise ValueError(f"weather.format: {self.format!r} is not one of {', '.join(WEATHER_FORMATS)}")
        if not isinstance(self.sowing_date, date):
            raise ValueError(f"weather.sowing_date: expected a date, got {self.sowing_date!r}")


@dataclass(frozen=True)
class WeatherSource:
    """Where a scenario's seasons come from (see the module docstring)."""

    kind: str
    seed: int = 0
    n_seasons: int = 1000
    generator: str = "benton"
    seasons: tuple[SeasonFile, ...] = ()
    mixture: tuple[str, ...] = ()
    warming_degc: float = 0.0
    drying_degc: float = 0.0
    diurnal_range_degc: float = 0.0
    rain_factor: float = 1.0
    radiation_factor: float = 1.0
    climate: str = ""  # real seasons: their site's fitted generator ('' none; a generated source's is its own)
    spread: ClimateSpread | None = None  # a generator source whose every season draws its own climate and sowing date

    def __post_init__(self) -> None:
        if self.kind not in WEATHER_KINDS:
            raise ValueError(f"weather.kind: {self.kind!r} is not one of {', '.join(WEATHER_KINDS)}")
        if self.kind == "generator":
            if self.generator not in GENERATOR_PARAMETERS:
                raise ValueError(f"weather.generator: {self.generator!r} is not one of "
                                 f"{', '.join(GENERATOR_PARAMETERS)}")
            for delta in ("warming_degc", "drying_degc", "diurnal_range_degc"):
                object.__setattr__(self, delta, _check_number(f"weather.{delta}", getattr(self, delta),
                                                              -MAX_DELTA_DEGC, MAX_DELTA_DEGC))
            for factor, low, high in (("rain_factor", MIN_RAIN_FACTOR, MAX_RAIN_FACTOR),
                                      ("radiation_factor", MIN_RADIATION_FACTOR, MAX_RADIATION_FACTOR)):
                object.__setattr__(self, factor, _check_number(f"weather.{factor}", getattr(self, factor), low, high))
            if self.drying_degc:  # refused here, by name, for a generator fitted without humidity data
                climate_parameters(self.generated_climate)
            if self.spread is not None:
                if not isinstance(self.spread, ClimateSpread):
                    raise ValueError(f"weather.spread: expected a ClimateSpread, got {self.spread!r}")
                if self._delta_changed:
                    raise ValueError("weather.spread: each season draws its warming, drying and rain factor from the "
                                     "spread's ranges; give those, not weather.warming_degc, drying_degc, "
                                     "diurnal_range_degc, rain_factor or radiation_factor")
                if self.spread.drying_degc != (0.0, 0.0):  # refused by name, as above
                    climate_parameters(climate_name(self.generator, drying_degc=max(self.spread.drying_degc, key=abs)))
            _check_count("weather.n_seasons", self.n_seasons, MAX_GENERATED_SEASONS)
            if int(self.seed) != self.seed or self.seed < 0:
                raise ValueError(f"weather.seed: {self.seed!r} is not a non-negative integer")
        elif self.kind == "mixture":
            if not self.mixture or not all(isinstance(n, str) and n for n in self.mixture):
                raise ValueError(f"weather.mixture: a mixture needs a list of built-in scenario names, got "
                                 f"{self.mixture!r}")
        elif not self.seasons or (self.kind == "file" and len(self.seasons) != 1):
            raise ValueError(f"weather.seasons: a {self.kind!r} source needs "
                             f"{'one season' if self.kind == 'file' else 'at least one season'}")
        if self.climate and self.kind not in ("file", "seasons"):
            raise ValueError(f"weather.climate: {self.climate!r} names the site of real seasons; a {self.kind!r} "
                             "source's climate is its generator's")
        if self.climate and self.climate not in GENERATOR_PARAMETERS:
            raise ValueError(f"weather.climate: {self.climate!r} is not one of {', '.join(GENERATOR_PARAMETERS)}")
        if self.kind != "generator" and (self._delta_changed or self.spread is not None):
            raise ValueError("weather.warming_degc, drying_degc, diurnal_range_degc, rain_factor, radiation_factor, "
                             "spread: only a 'generator' source can be warmed, dried, its diurnal range widened, its "
                             f"rain scaled, brightened or spread, not {self.kind!r}")

    @property
    def _delta_changed(self) -> bool:
        """Whether any delta-change (warming, drying, diurnal range, rain or radiation factor) is asked."""
        return ((self.warming_degc, self.drying_degc, self.diurnal_range_degc, self.rain_factor, self.radiation_factor)
                != (0.0, 0.0, 0.0, 1.0, 1.0))

    @property
    def generated_climate(self) -> str:
        """A generator source's climate: its generator, warmed, its diurnal range widened, dried, its radiation
        and rain scaled as it says (``benton+4C+4DTR+8DPDx1.25Sx0.3R``), the name its seasons' source carries.
        ValueError for a spread source, whose every season has its own (its source names it)."""
        if self.spread is not None:
            raise ValueError(f"generator {self.generator!r} with a spread: each season draws its own climate (its "
                             "source names it); the source has no one climate")
        return climate_name(self.generator, self.warming_degc, self.drying_degc, self.rain_factor,
                            self.radiation_factor, self.diurnal_range_degc)


@dataclass(frozen=True)
class Scenario:
    """One irrigation task setting. Units: CO2 ppm; irrigation mm per day; cost per mm of irrigation (a
    negative reward); dates are calendar dates; ``site`` overrides the weather source's site for ET0.

    ``observe_measured_tavg``: the observation's TAVG is the source's measured daily mean instead of
    (TMAX + TMIN) / 2 (the model itself always uses (TMAX + TMIN) / 2).
    """

    name: str
    weather: WeatherSource
    sowing_date: date | None = None
    crop: str = "potato"
    cultivar: str = "Russet Burbank"
    soil: str = "Benton USA potato"
    parameter_source: str = "zhao2019"
    site: Site | None = None
    co2_ppm: float = 369.0
    max_season_days: int = 200
    noise: ObservationNoise = ObservationNoise()
    irrigation_cost_per_mm: float = -1.25e-4
    max_irrigation_mm: float = 100.0
    et0_method: str = "penman_monteith"
    observe_measured_tavg: bool = False
    economics: Economics | None = None
    limits: FarmLimits = FarmLimits()
    description: str = ""
    data_dir: Path | None = None

    def __post_init__(self) -> None:
        if not self.name or not isinstance(self.name, str):
            raise ValueError(f"name: expected a non-empty string, got {self.name!r}")
        if not isinstance(self.weather, WeatherSource):
            raise ValueError(f"weather: expected a WeatherSource, got {self.weather!r}")
        if self.weather.kind == "generator" and not isinstance(self.sowing_date, date):
            raise ValueError(f"sowing_date: a generator scenario needs a date, got {self.sowing_date!r}")
        for name in ("co2_ppm", "irrigation_cost_per_mm", "max_irrigation_mm"):
            low, high = BOUNDS[name]
            _check_number(name, getattr(self, name), -np.inf if low is None else low, np.inf if high is None else high)
        _check_count("max_season_days", self.max_season_days, MAX_SEASON_DAYS)
        if self.weather.kind == "generator" and self.weather.n_seasons * self.max_season_days > MAX_GENERATED_DAYS:
            raise ValueError(f"weather.n_seasons x max_season_days: {self.weather.n_seasons} x "
                             f"{self.max_season_days} days is over {MAX_GENERATED_DAYS:,} generated days")
        if self.et0_method not in ET0_METHODS:
            raise ValueError(f"et0_method: {self.et0_method!r} is not one of {', '.join(ET0_METHODS)}")
        if not isinstance(self.noise, ObservationNoise):
            raise ValueError(f"noise: expected ObservationNoise, got {self.noise!r}")
        if self.site is not None and not isinstance(self.site, Site):
            raise ValueError(f"site: expected a Site, got {self.site!r}")
        if self.economics is not None and not isinstance(self.economics, Economics):
            raise ValueError(f"economics: expected Economics, got {self.economics!r}")
        if not isinstance(self.limits, FarmLimits):
            raise ValueError(f"limits: expected FarmLimits, got {self.limits!r}")
        if self.economics is None and self.limits != FarmLimits():
            raise ValueError("limits: a task with a quota, a capacity or imperfect sensing is a family task, "
                             "whose reward is in USD/ha: give it economics too (economics: {} takes the defaults)")

    @property
    def is_family_task(self) -> bool:
        """A task of the family (money, quota, capacity or imperfect sensing): extended observation, reward in
        USD/ha. The paper's task has none of these terms."""
        return self.economics is not None or self.limits != FarmLimits()

    @property
    def layout(self) -> ObservationLayout:
        """The observation layout: the paper's 20 values, or the family's 29."""
        return EXTENDED if self.is_family_task else PAPER

    @property
    def reward_unit(self) -> str:
        return "USD/ha" if self.economics is not None else "t/ha"

    @property
    def resolved_data_dir(self) -> Path:
        return default_data_dir() if self.data_dir is None else Path(self.data_dir)

    def field_parameters(self, water_stress: bool = True) -> FieldParameters:
        """The model parameters of one field (UnknownNameError for an unknown crop, cultivar or soil)."""
        inputs_dir = self.resolved_data_dir / "simple_r_inputs" if self.parameter_source == "simple_r" else None
        library = crop_library(self.parameter_source, inputs_dir)
        return field_parameters(library.species(self.crop), library.cultivar(self.crop, self.cultivar),
                                library.soil(self.soil), Management(co2_ppm=self.co2_ppm, water_stress=water_stress))

    @property
    def n_seasons(self) -> int:
        """How many distinct seasons ``reset`` draws from."""
        if self.weather.kind == "mixture":
            return sum(get_scenario(name, self.data_dir).n_seasons for name in self.weather.mixture)
        return self.weather.n_seasons if self.weather.kind == "generator" else len(self.weather.seasons)

    def season_path(self, season: SeasonFile) -> Path:
        """The weather file of ``season``, or FileNotFoundError naming it and the data directory."""
        path = Path(season.path)
        if not path.is_absolute():
            path = self.resolved_data_dir / path
        if not path.is_file():
            raise FileNotFoundError(f"scenario {self.name!r}: weather file {path} not found (data directory "
                                    f"{self.resolved_data_dir}; point elsewhere with data_dir=..., the sim node's "
                                    f"data_dir parameter or the environment variable {DATA_DIR_ENV})")
        return path

    def load_seasons(self) -> list[WeatherSeries]:
        """Every season of the scenario, prepared for the task (see :meth:`prepare`)."""
        if self.weather.kind == "generator" and self.weather.spread is not None:
            raw = generate_spread_seasons(self.weather.generator, self.weather.spread, self.sowing_date,
                                          self.max_season_days, self.weather.n_seasons, self.weather.seed)
            return [self.prepare(series) for series in raw]
        if self.weather.kind == "generator":
            raw = generate_seasons(climate_parameters(self.weather.generated_climate), self.sowing_date,
                                   self.max_season_days, self.weather.n_seasons, self.weather.seed)
            return [self.prepare(series) for series in raw]
        if self.weather.kind == "mixture":
            # each part's seasons as that scenario prepares them (its own sowing date, site, season length)
            return [series for name in self.weather.mixture
                    for series in get_scenario(name, self.data_dir).load_seasons()]
        return [self.prepare(_read_weather(str(self.season_path(s)), s.format), s.sowing_date)
                for s in self.weather.seasons]

    def prepare(self, series: WeatherSeries, sowing_date: date | None = None) -> WeatherSeries:
        """``series`` made ready for the task: the scenario's site (if it overrides one), the days from
        ``sowing_date`` (default: the series' first day) for at most ``max_season_days`` days, missing
        vapour pressure and wind filled by FAO-56's rules, and every needed value checked."""
        if self.site is not None:
            series = replace(series, site=self.site)
        series = series.window(series.start if sowing_date is None else sowing_date)
        if len(series) > self.max_season_days:
            series = series.window(series.start, self.max_season_days)
        needed = TASK_WEATHER_VARIABLES + (("tavg_degc",) if self.observe_measured_tavg else ())
        return series.with_fao56_fills().require(needed)


def find_data_dir(environment_value: str | None, cwd: Path | None, package_dir: Path) -> Path | None:
    """The reference data directory when no ``data_dir`` is given, or None if none is found:

    1. ``environment_value`` (the variable ``CROP_SIM_DATA_DIR``), if set and not empty;
    2. the checkout's ``../shared/data`` seen from ``cwd``: the first ``<ancestor>/shared/data`` directory walking
       up from ``cwd`` (a source checkout, or a colcon workspace inside the tree that holds ``shared/``);
    3. the same walking up from ``package_dir`` (a source checkout, an editable or a venv install inside it).

    Steps 1 and 2 are what finds the data from an install outside the checkout (a colcon build puts the package
    in ``install/crop_sim_ros/lib/python3.11/site-packages``, far from ``shared/``). ``cwd`` None: skipped."""
    if environment_value:
        return Path(environment_value).expanduser()
    for start in (cwd, package_dir) if cwd is not None else (package_dir,):
        for ancestor in (start, *start.parents):
            candidate = ancestor / "shared" / "data"
            if candidate.is_dir():
                return candidate
    return None


def installed_data_dir() -> Path | None:
    """``share/crop_sim_ros/data`` of a package installed where the ament index finds it (``colcon build``,
    ``AMENT_PREFIX_PATH``), if that directory exists; else None. The first place :func:`default_data_dir`
    looks."""
    try:
        from ament_index_python.packages import get_package_share_directory  # noqa: PLC0415

        with warnings.catch_warnings():  # it warns when the share directory does not exist: checked below
            warnings.simplefilter("ignore")
            share = Path(get_package_share_directory("crop_sim_ros")) / INSTALLED_DATA_SUBDIR
    except Exception:  # noqa: BLE001 - no AMENT_PREFIX_PATH, or the package is not in the index
        return None
    return share if share.is_dir() else None


def default_data_dir() -> Path:
    """Where scenario weather files are found when no ``data_dir`` is given: :func:`installed_data_dir`, else
    :func:`find_data_dir` from the environment, the current directory and this package's location. If nothing is
    found: ``../shared/data`` beside the package's parent directory, which the error of a missing weather file
    names."""
    installed = installed_data_dir()
    if installed is not None:
        return installed
    try:
        cwd = Path.cwd()
    except OSError:  # the current directory was removed
        cwd = None
    found = find_data_dir(os.environ.get(DATA_DIR_ENV), cwd, PACKAGE_DIR)
    return found if found is not None else PACKAGE_DIR.parent.parent / "shared" / "data"


@functools.lru_cache(maxsize=32)
def _read_weather(path: str, fmt: str) -> WeatherSeries:
    if fmt == "agweathernet":
        return read_agweathernet_csv(path)
    if fmt == "dssat":
        return read_dssat_wth(path)
    return read_plain_csv(path)


# --- YAML ---------------------------------------------------------------------------------------------

# What a scenario file may hold besides the schema's fields, and what it may not set.
SCHEMA_RULES = Rules(
    bounds=BOUNDS,
    choices={"weather.kind": WEATHER_KINDS, "weather.format": WEATHER_FORMATS,
             "weather.seasons.format": WEATHER_FORMATS, "weather.generator": GENERATOR_PARAMETERS,
             "weather.climate": GENERATOR_PARAMETERS, "et0_method": ET0_METHODS},
    extra={"weather": {"path": str, "format": str}},  # a 'file' source's one season
    exclude=frozenset({"data_dir"}))
# The top-level keys of a scenario file: Scenario's fields and ``base``.
SCENARIO_FILE_KEYS = frozenset(f.name for f in fields(Scenario) if f.name != "data_dir") | {"base"}


def scenario_from_dict(values: dict, data_dir: str | Path | None = None) -> Scenario:
    """A Scenario from a YAML mapping. ValueError: first every problem the schema finds, each with its path
    (``limits.quota_mm: ...``: types, ranges, required and unknown fields), then the first problem
    across fields (a 'file' source without a sowing date, ...)."""
    values = validated(Scenario, SCHEMA_RULES, values)
    weather = values.pop("weather")
    sowing = values.get("sowing_date")
    kind = weather["kind"]
    if kind == "file":
        if sowing is None:
            raise ValueError("sowing_date: a 'file' weather source needs the scenario's sowing date")
        for key in ("path", "format"):
            if key not in weather:
                raise ValueError(f"weather.{key}: missing (a 'file' source names its file and its format)")
        weather["seasons"] = [{"path": weather.pop("path"), "format": weather.pop("format"), "sowing_date": sowing}]
    extra = sorted({"path", "format"} & set(weather))
    if extra:
        raise ValueError(f"weather.{extra[0]}: not a field of a {kind!r} source")
    seasons = tuple(SeasonFile(**entry) for entry in weather.pop("seasons", None) or ())
    if weather.get("spread") is not None:
        try:
            weather["spread"] = ClimateSpread.from_dict(weather["spread"])
        except WeatherError as error:  # it names the spread's field: say where the spread is
            raise ValueError(f"weather.{error}") from None
    if "mixture" in weather:
        weather["mixture"] = tuple(weather["mixture"])
    source = WeatherSource(seasons=seasons, **weather)
    if "noise" in values:
        values["noise"] = ObservationNoise(**values["noise"])
    if values.get("site") is not None:
        try:
            values["site"] = Site(**values["site"])
        except WeatherError as error:
            raise ValueError(f"site: {error}") from None
    if values.get("economics") is not None:
        values["economics"] = Economics.from_dict(values["economics"])
    if "limits" in values:
        values["limits"] = FarmLimits.from_dict(values["limits"])
    return Scenario(weather=source, data_dir=None if data_dir is None else Path(data_dir), **values)


# Mappings a derived scenario merges with its base's, field by field (the rest it replaces whole).
_MERGED_MAPPINGS = ("noise", "economics", "limits")


def _base_path(base: Any, derived: Path) -> Path:
    """The file of ``base:`` in the scenario file ``derived``: a built-in scenario's, or a path beside it."""
    if not isinstance(base, str) or not base or len(base) > 1000:
        raise ValueError(f"base: {shown(base)} is not the name of a built-in scenario or a YAML path")
    built_in = SCENARIO_DIR / f"{base}.yaml"
    path = built_in if "/" not in base and built_in.is_file() else derived.parent / base
    if not path.exists():
        raise ValueError(f"base: {shown(base)} is neither a built-in scenario ({', '.join(scenario_names())}) nor a "
                         "file beside it")
    return path


def _scenario_file(path: Path, derived: Path | None) -> dict:
    """The mapping of the scenario file ``path`` (a base of ``derived``, or None); ValueError (naming the file,
    never quoting what it holds) for anything that is not a scenario file."""
    what = str(path) if derived is None else f"base: {path}"
    values = read_yaml(path, source=what)
    if not isinstance(values, dict):
        kind = {str: "text", list: "a list", type(None): "nothing"}.get(type(values), "a single value")
        raise ValueError(f"{what} is not a scenario file: it holds {kind}, not a mapping of scenario fields")
    unknown = [key for key in values if key not in SCENARIO_FILE_KEYS]
    if derived is not None and unknown:  # the file's own unknown fields the schema names; a base's, not
        raise ValueError(f"{what} is not a scenario file: {len(unknown)} of its {len(values)} top-level keys are "
                         "not scenario fields")
    return values


def _yaml_mapping(path: Path) -> dict:
    """The scenario mapping of the YAML file ``path``, with its ``base`` (a built-in scenario name or a YAML
    path relative to this file) resolved: the base's mapping updated by this file's fields (a chain of at most
    MAX_BASE_CHAIN files, without a cycle)."""
    chain, layers = [path], []
    while True:
        values = _scenario_file(chain[-1], chain[-2] if len(chain) > 1 else None)
        layers.append(values)
        if values.get("base") is None:
            values.pop("base", None)
            break
        base = _base_path(values.pop("base"), chain[-1])
        if os.path.abspath(base) in {os.path.abspath(p) for p in chain}:
            raise ValueError(f"base: {' -> '.join(str(p) for p in (*chain, base))} is a cycle")
        if len(chain) >= MAX_BASE_CHAIN:
            raise ValueError(f"base: a chain of more than {MAX_BASE_CHAIN} scenario files")
        chain.append(base)
    merged = layers.pop()
    for values in reversed(layers):
        merged.pop("description", None)
        for key, value in values.items():
            if key in _MERGED_MAPPINGS and isinstance(value, dict) and isinstance(merged.get(key), dict):
                merged[key] = {**merged[key], **value}
            else:
                merged[key] = value
    return merged


def load_scenario(path: str | Path, data_dir: str | Path | None = None) -> Scenario:
    """Read a scenario YAML file (``base: NAME`` derives it from another scenario: see the module docstring);
    ValueError names the file and every field at fault (never the file's text)."""
    path = Path(path)
    try:
        return scenario_from_dict(_yaml_mapping(path), data_dir)
    except ValueError as error:  # YamlInputError too: a read, syntax or size refusal
        text = str(error)
        raise ValueError(text if text.startswith((f"{path}:", f"{path} ")) else f"{path}: {text}") from None


def with_weather_of(task: Scenario, weather: Scenario) -> Scenario:
    """``task``'s crop, terms and noise on ``weather``'s seasons (source, sowing date, site, season length):
    how a family task is evaluated on held-out real seasons or another climate."""
    return replace(task, name=f"{task.name}@{weather.name}", weather=weather.weather, sowing_date=weather.sowing_date,
                   site=weather.site, max_season_days=weather.max_season_days, data_dir=weather.data_dir,
                   description=f"{task.description}; weather of {weather.name}")


def generated_parts(task: Scenario) -> list[Scenario]:
    """The generated-weather scenarios ``task`` draws its seasons from: itself, or each part of its mixture
    (in pool order); ValueError for a task on other weather."""
    if task.weather.kind == "generator":
        return [task]
    if task.weather.kind == "mixture":
        return [get_scenario(name, task.data_dir) for name in task.weather.mixture]
    raise ValueError(f"{task.name!r} does not train on generated weather (its weather is {task.weather.kind!r})")


def climates(task: Scenario) -> dict[str, Scenario]:
    """Name -> part of each generated part of ``task`` (:func:`generated_parts`, in pool order): the part's weather
    generator, or, where two parts share a generator (the same site sown on other dates), the part's scenario
    name without ``-generated`` (``benton-early``). The names of the MPC's continuation pools and of the
    evaluation's far sets."""
    parts = generated_parts(task)
    generators = [part.weather.generator for part in parts]
    return {(generator if generators.count(generator) == 1 else part.name.removesuffix("-generated")): part
            for generator, part in zip(generators, parts)}


def reseeded(source: Scenario, seed: int, n_seasons: int) -> Scenario:
    """``source``'s weather generator with another seed and pool size (seasons no training or validation pool
    holds): far evaluation seeds, and the MPC's weather continuations."""
    return replace(source, name=f"{source.weather.generator}-generated-seed{seed}",
                   weather=replace(source.weather, seed=seed, n_seasons=n_seasons))


def scenario_names() -> list[str]:
    """The names of the built-in scenarios."""
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.yaml"))


@functools.lru_cache(maxsize=None)  # a mixture's parts are other tasks' too
def longest_season_days(name: str) -> int:
    """The longest season of the built-in scenario ``name`` in days: its ``max_season_days`` (a mixture: the
    longest of its own and its parts', each part's seasons being as long as that part makes them), read from its
    YAML file alone (no weather is loaded or generated: what the Gymnasium registration's ``max_episode_steps``
    needs at import). UnknownNameError for an unknown name."""
    path = SCENARIO_DIR / f"{name}.yaml"
    if not path.is_file():
        raise UnknownNameError(f"unknown scenario {name!r}; known: {', '.join(scenario_names())}")
    values = _yaml_mapping(path)
    own = int(values.get("max_season_days", Scenario.max_season_days))
    weather = values.get("weather") or {}
    if weather.get("kind") == "mixture":
        return max([own, *(longest_season_days(part) for part in weather["mixture"])])
    return own


def get_scenario(name: str, data_dir: str | Path | None = None) -> Scenario:
    """A built-in scenario by name. Its weather files (if any) are looked up in ``data_dir`` (default
    ``../shared/data`` next to the repository): FileNotFoundError names a missing one; the crop, cultivar
    and soil are checked (UnknownNameError)."""
    path = SCENARIO_DIR / f"{name}.yaml"
    if not path.is_file():
        raise UnknownNameError(f"unknown scenario {name!r}; known: {', '.join(scenario_names())}")
    scenario = load_scenario(path, data_dir)
    scenario.field_parameters()
    for season in scenario.weather.seasons:
        scenario.season_path(season)
    return scenario
