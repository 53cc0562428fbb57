"""``crop-sim fit-weather``: fit :class:`GeneratorParameters` to observed daily weather files, write them as
JSON and print the fitted generator's monthly statistics next to the observed ones.

Every monthly statistic uses the days of its own calendar month when there are at least
``MIN_DAYS_PER_STATISTIC`` of them; otherwise the nearest months (cyclically, +-1, +-2, ...) are pooled in
until there are. Months without any observation of a variable (vapour pressure and wind outside
April-September, when only the AgWeatherNet file has them) so take the nearest observed month; the JSON
metadata lists every such pooling. Wet-day temperature and radiation statistics pool anomalies from the
dry-day mean curve of each day (the smooth daily curve of the monthly means, as the generator draws),
so pooling does not mix in the neighbour's seasonal level.

Repeated weather is fitted once (:func:`distinct_station_days`): experiments often reuse one year's file
under another name (CARO8201.WTH is UFGA8201.WTH), sometimes under another year's dates. A site whose files
have no vapour pressure (or no wind) at all gets none of those parameters: the generator then fills them by
FAO-56's missing-data rules, as the task fills a real season without them (see the generator's docstring).
"""

from __future__ import annotations

import argparse
import hashlib
from dataclasses import replace
from datetime import date
from pathlib import Path

import numpy as np

from .generator import (BENTON_PARAMETERS_FILE, MONTHS, PARAMETERS_SUFFIX, RESIDUAL_VARIABLES,
                        GeneratorParameters, conditional_field_names, dew_point_degc, generate_seasons,
                        smooth_daily)
from .readers import read_agweathernet_csv, read_dssat_wth
from .series import VARIABLES, WeatherError, WeatherSeries

DEFAULT_DATA_DIR = Path("../shared/data")
DEFAULT_AGWEATHERNET = ("agweathernet/benton_e_2000-04-01_2000-09-30.csv",)
DEFAULT_DSSAT = tuple(f"simple_r_inputs/Weather/WAPA{year}01.WTH" for year in (92, 93, 94, 95))
# 0.01 inch: the resolution of the tipping-bucket gauges behind both sources.
WET_DAY_THRESHOLD_MM = 0.25
MIN_DAYS_PER_STATISTIC = 10
# Mean month length (February of a leap year counted a quarter), days: monthly totals = daily mean x this.
MONTH_LENGTH_DAYS = np.array([31, 28.25, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31])
# Metadata of a fit without humidity or wind data: how the generator makes them instead.
FAO56_VAP_RULE = ("no vapour pressure in the data: generated as e_a = e0(TMIN) (dew point taken as TMIN, "
                  "FAO-56 eq. 48), as the task fills real seasons without it")
FAO56_WIND_RULE = ("no wind in the data: generated as 2 m/s at 2 m (FAO-56 missing-data rule), as the task "
                   "fills real seasons without it")
MONTH_NAMES = ("Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA_DIR,
                        help="reference data directory the file names are relative to (default: %(default)s)")
    parser.add_argument("--agweathernet", nargs="*", default=None, metavar="CSV",
                        help="AgWeatherNet daily CSV files (with neither this nor --dssat: the Benton E. 2000 "
                             "season; naming only --dssat fits only its files)")
    parser.add_argument("--dssat", nargs="*", default=None, metavar="WTH",
                        help="DSSAT .WTH files (with neither this nor --agweathernet: Paterson, WA, 1992-1995; "
                             "naming only --agweathernet fits only its files)")
    parser.add_argument("--name", default="benton", help="label of the fitted parameters (default: %(default)s)")
    parser.add_argument("--out", type=Path, default=None,
                        help="JSON file to write (default: the packaged <name>_generator.json)")
    parser.add_argument("--check-seasons", type=int, default=500, metavar="N",
                        help="years generated to compare with the observations (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the comparison run (default: %(default)s)")


def observed_files(agweathernet: list[str] | None, dssat: list[str] | None) -> tuple[list[str], list[str]]:
    """The files the command fits: Benton's defaults when neither option is given, else only those named (a
    fit of another site must not take in Benton's files unasked)."""
    if agweathernet is None and dssat is None:
        return list(DEFAULT_AGWEATHERNET), list(DEFAULT_DSSAT)
    return list(agweathernet or []), list(dssat or [])


