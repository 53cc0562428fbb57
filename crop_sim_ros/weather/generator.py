"""A seeded stochastic daily weather generator of Richardson / WGEN type, vectorised over N seasons.

Per calendar month (parameters are monthly steps):

- rain occurrence: a first-order Markov chain, P(wet | yesterday dry) and P(wet | yesterday wet); a day is
  wet when its rain is at least ``wet_day_threshold_mm``;
- rain amount on a wet day: the threshold plus a gamma-distributed excess (shape, scale in mm);
- TMAX, TMIN, SRAD: normal with means and standard deviations that depend on whether the day is wet;
  the monthly means become a smooth daily curve (:func:`smooth_daily`, which keeps each month's mean) so
  that the weather does not jump at the first of a month;
  their standardized residuals follow the multivariate lag-1 autoregression of Richardson (1981),
  z_t = A z_(t-1) + B e_t, with A and B from the lag-0 and lag-1 correlation matrices;
  TMIN <= TMAX is enforced (the two are swapped on the rare day they cross) and SRAD is clipped to
  [``MIN_SRAD_MJ_M2``, FAO-56 clear-sky radiation Rso = (0.75 + 2e-5 z) Ra] of the site and day;
- vapour pressure: e0(dew point), dew point = TMIN - a normal dew point depression (monthly mean and
  standard deviation), capped at the day's mean temperature (TMAX + TMIN) / 2;
- wind at 2 m: gamma distributed (monthly shape, scale in m s-1).

A site whose data had no humidity (or no wind) has no such parameters (``None``, ``null`` in the JSON): its
generated seasons get vapour pressure (or wind) the way the task fills a real season without them, by
FAO-56's missing-data rules (``WeatherSeries.with_fao56_fills``: e_a = e0(TMIN), wind 2 m/s), and the
series' ``filled`` says so.

Parameter sets are JSON files ``<name>_generator.json`` beside this module, one per climate, each fitted by
``crop-sim fit-weather`` (its metadata names the data); :func:`generator_parameters` reads one by name.

No separate daily mean temperature is drawn: ``tavg_degc`` is NaN, and users take (TMAX + TMIN) / 2.

Internally every variable is a numpy array of shape (days, N); a season is one column. Imports neither
rclpy, gymnasium nor torch.
"""

from __future__ import annotations

import functools
import json
import re
from dataclasses import asdict, dataclass, field, fields, replace
from datetime import date, timedelta
from pathlib import Path

import numpy as np
from refet.calcs import ra_daily, rso_simple

from ..output import write_text_atomic
from .series import Site, WeatherError, WeatherSeries, make_series, saturation_vapour_pressure_hpa

MONTHS = 12
# Order of the autocorrelated variables in the residual correlation matrices.
RESIDUAL_VARIABLES = ("tmax", "tmin", "srad")
RESIDUAL_UNITS = {"tmax": "degc", "tmin": "degc", "srad": "mj_m2"}
# SRAD never falls below this (MJ m-2 d-1): even a dark overcast day has some light.
MIN_SRAD_MJ_M2 = 0.1
PARAMETERS_SUFFIX = "_generator.json"
BENTON_PARAMETERS_FILE = Path(__file__).with_name("benton" + PARAMETERS_SUFFIX)
# Every packaged parameter set by name: the JSON files beside this module.
GENERATOR_NAMES = tuple(sorted(path.name.removesuffix(PARAMETERS_SUFFIX)
                               for path in Path(__file__).parent.glob("*" + PARAMETERS_SUFFIX)))
# Monthly fields a site without humidity (the first pair) or wind (the second pair) data leaves at None.
OPTIONAL_PAIRS = (("dew_point_depression_mean_degc", "dew_point_depression_sd_degc"),
                  ("wind_shape", "wind_scale_m_s"))


def conditional_field_names(variable: str) -> tuple[str, str, str, str]:
    """The (mean dry, mean wet, sd dry, sd wet) field names of ``variable`` (tmax, tmin or srad)."""
    unit = RESIDUAL_UNITS[variable]
    return (f"{variable}_mean_dry_{unit}", f"{variable}_mean_wet_{unit}",
            f"{variable}_sd_dry_{unit}", f"{variable}_sd_wet_{unit}")


def _month_position(dates: np.ndarray) -> np.ndarray:
    """Position of each day in the year in months: 0.5 is mid-January, 11.5 mid-December."""
    months = dates.astype("datetime64[M]")
    month_start = months.astype("datetime64[D]")
    month_length = ((months + 1).astype("datetime64[D]") - month_start).astype(int)
    return months.astype(int) % MONTHS + ((dates - month_start).astype(int) + 0.5) / month_length


