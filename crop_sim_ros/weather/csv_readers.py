"""Comma-separated daily weather: the project's plain CSV (read and write) and NASA POWER daily point CSV.

Plain CSV (:func:`read_plain_csv`, :func:`write_plain_csv`)::

    # name: Benton E., WA
    # latitude_deg: 46.2
    # longitude_deg: -119.2
    # elevation_m: 200
    date,tmax_degc,tmin_degc,srad_mj_m2,rain_mm,tavg_degc,vap_hpa,wind_m_s
    2000-04-01,25.8,6.5,19.24,0.0,15.6,8.0,1.6

Leading ``# key: value`` comment lines give the site (latitude and longitude in degrees north and east,
elevation in m; the name defaults to the file stem); other comment lines are ignored. The columns
``date`` (ISO, consecutive days), ``tmax_degc``, ``tmin_degc`` (degC), ``srad_mj_m2`` (MJ m-2 d-1) and
``rain_mm`` (mm) are required, ``tavg_degc`` (degC), ``vap_hpa`` (hPa) and ``wind_m_s`` (m s-1, at 2 m)
optional, in any order; an empty cell is a missing value (NaN).

NASA POWER (:func:`read_nasa_power_csv`): the daily point CSV of https://power.larc.nasa.gov. The block
between ``-BEGIN HEADER-`` and ``-END HEADER-`` carries latitude, longitude, elevation, the missing-value
mark (-999) and each parameter's unit; then a column line (``YEAR,DOY,...`` or ``YEAR,MO,DY,...``).
Used: T2M_MAX, T2M_MIN, ALLSKY_SFC_SW_DWN (MJ m-2 d-1; kW-hr m-2 d-1 is converted), PRECTOTCORR (mm d-1;
PRECTOT in older files) required; T2M, WS2M (m s-1, 2 m) optional; vapour pressure from T2MDEW (degC),
else QV2M (specific humidity, g/kg or kg/kg, with PS in kPa or the FAO-56 pressure of the elevation), else
RH2M (%) with T2M. Other columns are ignored.

Every problem raises :class:`WeatherError` naming the file, line and column; impossible values are found
by :meth:`WeatherSeries.require` (missing values are allowed: require them on the window you simulate).
"""

from __future__ import annotations

import csv
import math
import re
from datetime import date, timedelta
from pathlib import Path

import numpy as np
from refet.calcs import actual_vapor_pressure, air_pressure

from .readers import read_weather_text
from .series import Site, WeatherError, WeatherSeries, make_series, saturation_vapour_pressure_hpa

PLAIN_REQUIRED = ("date", "tmax_degc", "tmin_degc", "srad_mj_m2", "rain_mm")
PLAIN_OPTIONAL = ("tavg_degc", "vap_hpa", "wind_m_s")
PLAIN_SITE_KEYS = ("name", "latitude_deg", "longitude_deg", "elevation_m")
HPA_PER_KPA = 10.0
NASA_MISSING = -999.0
# NASA POWER column -> {unit as the header writes it: factor to this project's unit}
NASA_UNITS = {
    "T2M_MAX": {"C": 1.0}, "T2M_MIN": {"C": 1.0}, "T2M": {"C": 1.0}, "T2MDEW": {"C": 1.0},
    "ALLSKY_SFC_SW_DWN": {"MJ/m^2/day": 1.0, "kW-hr/m^2/day": 3.6},
    "PRECTOTCORR": {"mm/day": 1.0}, "PRECTOT": {"mm/day": 1.0}, "WS2M": {"m/s": 1.0},
    "QV2M": {"g/kg": 1e-3, "kg/kg": 1.0}, "RH2M": {"%": 1.0}, "PS": {"kPa": 1.0},
}
# Unit assumed when the header does not list a column (the API's current default units).
NASA_DEFAULT_UNITS = {"ALLSKY_SFC_SW_DWN": "MJ/m^2/day", "QV2M": "g/kg"}


def _cells(line: str) -> list[str]:
    return [cell.strip() for cell in next(csv.reader([line]))]


def _number(cell: str, where: str, missing: float | None = None) -> float:
    """``cell`` as a float; "" and values at or below ``missing`` are NaN."""
    if cell == "":
        return math.nan
    try:
        value = float(cell)
    except ValueError:
        raise WeatherError(f"{where}: {cell!r} is not a number") from None
    return math.nan if missing is not None and value <= missing else value


def _append_day(dates: list[date], day: date, where: str) -> None:
    """Append ``day`` after checking it follows the previous one (WeatherError naming ``where`` if not)."""
    if dates and day != dates[-1] + timedelta(days=1):
        raise WeatherError(f"{where}: {day} does not follow {dates[-1]} (days must be consecutive)")
    dates.append(day)