def load_observed(data_dir: Path, agweathernet=DEFAULT_AGWEATHERNET, dssat=DEFAULT_DSSAT) -> list[WeatherSeries]:
    """The observed series, AgWeatherNet files first (their site becomes the fitted site); each series'
    source is its file name relative to ``data_dir``, so the fitted metadata does not depend on where it ran.
    """
    return ([replace(read_agweathernet_csv(Path(data_dir) / name), source=str(name)) for name in agweathernet]
            + [replace(read_dssat_wth(Path(data_dir) / name), source=str(name)) for name in dssat])


def distinct_station_days(series_list: list[WeatherSeries]) -> tuple[list[WeatherSeries], list[dict]]:
    """``series_list`` with repeated weather removed, and one record per removal (source, what, days,
    same_as).

    Series are taken in order, and each calendar year of a series is one block:

    - a block whose values (every variable, day by day; dates left out) equal an earlier block's is a
      repeat: its days become missing (NaN). A series left without any value is dropped;
    - a day whose date and values an earlier series already gave is a repeat too (a partial year copied);
    - a day whose date an earlier series gave with other values is a WeatherError naming both files: two
      versions of the same day (a heated plot's temperatures, an offset TMIN) cannot both be the climate.
    """
    kept, repeats = [], []
    block_sources: dict[str, str] = {}
    day_sources: dict[np.datetime64, tuple[str, bytes]] = {}
    for series in series_list:
        values = np.nan_to_num(np.stack([getattr(series, name) for name in VARIABLES], axis=1), nan=-1e9)
        has_value = np.isfinite(np.stack([getattr(series, name) for name in VARIABLES])).any(axis=0)
        repeat = np.zeros(len(series), dtype=bool)
        years = series.dates.astype("datetime64[Y]")
        for year in np.unique(years[has_value]):
            block = (years == year) & has_value
            key = hashlib.sha256(values[block].tobytes()).hexdigest()
            if key in block_sources:
                repeat |= block
                repeats.append({"source": series.source, "what": f"year {year}", "days": int(block.sum()),
                                "same_as": block_sources[key]})
            else:
                block_sources[key] = f"{series.source}, year {year}"
        same_day_sources: dict[str, int] = {}
        for i in np.flatnonzero(has_value & ~repeat):
            earlier_source, earlier_row = day_sources.setdefault(series.dates[i], (series.source, values[i].tobytes()))
            if earlier_source == series.source:
                continue
            if earlier_row != values[i].tobytes():
                raise WeatherError(f"{series.source} and {earlier_source} give different weather for "
                                   f"{series.dates[i]}: two versions of one day cannot both be fitted")
            repeat[i] = True
            same_day_sources[earlier_source] = same_day_sources.get(earlier_source, 0) + 1
        repeats += [{"source": series.source, "what": "days of the same dates", "days": days, "same_as": earlier}
                    for earlier, days in same_day_sources.items()]
        if not repeat.any():
            kept.append(series)
        elif (has_value & ~repeat).any():
            kept.append(replace(series, **{name: np.where(repeat, np.nan, getattr(series, name))
                                           for name in VARIABLES}))
    return kept, repeats


class _Days:
    """All observed days pooled: variables, calendar month (0-11), wetness and yesterday's wetness."""

    def __init__(self, series_list: list[WeatherSeries], threshold_mm: float) -> None:
        def stack(values) -> np.ndarray:
            return np.concatenate([np.asarray(v, dtype=float) for v in values])

        self.dates = np.concatenate([s.dates for s in series_list])
        self.month = self.dates.astype("datetime64[M]").astype(int) % MONTHS
        for name in ("tmax_degc", "tmin_degc", "srad_mj_m2", "rain_mm", "vap_hpa", "wind_m_s"):
            setattr(self, name, stack(getattr(s, name) for s in series_list))
        self.has_rain = np.isfinite(self.rain_mm)
        self.wet = self.has_rain & (self.rain_mm >= threshold_mm)
        self.dry = self.has_rain & ~self.wet
        # Yesterday in the same series, with a rain observation.
        first = np.zeros(len(self.month), dtype=bool)
        first[np.cumsum([0] + [len(s) for s in series_list[:-1]])] = True
        self.has_yesterday = ~first & np.roll(self.has_rain, 1)
        self.wet_yesterday = np.roll(self.wet, 1) & self.has_yesterday