# Linear interpolation between mid-month nodes n averages (n[m-1] + 6 n[m] + n[m+1]) / 8 over month m
# (months taken as equally long): this inverse turns monthly means into the nodes that keep them.
_NODES_FROM_MONTHLY_MEANS = np.linalg.inv(
    (6 * np.eye(MONTHS) + np.roll(np.eye(MONTHS), 1, axis=1) + np.roll(np.eye(MONTHS), -1, axis=1)) / 8)


def smooth_daily(monthly_means, dates) -> np.ndarray:
    """Daily values on ``dates`` of a smooth annual curve whose monthly means are ``monthly_means``.

    Piecewise linear between mid-month nodes, cyclic over the year; the monthly means are kept to within
    the effect of unequal month lengths.
    """
    nodes = _NODES_FROM_MONTHLY_MEANS @ np.asarray(monthly_means, dtype=float)
    return np.interp(_month_position(np.asarray(dates, dtype="datetime64[D]")), np.arange(MONTHS) + 0.5,
                     nodes, period=MONTHS)


def dew_point_degc(vap_hpa):
    """Dew point, degC, of the actual vapour pressure ``vap_hpa`` (inverse of FAO-56 eq. 11)."""
    log_ratio = np.log(np.asarray(vap_hpa, dtype=float) / 6.108)
    return 237.3 * log_ratio / (17.27 - log_ratio)


def clear_sky_radiation_mj_m2(day_of_year, latitude_deg: float, elevation_m: float):
    """FAO-56 clear-sky radiation Rso = (0.75 + 2e-5 z) Ra, MJ m-2 d-1 (as the Penman-Monteith ET0 uses)."""
    return rso_simple(ra_daily(np.radians(latitude_deg), np.asarray(day_of_year, dtype=float)), elevation_m)


Monthly = tuple[float, ...]
# Monthly values, or None where the data had none of the variable (see OPTIONAL_PAIRS).
OptionalMonthly = Monthly | None
Matrix3 = tuple[tuple[float, float, float], ...]


