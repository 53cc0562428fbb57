"""The observation layouts of the irrigation tasks, defined once and read by name.

Two layouts exist. ``PAPER`` is the seed paper's 20 values (``shared/spec/IRRIGATION_TASK.md``); the task
family (money, water quota, pump capacity, imperfect sensing, other climates) appends nine values to it,
``EXTENDED`` (29 values), so that one policy can read every family task and the paper's first 20 columns
mean the same everywhere. Every consumer (the task core, the environments, the ROS interface, the policies)
imports the layout from here and reads columns by name (``layout.index("paw_mm")``); nothing else spells a
column number. This module imports only numpy.

======= ================================ ========== =======================================================
#       name                             unit       value
======= ================================ ========== =======================================================
0       biomass_t_ha                     t ha-1     above-ground biomass + noise, clipped at 0
1       thermal_time_degc_d              degC d     thermal time since sowing (TT), exact
2       days_since_sowing                d          exact
3-10    tmax_degc .. wind_m_s            (weather)  today's TMAX, TMIN, TAVG degC, RAIN mm, SRAD MJ m-2,
                                                    CO2 ppm, VAP hPa, WIND m s-1, exact
11-18   forecast_tmax_degc ..            (weather)  tomorrow's forecast of the same 8, + noise
19      paw_mm                           mm         plant-available water + noise (0 when not read)
20      tuber_price_usd_per_t            USD t-1    price of fresh tubers this season (extended only)
21      water_cost_usd_per_mm            USD mm-1   delivered water + pumping energy, per mm on one ha
22      event_cost_usd                   USD        fixed cost of each irrigation event (day with water)
23      quota_remaining_mm               mm         the season's water allocation left (QUOTA_OBSERVED_CAP_MM
                                                    = no binding quota: at least that much left)
24      season_days_left                 d          days left of the nominal season (the scenario's
                                                    ``nominal_season_days`` - days since sowing, >= 0)
25      capacity_mm_per_day              mm d-1     most the irrigation system can apply in one day
26      paw_observed                     1 or 0     1 if column 19 is today's sensor reading, 0 if the
                                                    reading is missing (dropout, or no sensor)
27      irrigation_yesterday_mm          mm         irrigation actually applied yesterday (after the
                                                    capacity and quota limits), 0 on the sowing day
28      et0_mm                           mm         today's reference evapotranspiration (FAO-56 at the
                                                    site, as weather networks such as AgWeatherNet publish
                                                    it daily), exact
======= ================================ ========== =======================================================
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

WEATHER_NAMES = ("tmax_degc", "tmin_degc", "tavg_degc", "rain_mm", "srad_mj_m2", "co2_ppm", "vap_hpa", "wind_m_s")
WEATHER_UNITS = ("degC", "degC", "degC", "mm", "MJ/m2", "ppm", "hPa", "m/s")
# Lower physical bound of each weather value (a noisy forecast below it is clipped to it).
WEATHER_LOW = (-np.inf, -np.inf, -np.inf, 0.0, 0.0, 0.0, 0.0, 0.0)
# The quota column shows at most this (mm): a potato season needs 400-800 mm, so more is "no binding quota".
QUOTA_OBSERVED_CAP_MM = 1000.0


@dataclass(frozen=True)
class Column:
    name: str
    unit: str
    low: float


@dataclass(frozen=True)
class ObservationLayout:
    """An ordered set of named observation columns with units and lower bounds (upper bounds are +inf)."""

    columns: tuple[Column, ...]

    @functools.cached_property
    def names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.columns)

    @functools.cached_property
    def units(self) -> tuple[str, ...]:
        return tuple(c.unit for c in self.columns)

    @functools.cached_property
    def labels(self) -> tuple[str, ...]:
        """``name[unit]`` of every column (the ROS array labels)."""
        return tuple(f"{c.name}[{c.unit}]" for c in self.columns)

    @functools.cached_property
    def size(self) -> int:
        return len(self.columns)

    @functools.cached_property
    def low(self) -> np.ndarray:
        low = np.array([c.low for c in self.columns], dtype=np.float32)
        low.setflags(write=False)  # shared by every caller
        return low

    @functools.cached_property
    def high(self) -> np.ndarray:
        high = np.full(self.size, np.inf, dtype=np.float32)
        high.setflags(write=False)
        return high

    def index(self, name: str) -> int:
        """The column of ``name``; KeyError lists the names that exist."""
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no observation column {name!r}; columns: {', '.join(self.names)}") from None

    def __len__(self) -> int:
        return self.size


_PAPER_COLUMNS = (
    (Column("biomass_t_ha", "t/ha", 0.0), Column("thermal_time_degc_d", "degC d", -np.inf),
     Column("days_since_sowing", "d", 0.0))
    + tuple(Column(n, u, lo) for n, u, lo in zip(WEATHER_NAMES, WEATHER_UNITS, WEATHER_LOW))
    + tuple(Column(f"forecast_{n}", u, lo) for n, u, lo in zip(WEATHER_NAMES, WEATHER_UNITS, WEATHER_LOW))
    + (Column("paw_mm", "mm", 0.0),))
EXTENSION_COLUMNS = (
    Column("tuber_price_usd_per_t", "USD/t", 0.0), Column("water_cost_usd_per_mm", "USD/mm", 0.0),
    Column("event_cost_usd", "USD", 0.0), Column("quota_remaining_mm", "mm", 0.0),
    Column("season_days_left", "d", 0.0), Column("capacity_mm_per_day", "mm/d", 0.0),
    Column("paw_observed", "1", 0.0), Column("irrigation_yesterday_mm", "mm", 0.0), Column("et0_mm", "mm", 0.0))

PAPER = ObservationLayout(_PAPER_COLUMNS)
EXTENDED = ObservationLayout(_PAPER_COLUMNS + EXTENSION_COLUMNS)
LAYOUTS = {"paper": PAPER, "extended": EXTENDED}

# Column positions shared by both layouts (the extended layout starts with the paper's 20 values).
BIOMASS = PAPER.index("biomass_t_ha")
THERMAL_TIME = PAPER.index("thermal_time_degc_d")
DAY = PAPER.index("days_since_sowing")
TODAY = slice(PAPER.index("tmax_degc"), PAPER.index("wind_m_s") + 1)
FORECAST = slice(PAPER.index("forecast_tmax_degc"), PAPER.index("forecast_wind_m_s") + 1)
TODAY_RAIN = PAPER.index("rain_mm")
FORECAST_RAIN = PAPER.index("forecast_rain_mm")
PAW = PAPER.index("paw_mm")
EXTENSION = slice(PAPER.size, EXTENDED.size)
PAW_OBSERVED = EXTENDED.index("paw_observed")


def layout_of_size(size: int) -> ObservationLayout:
    """The layout with ``size`` columns; ValueError names the sizes that exist."""
    for layout in LAYOUTS.values():
        if layout.size == size:
            return layout
    raise ValueError(f"no observation layout has {size} values; layouts: "
                     + ", ".join(f"{name} ({layout.size})" for name, layout in LAYOUTS.items()))