def _rows(lines: list[str], header_index: int, source: str, columns: list[str]):
    """(line number, {column: cell}) of each non-blank line after the column line."""
    for number, line in enumerate(lines[header_index + 1:], start=header_index + 2):
        if not line.strip():
            continue
        cells = _cells(line)
        if len(cells) < len(columns):
            raise WeatherError(f"{source}, line {number}, column {columns[len(cells)]}: no cell "
                               f"({len(cells)} cells for {len(columns)} columns)")
        if len(cells) > len(columns):
            raise WeatherError(f"{source}, line {number}, column {columns[-1]}: cells after the last column "
                               f"({len(cells)} cells for {len(columns)} columns)")
        yield number, dict(zip(columns, cells))


def _finish(series: WeatherSeries) -> WeatherSeries:
    series.require(())  # impossible values only; missing ones are the caller's to require
    return series


def read_plain_csv(path: str | Path, site: Site | None = None) -> WeatherSeries:
    """Read the plain daily CSV (see the module docstring); ``site`` overrides the comment lines."""
    path = Path(path)
    source = str(path)
    lines = read_weather_text(path).splitlines()
    comments: dict[str, tuple[int, str]] = {}
    header_index = None
    for index, line in enumerate(lines):
        text = line.strip()
        if text.startswith("#"):
            key, colon, value = text[1:].partition(":")
            if colon and key.strip() in PLAIN_SITE_KEYS:
                comments[key.strip()] = (index + 1, value.strip())
        elif text:
            header_index = index
            break
    if header_index is None:
        raise WeatherError(f"{source}: no column line ({','.join(PLAIN_REQUIRED)})")
    columns = _cells(lines[header_index])
    for column in columns:
        if column not in PLAIN_REQUIRED + PLAIN_OPTIONAL or columns.count(column) > 1:
            raise WeatherError(f"{source}, line {header_index + 1}, column {column}: unknown or repeated column "
                               f"(known: {', '.join(PLAIN_REQUIRED + PLAIN_OPTIONAL)})")
    for column in PLAIN_REQUIRED:
        if column not in columns:
            raise WeatherError(f"{source}, line {header_index + 1}, column {column}: required column is missing")
    if site is None:
        site = _plain_site(comments, path)

    dates, line_numbers = [], []
    values = {column: [] for column in columns if column != "date"}
    for number, row in _rows(lines, header_index, source, columns):
        where = f"{source}, line {number}, column "
        try:
            day = date.fromisoformat(row["date"])
        except ValueError:
            raise WeatherError(f"{where}date: {row['date']!r} is not an ISO date (YYYY-MM-DD)") from None
        _append_day(dates, day, where + "date")
        for column in values:
            values[column].append(_number(row[column], where + column))
        line_numbers.append(number)
    if not dates:
        raise WeatherError(f"{source}: no daily rows after the column line {header_index + 1}")
    return _finish(make_series(site, dates, source=source, line_numbers=line_numbers, **values))


def _plain_site(comments: dict[str, tuple[int, str]], path: Path) -> Site:
    numbers = {}
    for key in PLAIN_SITE_KEYS[1:]:
        if key not in comments:
            raise WeatherError(f"{path}: no '# {key}: ...' comment line and no site given")
        number, text = comments[key]
        numbers[key] = _number(text, f"{path}, line {number}, column {key}")
        if not math.isfinite(numbers[key]):
            raise WeatherError(f"{path}, line {number}, column {key}: empty value")
    try:
        return Site(comments.get("name", (0, path.stem))[1], **numbers)
    except WeatherError as error:
        raise WeatherError(f"{path}, line {comments['latitude_deg'][0]}: {error}") from None


def _format(value: float) -> str:
    return "" if not math.isfinite(value) else repr(float(value))


def write_plain_csv(series: WeatherSeries, path: str | Path) -> None:
    """Write ``series`` as plain CSV (all columns; NaN as an empty cell; floats exactly, read back equal)."""
    site = series.site
    lines = [f"# name: {site.name}", f"# latitude_deg: {site.latitude_deg!r}",
             f"# longitude_deg: {site.longitude_deg!r}", f"# elevation_m: {site.elevation_m!r}",
             f"# source: {series.source}", ",".join(PLAIN_REQUIRED + PLAIN_OPTIONAL)]
    columns = [getattr(series, name) for name in PLAIN_REQUIRED[1:] + PLAIN_OPTIONAL]
    for i, day in enumerate(series.dates):
        lines.append(",".join([str(day)] + [_format(column[i]) for column in columns]))
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")


def _nasa_header(lines: list[str], source: str):
    """(index of the column line, {parameter: (unit, line number)}, latitude/longitude/elevation,
    missing-value mark)."""
    try:
        begin = next(i for i, line in enumerate(lines) if line.strip() == "-BEGIN HEADER-")
        end = next(i for i in range(begin, len(lines)) if lines[i].strip() == "-END HEADER-")
    except StopIteration:
        raise WeatherError(f"{source}: no '-BEGIN HEADER-' ... '-END HEADER-' block") from None
    units, location, missing = {}, {"latitude_deg": None, "longitude_deg": None, "elevation_m": None}, NASA_MISSING
    numeric = r"(-?\d+(?:\.\d*)?)"
    for number, line in enumerate(lines[begin + 1:end], start=begin + 2):
        if match := re.search(rf"Latitude\s+{numeric}\s+Longitude\s+{numeric}", line):
            location["latitude_deg"], location["longitude_deg"] = float(match[1]), float(match[2])
        elif line.lstrip().startswith("Elevation") and (match := re.search(rf"=\s*{numeric}\s*met", line)):
            location["elevation_m"] = float(match[1])
        elif "missing" in line.lower() and (match := re.search(rf":\s*{numeric}\s*$", line.strip())):
            missing = float(match[1])
        elif match := re.match(r"\s*([A-Z0-9_]+)\s+.*\(([^()]*)\)\s*$", line):
            units[match[1]] = (match[2].strip(), number)
    return end + 1, units, location, missing