@dataclass(frozen=True)
class GeneratorParameters:
    """Parameters of the weather generator for one site. Monthly fields hold 12 values, January first.

    ============================== ======== ===========================================================
    Name                           Unit     Description
    ============================== ======== ===========================================================
    name                           -        short label used in the source of generated series
    site                           -        latitude_deg, longitude_deg (north, east), elevation_m
    wet_day_threshold_mm           mm       a day is wet when rain_mm >= this
    p_wet_after_dry                -        monthly P(wet today | dry yesterday)
    p_wet_after_wet                -        monthly P(wet today | wet yesterday)
    rain_excess_shape              -        monthly gamma shape of (wet-day rain - threshold)
    rain_excess_scale_mm           mm       monthly gamma scale of (wet-day rain - threshold)
    tmax_mean_dry_degc             degC     monthly mean TMAX on dry days
    tmax_mean_wet_degc             degC     monthly mean TMAX on wet days
    tmax_sd_dry_degc               degC     monthly standard deviation of TMAX on dry days
    tmax_sd_wet_degc               degC     monthly standard deviation of TMAX on wet days
    tmin_mean_dry_degc ...         degC     the same four for TMIN
    srad_mean_dry_mj_m2 ...        MJ m-2   the same four for daily global radiation SRAD
    residual_lag0_correlation      -        3 x 3 correlation of standardized (TMAX, TMIN, SRAD)
                                            residuals on the same day
    residual_lag1_correlation      -        3 x 3 correlation, row: today's residual, column:
                                            yesterday's
    dew_point_depression_mean_degc degC     monthly mean of TMIN - dew point (None: no humidity data,
                                            e_a = e0(TMIN) by FAO-56's missing-data rule)
    dew_point_depression_sd_degc   degC     monthly standard deviation of TMIN - dew point (None with
                                            the mean)
    wind_shape                     -        monthly gamma shape of the daily mean wind at 2 m (None: no
                                            wind data, 2 m s-1 by FAO-56's missing-data rule)
    wind_scale_m_s                 m s-1    monthly gamma scale of the daily mean wind at 2 m (None with
                                            the shape)
    metadata                       -        free-form provenance (data fitted from, fills); not compared
    ============================== ======== ===========================================================
    """

    name: str
    site: Site
    wet_day_threshold_mm: float
    p_wet_after_dry: Monthly
    p_wet_after_wet: Monthly
    rain_excess_shape: Monthly
    rain_excess_scale_mm: Monthly
    tmax_mean_dry_degc: Monthly
    tmax_mean_wet_degc: Monthly
    tmax_sd_dry_degc: Monthly
    tmax_sd_wet_degc: Monthly
    tmin_mean_dry_degc: Monthly
    tmin_mean_wet_degc: Monthly
    tmin_sd_dry_degc: Monthly
    tmin_sd_wet_degc: Monthly
    srad_mean_dry_mj_m2: Monthly
    srad_mean_wet_mj_m2: Monthly
    srad_sd_dry_mj_m2: Monthly
    srad_sd_wet_mj_m2: Monthly
    residual_lag0_correlation: Matrix3
    residual_lag1_correlation: Matrix3
    dew_point_depression_mean_degc: OptionalMonthly
    dew_point_depression_sd_degc: OptionalMonthly
    wind_shape: OptionalMonthly
    wind_scale_m_s: OptionalMonthly
    metadata: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        for pair in OPTIONAL_PAIRS:
            if (getattr(self, pair[0]) is None) != (getattr(self, pair[1]) is None):
                raise WeatherError(f"generator parameters {self.name}: {pair[0]} and {pair[1]} must both be "
                                   f"given or both be null")
        for item in fields(self):
            if item.type not in ("Monthly", "OptionalMonthly") or getattr(self, item.name) is None:
                continue
            values = tuple(float(v) for v in getattr(self, item.name))
            if len(values) != MONTHS or not all(np.isfinite(values)):
                raise WeatherError(f"generator parameters {self.name}: {item.name} needs {MONTHS} finite "
                                   f"monthly values, got {values}")
            object.__setattr__(self, item.name, values)
            if item.name.startswith("p_wet") and not all(0.0 <= v <= 1.0 for v in values):
                raise WeatherError(f"generator parameters {self.name}: {item.name} has a probability "
                                   f"outside [0, 1]: {values}")
            positive = item.name.endswith(("shape", "scale_mm", "scale_m_s"))
            if (positive and min(values) <= 0) or ("_sd_" in item.name and min(values) < 0):
                raise WeatherError(f"generator parameters {self.name}: {item.name} must be "
                                   f"{'positive' if positive else 'non-negative'}: {values}")
        for name in ("residual_lag0_correlation", "residual_lag1_correlation"):
            matrix = np.asarray(getattr(self, name), dtype=float)
            if matrix.shape != (3, 3) or not np.all(np.abs(matrix) <= 1.0):
                raise WeatherError(f"generator parameters {self.name}: {name} must be a 3 x 3 correlation "
                                   f"matrix, got {matrix.tolist()}")
            object.__setattr__(self, name, tuple(tuple(float(v) for v in row) for row in matrix))

    def to_json(self, path: str | Path) -> None:
        """Write the parameters (and metadata) as JSON."""
        write_text_atomic(path, json.dumps(asdict(self), indent=1) + "\n")

    @classmethod
    def from_json(cls, path: str | Path) -> "GeneratorParameters":
        """Read parameters written by :meth:`to_json`; WeatherError names the file on any problem."""
        try:
            values = json.loads(Path(path).read_text(encoding="utf-8"))
            values["site"] = Site(**values["site"])
            return cls(**values)
        except (OSError, ValueError, TypeError, KeyError) as error:
            raise WeatherError(f"{path}: not generator parameters: {error}") from None


    @property
    def fao56_filled(self) -> tuple[str, ...]:
        """The variables (vap_hpa, wind_m_s) generated by FAO-56's missing-data rules, not drawn."""
        return tuple(variable for variable, pair in zip(("vap_hpa", "wind_m_s"), OPTIONAL_PAIRS)
                     if getattr(self, pair[0]) is None)


# Frozen parameters, read once per process: a spread pool derives thousands of climates from one fitted set.
@functools.lru_cache(maxsize=None)
def generator_parameters(name: str) -> GeneratorParameters:
    """The packaged parameter set ``name`` (one of :data:`GENERATOR_NAMES`); WeatherError lists the known
    names for an unknown one."""
    if name not in GENERATOR_NAMES:
        raise WeatherError(f"unknown generator parameters {name!r}; known: {', '.join(GENERATOR_NAMES)}")
    params = GeneratorParameters.from_json(Path(__file__).with_name(name + PARAMETERS_SUFFIX))
    if params.name != name:
        raise WeatherError(f"{name}{PARAMETERS_SUFFIX}: holds parameters named {params.name!r}, not {name!r}")
    return params


# Largest warming or drying (degC, either sign) a scenario may add to a generator's temperatures or dew-point
# depressions.
MAX_DELTA_DEGC = 10.0