def pooled_months(month_of_day: np.ndarray, selected: np.ndarray, min_days: int = MIN_DAYS_PER_STATISTIC):
    """For each month, the months whose ``selected`` days one statistic uses (see the module docstring)."""
    counts = np.bincount(month_of_day[selected], minlength=MONTHS)
    if counts.sum() < min_days:
        raise WeatherError(f"only {counts.sum()} days to fit a statistic that needs {min_days}")
    result = []
    for month in range(MONTHS):
        radius = 0
        while counts[[(month + d) % MONTHS for d in range(-radius, radius + 1)]].sum() < min_days:
            radius += 1
        result.append(sorted({(month + d) % MONTHS for d in range(-radius, radius + 1)
                              if counts[(month + d) % MONTHS] > 0}))
    return result


class _Fitter:
    """Monthly statistics with pooling; ``pooling`` records every month that borrowed other months' days."""

    def __init__(self, days: _Days) -> None:
        self.days = days
        self.pooling: dict[str, dict[str, list[int]]] = {}

    def monthly(self, label: str, values: np.ndarray, selected: np.ndarray, statistic) -> list:
        selected = selected & np.isfinite(values)
        result = []
        for month, months in enumerate(pooled_months(self.days.month, selected)):
            if months != [month]:
                self.pooling.setdefault(label, {})[MONTH_NAMES[month]] = [MONTH_NAMES[m] for m in months]
            result.append(statistic(values[selected & np.isin(self.days.month, months)]))
        return result


def _sd(values: np.ndarray) -> float:
    return float(np.std(values, ddof=1))


def _gamma_moments(values: np.ndarray) -> tuple[float, float]:
    """Gamma (shape, scale) by the method of moments: it keeps the mean, hence monthly totals, exact."""
    mean, variance = float(np.mean(values)), float(np.var(values, ddof=1))
    return mean * mean / variance, variance / mean


