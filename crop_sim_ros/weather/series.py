"""A season of daily weather as one array type, with the checks every reader and generator shares.

================ ========== ===================================================================
Variable         Unit       Description
================ ========== ===================================================================
dates            date       consecutive calendar days (numpy datetime64[D])
tmax_degc        degC       daily maximum air temperature
tmin_degc        degC       daily minimum air temperature
tavg_degc        degC       measured daily mean air temperature (NaN if the source has none);
                            the model uses (TMAX + TMIN) / 2 unless told otherwise
srad_mj_m2       MJ m-2     daily global solar radiation
rain_mm          mm         daily precipitation
vap_hpa          hPa        actual vapour pressure (NaN if the source has none)
wind_m_s         m s-1      mean wind speed at 2 m (NaN if the source has none)
================ ========== ===================================================================

Missing values are NaN. ``line_numbers`` keeps the source line of each day so that a problem found
after windowing still names the file, line and column.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from datetime import date

import numpy as np

from ..model.et0 import penman_monteith, priestley_taylor, saturation_vapour_pressure_hpa

VARIABLES = ("tmax_degc", "tmin_degc", "tavg_degc", "srad_mj_m2", "rain_mm", "vap_hpa", "wind_m_s")
# What the crop model itself needs every day.
MODEL_VARIABLES = ("tmax_degc", "tmin_degc", "srad_mj_m2", "rain_mm")
# FAO-56 (section "missing data"): wind 2 m/s where no wind was measured.
FAO56_DEFAULT_WIND_M_S = 2.0


class WeatherError(ValueError):
    """Bad weather input; the message names the source (file), line, column and value."""


@dataclass(frozen=True)
class Site:
    """Where the weather was observed: latitude and longitude in degrees (north, east), elevation in m."""

    name: str
    latitude_deg: float
    longitude_deg: float
    elevation_m: float

    def __post_init__(self) -> None:
        if not -90 <= self.latitude_deg <= 90:
            raise WeatherError(f"site {self.name}: latitude {self.latitude_deg} deg is outside [-90, 90]")


@dataclass(frozen=True)
class WeatherSeries:
    """Daily weather of one site over consecutive days (see the module table for units)."""

    site: Site
    dates: np.ndarray
    tmax_degc: np.ndarray
    tmin_degc: np.ndarray
    tavg_degc: np.ndarray
    srad_mj_m2: np.ndarray
    rain_mm: np.ndarray
    vap_hpa: np.ndarray
    wind_m_s: np.ndarray
    source: str = "memory"
    line_numbers: np.ndarray | None = None
    filled: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        n = len(self.dates)
        for name in VARIABLES:
            if np.shape(getattr(self, name)) != (n,):
                raise WeatherError(f"{self.source}: {name} has shape {np.shape(getattr(self, name))}, "
                                   f"expected ({n},) like dates")
        if n > 1:
            gaps = np.flatnonzero(np.diff(self.dates).astype(int) != 1)
            if gaps.size:
                i = gaps[0] + 1
                raise WeatherError(f"{self._where(i)}: dates are not consecutive: {self.dates[i - 1]} is "
                                   f"followed by {self.dates[i]}")

    def __len__(self) -> int:
        return len(self.dates)

    @property
    def start(self) -> date:
        return self.dates[0].astype(date)

    @property
    def end(self) -> date:
        return self.dates[-1].astype(date)

    @property
    def day_of_year(self) -> np.ndarray:
        years = self.dates.astype("datetime64[Y]")
        return (self.dates - years.astype("datetime64[D]")).astype(int) + 1

    def _where(self, index: int, column: str | None = None) -> str:
        where = self.source
        if self.line_numbers is not None and self.line_numbers[index] > 0:
            where += f", line {int(self.line_numbers[index])}"
        else:
            where += f", {self.dates[index]}"
        if column:
            where += f", column {column}"
        return where

    def _check_physical(self) -> None:
        with np.errstate(invalid="ignore"):
            checks = [
                ("tmin_degc", self.tmin_degc > self.tmax_degc, "TMIN exceeds TMAX"),
                ("rain_mm", self.rain_mm < 0, "negative rain"),
                ("srad_mj_m2", self.srad_mj_m2 < 0, "negative radiation"),
                ("srad_mj_m2", self.srad_mj_m2 > 50, "radiation above 50 MJ m-2 d-1"),
                ("tmax_degc", np.abs(self.tmax_degc) > 70, "temperature beyond +-70 degC"),
                ("tmin_degc", np.abs(self.tmin_degc) > 70, "temperature beyond +-70 degC"),
                ("vap_hpa", self.vap_hpa < 0, "negative vapour pressure"),
                ("wind_m_s", self.wind_m_s < 0, "negative wind speed"),
            ]
        for column, bad, what in checks:
            hits = np.flatnonzero(bad)
            if hits.size:
                i = hits[0]
                raise WeatherError(f"{self._where(i, column)}: {what} "
                                   f"(TMAX {self.tmax_degc[i]}, TMIN {self.tmin_degc[i]}, "
                                   f"{column} {getattr(self, column)[i]})")

    def require(self, variables=MODEL_VARIABLES) -> "WeatherSeries":
        """Self, or WeatherError naming the first missing (NaN) value among ``variables`` or the first
        impossible value (TMIN > TMAX, negative rain, radiation, wind or vapour pressure, ...).

        Files often carry bad days outside the season one simulates, so this runs on the window used.
        """
        self._check_physical()
        for name in variables:
            missing = np.flatnonzero(~np.isfinite(getattr(self, name)))
            if missing.size:
                raise WeatherError(f"{self._where(missing[0], name)}: missing value on {self.dates[missing[0]]} "
                                   f"({missing.size} missing in {self.start}..{self.end})")
        return self

    def window(self, start: date | str | np.datetime64, days: int | None = None) -> "WeatherSeries":
        """The days from ``start`` on (``days`` of them, or to the end of the series)."""
        first = int((np.datetime64(start, "D") - self.dates[0]).astype(int))
        if not 0 <= first < len(self):
            raise WeatherError(f"{self.source}: {start} is outside the series {self.start}..{self.end}")
        last = len(self) if days is None else first + days
        if last > len(self):
            raise WeatherError(f"{self.source}: {days} days from {start} run past the series end {self.end}")
        return self._slice(slice(first, last))

    def _slice(self, index) -> "WeatherSeries":
        arrays = {name: getattr(self, name)[index] for name in VARIABLES}
        lines = None if self.line_numbers is None else self.line_numbers[index]
        return replace(self, dates=self.dates[index], line_numbers=lines, **arrays)

    def with_fao56_fills(self) -> "WeatherSeries":
        """Missing vapour pressure and wind filled by FAO-56's rules for missing data.

        Vapour pressure: e_a = e0(TMIN) (dew point taken as TMIN, FAO-56 eq. 48); wind: 2 m s-1.
        What was filled is listed in ``filled``.
        """
        vap, wind, filled = self.vap_hpa, self.wind_m_s, list(self.filled)
        missing_vap = ~np.isfinite(vap)
        if missing_vap.any():
            vap = np.where(missing_vap, saturation_vapour_pressure_hpa(self.tmin_degc), vap)
            filled.append(f"vap_hpa from TMIN (FAO-56 eq. 48) on {int(missing_vap.sum())} days")
        missing_wind = ~np.isfinite(wind)
        if missing_wind.any():
            wind = np.where(missing_wind, FAO56_DEFAULT_WIND_M_S, wind)
            filled.append(f"wind_m_s = {FAO56_DEFAULT_WIND_M_S} m/s (FAO-56) on {int(missing_wind.sum())} days")
        return replace(self, vap_hpa=vap, wind_m_s=wind, filled=tuple(filled))

    def et0_mm(self, method: str) -> np.ndarray:
        """Reference ET, mm d-1, by ``priestley_taylor`` or ``penman_monteith`` (which fills by FAO-56)."""
        if method == "priestley_taylor":
            self.require(("tmax_degc", "tmin_degc", "srad_mj_m2"))
            return priestley_taylor(self.tmax_degc, self.tmin_degc, self.srad_mj_m2)
        if method == "penman_monteith":
            filled = self.with_fao56_fills().require(("tmax_degc", "tmin_degc", "srad_mj_m2"))
            return penman_monteith(filled.tmax_degc, filled.tmin_degc, filled.srad_mj_m2, filled.vap_hpa,
                                   filled.wind_m_s, self.day_of_year, self.site.latitude_deg,
                                   self.site.elevation_m)
        raise ValueError(f"unknown ET0 method {method!r}; known: priestley_taylor, penman_monteith")


def make_series(site: Site, dates, source: str = "memory", line_numbers=None, **columns) -> WeatherSeries:
    """A WeatherSeries from columns (any missing variable is all-NaN); dates as datetime64 or ISO strings."""
    dates = np.asarray(dates, dtype="datetime64[D]")
    n = len(dates)
    arrays = {}
    for name in VARIABLES:
        value = columns.pop(name, None)
        arrays[name] = np.full(n, np.nan) if value is None else np.asarray(value, dtype=float)
    if columns:
        raise WeatherError(f"{source}: unknown weather variables {sorted(columns)}; known: {VARIABLES}")
    lines = None if line_numbers is None else np.asarray(line_numbers, dtype=np.int64)
    return WeatherSeries(site=site, dates=dates, source=source, line_numbers=lines, **arrays)