def _bounded_number(name: str, value, low: float = -MAX_DELTA_DEGC, high: float = MAX_DELTA_DEGC) -> float:
    """``value`` as a float, or WeatherError naming ``name`` unless it is finite and within [low, high] (by
    default a delta-change's +-:data:`MAX_DELTA_DEGC`)."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = np.nan
    if not (np.isfinite(number) and low <= number <= high):
        raise WeatherError(f"{name}: {value!r} is not a finite number in [{low:g}, {high:g}]")
    return number


def warmed(params: GeneratorParameters, warming_degc: float) -> GeneratorParameters:
    """``params`` with every monthly mean of TMAX and TMIN (dry and wet days) raised by ``warming_degc`` (the
    delta-change method of climate-change impact studies: the same variability, the same rain, radiation,
    wind and dew-point depression, so vapour pressure rises with TMIN). Named ``<name><warming>C``
    (``benton+4C``), so a warmed climate's seasons (their source names the parameters) are told apart from the
    original's. 0 returns ``params``."""
    warming = _bounded_number("warming_degc", warming_degc)
    if warming == 0.0:
        return params
    shifted = {name: tuple(float(v) + warming for v in getattr(params, name))
               for name in ("tmax_mean_dry_degc", "tmax_mean_wet_degc", "tmin_mean_dry_degc", "tmin_mean_wet_degc")}
    return replace(params, name=f"{params.name}{warming:+g}C", **shifted)


def widened(params: GeneratorParameters, diurnal_range_degc: float) -> GeneratorParameters:
    """``params`` with every monthly mean diurnal temperature range (TMAX - TMIN, dry and wet days) widened by
    ``diurnal_range_degc``: TMAX raised and TMIN lowered by half of it each, the daily mean temperature kept. A
    desert's clear, dry nights are cold: its days are hotter than a humid site's at the same mean (Maricopa sown
    February 28: TMAX - TMIN 18-19 degC a day, Benton's spring 15-17). The dew-point depression is kept, so the
    dew point and the vapour pressure follow TMIN down. Named ``<name><range>DTR`` (``benton+4C+4DTR``). 0
    returns ``params``."""
    widening = _bounded_number("diurnal_range_degc", diurnal_range_degc)
    if widening == 0.0:
        return params
    half = widening / 2.0
    shifted = {name: tuple(float(v) + sign * half for v in getattr(params, name))
               for name, sign in (("tmax_mean_dry_degc", 1.0), ("tmax_mean_wet_degc", 1.0),
                                  ("tmin_mean_dry_degc", -1.0), ("tmin_mean_wet_degc", -1.0))}
    return replace(params, name=f"{params.name}{widening:+g}DTR", **shifted)


def dried(params: GeneratorParameters, drying_degc: float) -> GeneratorParameters:
    """``params`` with every monthly mean dew-point depression (TMIN - dew point) raised by ``drying_degc``: the
    same temperatures, rain, radiation and wind under drier air (lower vapour pressure, so higher FAO-56 ET0),
    the humidity delta-change beside :func:`warmed`'s temperature one. Named ``<name><drying>DPD``
    (``benton+4C+8DPD``). 0 returns ``params``; WeatherError for a site fitted without humidity data (its
    vapour pressure follows FAO-56's missing-data rule, e_a = e0(TMIN), which has no depression to raise)."""
    drying = _bounded_number("drying_degc", drying_degc)
    if drying == 0.0:
        return params
    if params.dew_point_depression_mean_degc is None:
        raise WeatherError(f"drying_degc: {params.name} was fitted without humidity data; there is no dew-point "
                           "depression to raise")
    depression = tuple(float(v) + drying for v in params.dew_point_depression_mean_degc)
    return replace(params, name=f"{params.name}{drying:+g}DPD", dew_point_depression_mean_degc=depression)


# Rain factors a scenario may apply to a generator's rain amounts.
MIN_RAIN_FACTOR, MAX_RAIN_FACTOR = 0.0, 3.0


def rain_scaled(params: GeneratorParameters, rain_factor: float) -> GeneratorParameters:
    """``params`` with every wet day's rain multiplied by ``rain_factor`` (the delta-change of precipitation: the
    same wet days, smaller or larger amounts; the wet-day threshold and the gamma scale of the excess both scale,
    so a generated day's rain is exactly ``rain_factor`` times the original's). Named ``<name>x<factor>R``
    (``benton+6C+8DPDx0.3R``). 1 returns ``params``."""
    factor = _bounded_number("rain_factor", rain_factor, MIN_RAIN_FACTOR, MAX_RAIN_FACTOR)
    if factor == 1.0:
        return params
    return replace(params, name=f"{params.name}x{factor:g}R", wet_day_threshold_mm=params.wet_day_threshold_mm * factor,
                   rain_excess_scale_mm=tuple(float(v) * factor for v in params.rain_excess_scale_mm))