def fit_parameters(series_list: list[WeatherSeries], name: str,
                   threshold_mm: float = WET_DAY_THRESHOLD_MM) -> GeneratorParameters:
    """Fit the generator to the distinct station-days of ``series_list`` (pooled by calendar month); the
    site is the first series'."""
    series_list, repeats = distinct_station_days(series_list)
    days = _Days(series_list, threshold_mm)
    fitter = _Fitter(days)
    p_wet_after_dry = fitter.monthly("p_wet_after_dry", days.wet.astype(float),
                                     days.has_yesterday & ~days.wet_yesterday & days.has_rain, np.mean)
    p_wet_after_wet = fitter.monthly("p_wet_after_wet", days.wet.astype(float),
                                     days.wet_yesterday & days.has_rain, np.mean)
    rain_gamma = fitter.monthly("rain_excess", days.rain_mm - threshold_mm, days.wet, _gamma_moments)

    values: dict = {}
    residuals = []
    for variable, column in zip(RESIDUAL_VARIABLES, ("tmax_degc", "tmin_degc", "srad_mj_m2")):
        observed = getattr(days, column)
        mean_dry_name, mean_wet_name, sd_dry_name, sd_wet_name = conditional_field_names(variable)
        mean_dry = np.array(fitter.monthly(mean_dry_name, observed, days.dry, np.mean))
        anomaly_dry = observed - smooth_daily(mean_dry, days.dates)
        sd_dry = np.array(fitter.monthly(sd_dry_name, anomaly_dry, days.dry, _sd))
        mean_wet = mean_dry + fitter.monthly(mean_wet_name, anomaly_dry, days.wet, np.mean)
        anomaly_wet = observed - smooth_daily(mean_wet, days.dates)
        sd_wet = np.array(fitter.monthly(sd_wet_name, anomaly_wet, days.wet, _sd))
        values.update({mean_dry_name: mean_dry, mean_wet_name: mean_wet, sd_dry_name: sd_dry, sd_wet_name: sd_wet})
        residuals.append(np.where(days.wet, anomaly_wet / sd_wet[days.month], anomaly_dry / sd_dry[days.month]))
    residuals = np.array(residuals)  # (3, days)
    today = np.all(np.isfinite(residuals), axis=0)
    lag0 = np.corrcoef(residuals[:, today])
    pairs = np.flatnonzero(today & np.roll(today, 1) & days.has_yesterday)
    lag1 = np.array([[np.corrcoef(residuals[i, pairs], residuals[j, pairs - 1])[0, 1] for j in range(3)]
                     for i in range(3)])

    everyday = np.ones(len(days.month), dtype=bool)
    # No humidity (wind) data at all: no parameters; the generator fills by FAO-56 like the task does.
    depression_mean = depression_sd = wind_shape = wind_scale = None
    fao56_rules = {}
    if np.isfinite(days.vap_hpa).any():
        depression = days.tmin_degc - dew_point_degc(days.vap_hpa)
        depression_mean = fitter.monthly("dew_point_depression_mean_degc", depression, everyday, np.mean)
        depression_sd = fitter.monthly("dew_point_depression_sd_degc", depression, everyday, _sd)
    else:
        fao56_rules["vap_hpa"] = FAO56_VAP_RULE
    if np.isfinite(days.wind_m_s).any():
        wind_gamma = fitter.monthly("wind", days.wind_m_s, everyday, _gamma_moments)
        wind_shape, wind_scale = [g[0] for g in wind_gamma], [g[1] for g in wind_gamma]
    else:
        fao56_rules["wind_m_s"] = FAO56_WIND_RULE

    metadata = {
        "fitted_by": "crop-sim fit-weather (crop_sim_ros.weather.fit)",
        "data": "sources are relative to the reference data directory (shared/data, see its README.md)",
        "fitted_from": [_data_summary(s) for s in series_list],
        "min_days_per_statistic": MIN_DAYS_PER_STATISTIC,
        "pooled_months": fitter.pooling,
        "note": "monthly statistics pool all files' days of a calendar month; a month listed under "
                "pooled_months had fewer than min_days_per_statistic own days of that variable and uses "
                "the listed (nearest) months' days instead",
    }
    # Only when they apply, so that a fit with neither writes the same file as before they existed.
    if repeats:
        metadata["repeats_not_fitted"] = repeats
    if fao56_rules:
        metadata["fao56_missing_data_rules"] = fao56_rules
    return GeneratorParameters(
        name=name, site=series_list[0].site, wet_day_threshold_mm=threshold_mm,
        p_wet_after_dry=p_wet_after_dry, p_wet_after_wet=p_wet_after_wet,
        rain_excess_shape=[g[0] for g in rain_gamma], rain_excess_scale_mm=[g[1] for g in rain_gamma],
        residual_lag0_correlation=lag0, residual_lag1_correlation=lag1,
        dew_point_depression_mean_degc=depression_mean, dew_point_depression_sd_degc=depression_sd,
        wind_shape=wind_shape, wind_scale_m_s=wind_scale,
        metadata=metadata, **values)


def _data_summary(series: WeatherSeries) -> dict:
    """Source, first and last day with data, days with data and the variables of ``series``."""
    has_value = np.isfinite(np.stack([getattr(series, name) for name in VARIABLES])).any(axis=0)
    with_data = series.dates[has_value]
    return {"source": series.source, "first_day": str(with_data[0]), "last_day": str(with_data[-1]),
            "days": int(has_value.sum()),
            "variables": [v for v in ("tmax_degc", "tmin_degc", "srad_mj_m2", "rain_mm", "vap_hpa", "wind_m_s")
                          if np.isfinite(getattr(series, v)).any()]}