def read_nasa_power_csv(path: str | Path, site: Site | None = None) -> WeatherSeries:
    """Read a NASA POWER daily point CSV (see the module docstring); ``site`` overrides the header's."""
    path = Path(path)
    source = str(path)
    lines = read_weather_text(path).splitlines()
    header_index, units, location, missing = _nasa_header(lines, source)
    if site is None:
        absent = [key for key, value in location.items() if value is None]
        if absent:
            raise WeatherError(f"{source}: the header gives no {', '.join(absent)} and no site was passed")
        site = Site(f"NASA POWER {location['latitude_deg']:g}N {location['longitude_deg']:g}E", **location)
    if header_index >= len(lines):
        raise WeatherError(f"{source}: no column line after '-END HEADER-'")
    columns = _cells(lines[header_index])
    column_line = f"{source}, line {header_index + 1}"
    date_columns = ("YEAR", "DOY") if "DOY" in columns else ("YEAR", "MO", "DY")
    precipitation = "PRECTOTCORR" if "PRECTOTCORR" in columns or "PRECTOT" not in columns else "PRECTOT"
    for column in date_columns + ("T2M_MAX", "T2M_MIN", "ALLSKY_SFC_SW_DWN", precipitation):
        if column not in columns:
            raise WeatherError(f"{column_line}, column {column}: required column is missing")
    used = [c for c in columns if c in NASA_UNITS]
    factors = {}
    for column in used:
        unit, unit_line = units.get(column, (NASA_DEFAULT_UNITS.get(column, next(iter(NASA_UNITS[column]))), 0))
        if unit not in NASA_UNITS[column]:
            raise WeatherError(f"{source}, line {unit_line}, column {column}: unit {unit!r} is not one of "
                               f"{', '.join(NASA_UNITS[column])}")
        factors[column] = NASA_UNITS[column][unit]

    dates, line_numbers = [], []
    values = {column: [] for column in used}
    for number, row in _rows(lines, header_index, source, columns):
        where = f"{source}, line {number}, column "
        _append_day(dates, _nasa_date(row, date_columns, where), where + date_columns[-1])
        for column in used:
            values[column].append(_number(row[column], where + column, missing) * factors[column])
        line_numbers.append(number)
    if not dates:
        raise WeatherError(f"{column_line}: no daily rows after the column line")
    table = {column: np.array(v, dtype=float) for column, v in values.items()}
    return _finish(make_series(site, dates, source=source, line_numbers=line_numbers,
                               tmax_degc=table["T2M_MAX"], tmin_degc=table["T2M_MIN"], tavg_degc=table.get("T2M"),
                               srad_mj_m2=table["ALLSKY_SFC_SW_DWN"], rain_mm=table[precipitation],
                               vap_hpa=_nasa_vapour_pressure_hpa(table, site.elevation_m),
                               wind_m_s=table.get("WS2M")))


def _nasa_date(row: dict[str, str], date_columns: tuple[str, ...], where: str) -> date:
    cells = [row[column] for column in date_columns]
    if not all(cell.isdigit() for cell in cells):
        bad = next(c for c, cell in zip(date_columns, cells) if not cell.isdigit())
        raise WeatherError(f"{where}{bad}: {row[bad]!r} is not a whole number")
    year, *rest = (int(cell) for cell in cells)
    try:
        if len(rest) == 1:
            if not 1 <= rest[0] <= (date(year, 12, 31) - date(year, 1, 1)).days + 1:
                raise ValueError(f"day of year {rest[0]} is outside {year}")
            return date(year, 1, 1) + timedelta(days=rest[0] - 1)
        return date(year, *rest)
    except ValueError as error:
        raise WeatherError(f"{where}{date_columns[-1]}: {'-'.join(cells)} is not a date ({error})") from None


def _nasa_vapour_pressure_hpa(table: dict[str, np.ndarray], elevation_m: float) -> np.ndarray | None:
    """Actual vapour pressure, hPa, from the dew point, else specific humidity, else relative humidity."""
    if "T2MDEW" in table:
        return saturation_vapour_pressure_hpa(table["T2MDEW"])
    if "QV2M" in table:
        pressure_kpa = table["PS"] if "PS" in table else air_pressure(elevation_m)
        return actual_vapor_pressure(table["QV2M"], pressure_kpa) * HPA_PER_KPA
    if "RH2M" in table and "T2M" in table:
        return table["RH2M"] / 100.0 * saturation_vapour_pressure_hpa(table["T2M"])
    return None