# Radiation factors a scenario may apply to a generator's SRAD (clearer or cloudier skies).
MIN_RADIATION_FACTOR, MAX_RADIATION_FACTOR = 0.5, 2.0


def brightened(params: GeneratorParameters, radiation_factor: float) -> GeneratorParameters:
    """``params`` with every monthly mean and standard deviation of SRAD (dry and wet days) multiplied by
    ``radiation_factor``: clearer (above 1) or cloudier skies, the delta-change of radiation beside
    :func:`warmed`'s, :func:`dried`'s and :func:`rain_scaled`'s (the same temperatures, humidity, rain, wind and
    standardized residuals). Every day stays capped at the site's clear-sky radiation Rso, so a month already
    near it gains less than the factor. Named ``<name>x<factor>S`` (``benton+6C+8DPDx1.25Sx0.3R``). 1 returns
    ``params``."""
    factor = _bounded_number("radiation_factor", radiation_factor, MIN_RADIATION_FACTOR, MAX_RADIATION_FACTOR)
    if factor == 1.0:
        return params
    scaled = {name: tuple(float(v) * factor for v in getattr(params, name))
              for name in ("srad_mean_dry_mj_m2", "srad_mean_wet_mj_m2", "srad_sd_dry_mj_m2", "srad_sd_wet_mj_m2")}
    return replace(params, name=f"{params.name}x{factor:g}S", **scaled)


# A climate's name: a fitted generator, then optionally its warming (C), its diurnal range's widening (DTR), its
# drying (DPD), its radiation factor (S) and its rain factor (R), as warmed, widened, dried, brightened and
# rain_scaled write them.
_CLIMATE_NAME = re.compile(r"(?P<generator>[a-z_]+)(?:(?P<warming>[+-][0-9.]+)C)?(?:(?P<range>[+-][0-9.]+)DTR)?"
                           r"(?:(?P<drying>[+-][0-9.]+)DPD)?"
                           r"(?:x(?P<radiation>[0-9.]+)S)?(?:x(?P<rain>[0-9.]+)R)?")


def climate_name(generator: str, warming_degc: float = 0.0, drying_degc: float = 0.0, rain_factor: float = 1.0,
                 radiation_factor: float = 1.0, diurnal_range_degc: float = 0.0) -> str:
    """The name of ``generator`` warmed by ``warming_degc``, its diurnal range widened by ``diurnal_range_degc``,
    dried by ``drying_degc``, its radiation scaled by ``radiation_factor`` and its rain by ``rain_factor``
    (``benton+4C+4DTR+8DPDx1.25Sx0.3R``): the name the climate's parameters and its seasons' source carry."""
    return (generator + (f"{float(warming_degc):+g}C" if warming_degc else "")
            + (f"{float(diurnal_range_degc):+g}DTR" if diurnal_range_degc else "")
            + (f"{float(drying_degc):+g}DPD" if drying_degc else "")
            + (f"x{float(radiation_factor):g}S" if radiation_factor != 1.0 else "")
            + (f"x{float(rain_factor):g}R" if rain_factor != 1.0 else ""))


def climate_parameters(climate: str) -> GeneratorParameters:
    """The parameters of ``climate`` (``benton``, ``benton+4C``, ``benton+6C+8DPDx1.25Sx0.3R``: see
    :func:`climate_name`); WeatherError naming the fitted generators for an unknown one."""
    match = _CLIMATE_NAME.fullmatch(str(climate))
    if match is None or match["generator"] not in GENERATOR_NAMES:
        raise WeatherError(f"no climate {climate!r}: a fitted generator ({', '.join(GENERATOR_NAMES)}), optionally "
                           "warmed, its diurnal range widened, dried, its radiation and its rain scaled as in "
                           "benton+4C, benton+4C+8DPD or benton+4C+4DTR+8DPDx1.25Sx0.3R")
    try:
        warming, widening, drying = (float(match[key] or 0.0) for key in ("warming", "range", "drying"))
        radiation, rain = (float(match[key] or 1.0) for key in ("radiation", "rain"))
    except ValueError:
        raise WeatherError(f"no climate {climate!r}: its warming, diurnal range, drying, radiation or rain factor "
                           "is not a number") from None
    params = rain_scaled(brightened(dried(widened(warmed(generator_parameters(match["generator"]), warming), widening),
                                          drying), radiation), rain)
    if params.name != climate:  # e.g. benton+4.0C, which no generated season's source is named
        raise WeatherError(f"no climate {climate!r}: its parameters are named {params.name!r}")
    return params