# name -> (how it is computed, unit)
STATISTICS = {
    "tmax_degc": ("mean TMAX", "degC"),
    "tmin_degc": ("mean TMIN", "degC"),
    "srad_mj_m2": ("mean SRAD", "MJ/m2/d"),
    "wet_fraction": ("fraction of wet days", "-"),
    "rain_total_mm": ("mean monthly rain total", "mm"),
    "vap_hpa": ("mean vapour pressure", "hPa"),
    "wind_m_s": ("mean wind at 2 m", "m/s"),
}


def monthly_statistics(series_list: list[WeatherSeries],
                       threshold_mm: float = WET_DAY_THRESHOLD_MM) -> dict[str, np.ndarray]:
    """Per calendar month (12 values, NaN without data) the statistics of :data:`STATISTICS`.

    The monthly rain total is the mean daily rain times the mean month length.
    """
    days = _Days(series_list, threshold_mm)

    def by_month(values: np.ndarray) -> np.ndarray:
        finite = np.isfinite(values)
        counts = np.bincount(days.month[finite], minlength=MONTHS)
        sums = np.bincount(days.month[finite], weights=values[finite], minlength=MONTHS)
        with np.errstate(invalid="ignore", divide="ignore"):
            return sums / np.where(counts > 0, counts, np.nan)

    return {"tmax_degc": by_month(days.tmax_degc), "tmin_degc": by_month(days.tmin_degc),
            "srad_mj_m2": by_month(days.srad_mj_m2),
            "wet_fraction": by_month(np.where(days.has_rain, days.wet, np.nan)),
            "rain_total_mm": by_month(days.rain_mm) * MONTH_LENGTH_DAYS,
            "vap_hpa": by_month(days.vap_hpa), "wind_m_s": by_month(days.wind_m_s)}


def comparison_table(observed: dict[str, np.ndarray], generated: dict[str, np.ndarray]) -> str:
    """A text table, one row per month, "observed / generated" for each statistic."""
    header = "month " + " ".join(f"{name:>17}" for name in STATISTICS)
    lines = [header, "      " + " ".join(f"{'obs / gen ' + unit:>17}" for _, unit in STATISTICS.values())]
    for month in range(MONTHS):
        cells = []
        for name in STATISTICS:
            obs, gen = observed[name][month], generated[name][month]
            cells.append(f"{'-' if np.isnan(obs) else f'{obs:.2f}':>8} / {gen:6.2f}")
        lines.append(f"{MONTH_NAMES[month]:<5} " + " ".join(f"{cell:>17}" for cell in cells))
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from ..task.scenario import MAX_GENERATED_SEASONS
    from ..usage import UsageError, check_range, one_line
    check_range("--check-seasons", args.check_seasons, 1, MAX_GENERATED_SEASONS)  # before anything is written
    check_range("--seed", args.seed, 0, 2**32 - 1)
    try:
        observed = load_observed(args.data, *observed_files(args.agweathernet, args.dssat))
        params = fit_parameters(observed, args.name)
    except WeatherError as error:  # the files given (or their absence): the user's
        raise UsageError(one_line(error)) from None
    out = args.out or BENTON_PARAMETERS_FILE.with_name(args.name + PARAMETERS_SUFFIX)
    params.to_json(out)
    print(f"wrote {out} (fitted from {', '.join(s.source for s in observed)} under {args.data})")
    for repeat in params.metadata.get("repeats_not_fitted", []):
        print(f"  not fitted, a repeat: {repeat['source']} {repeat['what']} ({repeat['days']} days) "
              f"= {repeat['same_as']}")
    for label, months in params.metadata["pooled_months"].items():
        print(f"  {label}: " + ", ".join(f"{m} from {'+'.join(p)}" for m, p in months.items()))
    for rule in params.metadata.get("fao56_missing_data_rules", {}).values():
        print(f"  {rule}")
    generated = generate_seasons(params, date(2001, 1, 1), 365, args.check_seasons, args.seed)
    print(f"\nmonthly statistics, observed (distinct station-days) / generated ({args.check_seasons} years, "
          f"seed {args.seed}):")
    print(comparison_table(monthly_statistics(distinct_station_days(observed)[0]), monthly_statistics(generated)))
    return 0