def benton_parameters() -> GeneratorParameters:
    """Parameters fitted to Benton County, WA (``crop-sim fit-weather``; see the file's metadata)."""
    return generator_parameters("benton")


def _monthly(params: GeneratorParameters, name: str, month_index: np.ndarray) -> np.ndarray:
    """The monthly parameter ``name`` for each day, shape (days, 1) to broadcast over seasons."""
    return np.asarray(getattr(params, name))[month_index][:, None]


def _autoregression(params: GeneratorParameters) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Richardson's A, B (z_t = A z_(t-1) + B e_t) and the Cholesky factor of the lag-0 correlation."""
    m0 = np.asarray(params.residual_lag0_correlation)
    m1 = np.asarray(params.residual_lag1_correlation)
    a = m1 @ np.linalg.inv(m0)
    innovation = m0 - a @ m1.T
    # Sampling error can leave the innovation covariance slightly indefinite: clip its eigenvalues.
    eigenvalues, vectors = np.linalg.eigh((innovation + innovation.T) / 2)
    b = vectors * np.sqrt(np.clip(eigenvalues, 0.0, None))
    return a, b, np.linalg.cholesky(m0)


def _generate_arrays(params: GeneratorParameters, dates: np.ndarray, n_seasons: int,
                     rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Every weather variable as a (days, n_seasons) array."""
    days = len(dates)
    month_index = (dates.astype("datetime64[M]").astype(int) % MONTHS)
    day_of_year = (dates - dates.astype("datetime64[Y]").astype("datetime64[D]")).astype(int) + 1

    # Rain occurrence: Markov chain, started from the first month's stationary wet probability.
    uniform = rng.random((days, n_seasons))
    p_dry_wet = _monthly(params, "p_wet_after_dry", month_index)[:, 0]
    p_wet_wet = _monthly(params, "p_wet_after_wet", month_index)[:, 0]
    wet = np.empty((days, n_seasons), dtype=bool)
    wet[0] = uniform[0] < p_dry_wet[0] / max(1.0 + p_dry_wet[0] - p_wet_wet[0], 1e-12)
    for t in range(1, days):
        wet[t] = uniform[t] < np.where(wet[t - 1], p_wet_wet[t], p_dry_wet[t])
    excess_mm = rng.gamma(_monthly(params, "rain_excess_shape", month_index),
                          _monthly(params, "rain_excess_scale_mm", month_index), size=(days, n_seasons))
    rain_mm = np.where(wet, params.wet_day_threshold_mm + excess_mm, 0.0)

    # Standardized TMAX, TMIN, SRAD residuals: multivariate AR(1).
    a, b, lag0_factor = _autoregression(params)
    noise = rng.standard_normal((days, n_seasons, len(RESIDUAL_VARIABLES)))
    residuals = np.empty_like(noise)
    residuals[0] = noise[0] @ lag0_factor.T
    for t in range(1, days):
        residuals[t] = residuals[t - 1] @ a.T + noise[t] @ b.T
    values = {}
    for k, variable in enumerate(RESIDUAL_VARIABLES):
        mean_dry_name, mean_wet_name, sd_dry_name, sd_wet_name = conditional_field_names(variable)
        mean_dry = smooth_daily(getattr(params, mean_dry_name), dates)[:, None]
        mean_wet = smooth_daily(getattr(params, mean_wet_name), dates)[:, None]
        sd_dry, sd_wet = _monthly(params, sd_dry_name, month_index), _monthly(params, sd_wet_name, month_index)
        values[variable] = np.where(wet, mean_wet + sd_wet * residuals[..., k],
                                    mean_dry + sd_dry * residuals[..., k])
    tmin_degc = np.minimum(values["tmin"], values["tmax"])
    tmax_degc = np.maximum(values["tmin"], values["tmax"])
    srad_max = clear_sky_radiation_mj_m2(day_of_year, params.site.latitude_deg, params.site.elevation_m)
    srad_mj_m2 = np.clip(values["srad"], MIN_SRAD_MJ_M2, srad_max[:, None])

    # Without parameters (no data) VAP and wind stay missing here; generate_seasons fills them by FAO-56.
    vap_hpa = wind_m_s = np.full((days, n_seasons), np.nan)
    if "vap_hpa" not in params.fao56_filled:
        depression_degc = (_monthly(params, "dew_point_depression_mean_degc", month_index)
                           + _monthly(params, "dew_point_depression_sd_degc", month_index)
                           * rng.standard_normal((days, n_seasons)))
        vap_hpa = saturation_vapour_pressure_hpa(np.minimum(tmin_degc - depression_degc, (tmax_degc + tmin_degc) / 2))
    if "wind_m_s" not in params.fao56_filled:
        wind_m_s = rng.gamma(_monthly(params, "wind_shape", month_index),
                             _monthly(params, "wind_scale_m_s", month_index), size=(days, n_seasons))
    return {"tmax_degc": tmax_degc, "tmin_degc": tmin_degc, "srad_mj_m2": srad_mj_m2, "rain_mm": rain_mm,
            "vap_hpa": vap_hpa, "wind_m_s": wind_m_s}


def _season_series(params: GeneratorParameters, dates: np.ndarray, arrays: dict[str, np.ndarray], k: int,
                   source: str) -> WeatherSeries:
    """Season ``k`` (a column) of :func:`_generate_arrays`' ``arrays`` as a series from ``source``, the variables
    the parameters have no data for filled by FAO-56's rules."""
    one = make_series(params.site, dates, source=source,
                      **{name: np.ascontiguousarray(values[:, k]) for name, values in arrays.items()})
    return one.with_fao56_fills() if params.fao56_filled else one


def generate_seasons(params: GeneratorParameters, start: date, days: int, n_seasons: int,
                     seed: int | np.random.Generator) -> list[WeatherSeries]:
    """``n_seasons`` independent seasons of ``days`` days from ``start``, drawn at once.

    The same integer seed gives the same seasons; a ``numpy.random.Generator`` is advanced. Each series'
    source reads ``generator(<name>, seed=<seed>, season=<k>)`` (no season index when n_seasons is 1).
    Variables the parameters have no data for are filled by FAO-56's rules and listed in ``filled``.
    """
    if days < 1 or n_seasons < 1:
        raise WeatherError(f"generator({params.name}): days ({days}) and n_seasons ({n_seasons}) must be >= 1")
    dates = np.datetime64(start, "D") + np.arange(days)
    arrays = _generate_arrays(params, dates, n_seasons, np.random.default_rng(seed))
    seed_text = seed if isinstance(seed, (int, np.integer)) else "rng"
    return [_season_series(params, dates, arrays, k, f"generator({params.name}, seed={seed_text}"
                                                     f"{'' if n_seasons == 1 else f', season={k}'})")
            for k in range(n_seasons)]


def _range(name: str, values, low: float, high: float, whole: bool = False) -> tuple[float, float]:
    """``values`` as a (least, most) pair within [low, high] (whole numbers if ``whole``), else WeatherError
    naming ``name``."""
    if not isinstance(values, (tuple, list)) or len(values) != 2:
        raise WeatherError(f"{name}: expected [least, most], got {values!r}")
    least, most = (_bounded_number(name, v, low, high) for v in values)
    if least > most or (whole and (least != int(least) or most != int(most))):
        raise WeatherError(f"{name}: {list(values)!r} is not a range [least, most]"
                           f"{' of whole numbers' if whole else ''}")
    return least, most


# Most days a spread pool may delay a season's sowing past its scenario's sowing date (a year).
MAX_SOWING_DELAY_DAYS = 365


@dataclass(frozen=True)
class ClimateSpread:
    """Ranges from which every season of a pool draws its own climate and sowing date, each uniformly and
    independently (domain randomisation across climates, where a mixture's parts are a few fixed points):

    ===================== ======= ==========================================================================
    field                 unit    what each season draws (a range [least, most]; least == most fixes it)
    ===================== ======= ==========================================================================
    warming_degc          degC    its :func:`warmed` delta-change, rounded to 0.1 degC
    drying_degc           degC    its :func:`dried` delta-change, rounded to 0.1 degC
    rain_factor           1       its :func:`rain_scaled` factor, rounded to 0.01
    sowing_delay_days     d       whole days after the scenario's sowing date that it is sown
    ===================== ======= ==========================================================================

    The rounding keeps each season's climate a short name (``benton+3.7C+5.2DPDx0.46R``) that
    :func:`climate_parameters` reads back, so a season's source names its own climate."""

    warming_degc: tuple[float, float] = (0.0, 0.0)
    drying_degc: tuple[float, float] = (0.0, 0.0)
    rain_factor: tuple[float, float] = (1.0, 1.0)
    sowing_delay_days: tuple[int, int] = (0, 0)

    def __post_init__(self) -> None:
        for name, low, high, whole in (("warming_degc", -MAX_DELTA_DEGC, MAX_DELTA_DEGC, False),
                                       ("drying_degc", -MAX_DELTA_DEGC, MAX_DELTA_DEGC, False),
                                       ("rain_factor", MIN_RAIN_FACTOR, MAX_RAIN_FACTOR, False),
                                       ("sowing_delay_days", 0, MAX_SOWING_DELAY_DAYS, True)):
            least, most = _range(f"spread.{name}", getattr(self, name), low, high, whole)
            object.__setattr__(self, name, (int(least), int(most)) if whole else (least, most))

    @classmethod
    def from_dict(cls, values: dict) -> "ClimateSpread":
        """From a mapping of the fields (a scenario's ``weather.spread``); WeatherError names an unknown field."""
        if not isinstance(values, dict):
            raise WeatherError(f"spread: expected a mapping of ranges, got {values!r}")
        unknown = set(values) - {f.name for f in fields(cls)}
        if unknown:
            raise WeatherError(f"spread.{sorted(unknown)[0]}: not a field (fields: "
                               f"{', '.join(f.name for f in fields(cls))})")
        return cls(**{name: tuple(v) if isinstance(v, list) else v for name, v in values.items()})

    def describe(self) -> str:
        """The ranges in words (``+0 to +8 degC, dew-point depression +0 to +10 degC, rain x 0.2 to 1, sown 0 to 61
        days later``), the fixed ones left out."""
        def span(least, most, form):
            return format(least, form) + ("" if least == most else " to " + format(most, form))
        words = [f"{prefix}{span(*values, '+g')} degC" for prefix, values in
                 (("", self.warming_degc), ("dew-point depression ", self.drying_degc)) if values != (0.0, 0.0)]
        if self.rain_factor != (1.0, 1.0):
            words.append(f"rain x {span(*self.rain_factor, 'g')}")
        if self.sowing_delay_days != (0, 0):
            words.append(f"sown {span(*self.sowing_delay_days, 'd')} days later")
        return ", ".join(words)

    def draw(self, generator: str, n_seasons: int, rng: np.random.Generator) -> list[tuple[str, int]]:
        """(climate name, sowing delay in days) of each of ``n_seasons`` seasons of ``generator``."""
        warming = np.round(rng.uniform(*self.warming_degc, n_seasons), 1)
        drying = np.round(rng.uniform(*self.drying_degc, n_seasons), 1)
        rain = np.round(rng.uniform(*self.rain_factor, n_seasons), 2)
        delay = rng.integers(self.sowing_delay_days[0], self.sowing_delay_days[1] + 1, n_seasons)
        # + 0.0 turns a rounded -0.0 into 0.0, which the name omits
        return [(climate_name(generator, w + 0.0, d + 0.0, r), int(days))
                for w, d, r, days in zip(warming, drying, rain, delay)]


def generate_spread_seasons(generator: str, spread: ClimateSpread, start: date, days: int, n_seasons: int,
                            seed: int) -> list[WeatherSeries]:
    """``n_seasons`` seasons of ``days`` days, each from its own climate and sowing date drawn from ``spread``
    (the climate ``generator`` delta-changed; sown ``start`` + its delay). The same seed gives the same seasons.
    Each series' source reads ``generator(<its climate>, seed=<seed>, season=<k>)``."""
    if days < 1 or n_seasons < 1:
        raise WeatherError(f"generator({generator}): days ({days}) and n_seasons ({n_seasons}) must be >= 1")
    rng = np.random.default_rng(seed)
    series = []
    for k, (climate, delay) in enumerate(spread.draw(generator, n_seasons, rng)):
        params = climate_parameters(climate)
        dates = np.datetime64(start + timedelta(days=delay), "D") + np.arange(days)
        series.append(_season_series(params, dates, _generate_arrays(params, dates, 1, rng), 0,
                                     f"generator({climate}, seed={seed}, season={k})"))
    return series


def generator_of_source(source: str) -> str | None:
    """The generator name in a series' source as :func:`generate_seasons` writes it
    (``generator(<name>, seed=...)``), or None for weather that no generator made."""
    if not source.startswith("generator(") or "," not in source:
        return None
    return source[len("generator("):source.index(",")]


def generate_season(params: GeneratorParameters, start: date, days: int,
                    seed: int | np.random.Generator) -> WeatherSeries:
    """One season: :func:`generate_seasons` with n_seasons = 1."""
    return generate_seasons(params, start, days, 1, seed)[0]
