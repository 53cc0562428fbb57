"""Readers of daily weather files. Each returns a :class:`WeatherSeries` or raises :class:`WeatherError`
naming the file, line and column of the first problem.

- :func:`read_dssat_wth`: DSSAT ``.WTH`` (header with INSI, LAT, LONG, ELEV, ...; DATE as YYDDD or YYYYDDD;
  SRAD MJ m-2, TMAX/TMIN degC, RAIN mm; optional DEWP degC, WIND km d-1, VPRS/VAPR hPa/kPa); -99 is missing.
- :func:`read_agweathernet_csv`: AgWeatherNet daily CSV export (units in the header; "NA" is missing).
"""

from __future__ import annotations

import csv
import math
from datetime import date, timedelta
from pathlib import Path

import numpy as np

from .series import Site, WeatherError, WeatherSeries, make_series, saturation_vapour_pressure_hpa

DSSAT_MISSING = -99.0
KM_PER_DAY_PER_M_S = 86.4
# Two-digit DSSAT years up to this belong to the 2000s (the SIMPLE set spans 1970-2009).
DSSAT_CENTURY_PIVOT = 40


def dssat_date(code: str | int, source: str = "date") -> date:
    """A DSSAT date, YYDDD (two-digit year, pivot 40) or YYYYDDD, as a calendar date."""
    text = str(code).strip()
    if not text.isdigit() or len(text) not in (4, 5, 7):
        raise WeatherError(f"{source}: {code!r} is not a DSSAT date (YYDDD or YYYYDDD)")
    value = int(text)
    year, day = divmod(value, 1000)
    if len(text) != 7:
        year += 2000 if year <= DSSAT_CENTURY_PIVOT else 1900
    if not 1 <= day <= (366 if _leap(year) else 365):
        raise WeatherError(f"{source}: {code!r} has day of year {day}, outside the year {year}")
    return date(year, 1, 1) + timedelta(days=day - 1)


def _leap(year: int) -> bool:
    return year % 4 == 0 and (year % 100 != 0 or year % 400 == 0)


def wind_at_2m(wind_m_s, height_m: float):
    """FAO-56 eq. 47: wind measured at ``height_m`` converted to 2 m."""
    return np.asarray(wind_m_s, dtype=float) * 4.87 / math.log(67.8 * height_m - 5.42)


def read_dssat_wth(path: str | Path) -> WeatherSeries:
    """Read a DSSAT ``.WTH`` file (see the module docstring)."""
    path = Path(path)
    source = str(path)
    try:
        lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError as error:
        raise WeatherError(f"{source}: cannot read: {error}") from None
    site_header = next((i for i, line in enumerate(lines) if line.lstrip().startswith("@") and "INSI" in line), None)
    if site_header is None or site_header + 1 >= len(lines):
        raise WeatherError(f"{source}: no '@ INSI LAT LONG ELEV' site header")
    names = lines[site_header].lstrip("@ ").split()
    values = lines[site_header + 1].split()
    site_values = dict(zip(names, values))
    try:
        latitude, longitude, elevation = (float(site_values[k]) for k in ("LAT", "LONG", "ELEV"))
    except (KeyError, ValueError):
        raise WeatherError(f"{source}, line {site_header + 2}: site line lacks numeric LAT, LONG, ELEV: "
                           f"{lines[site_header + 1].strip()!r}") from None
    wind_height = float(site_values.get("WNDHT", DSSAT_MISSING))
    site = Site(site_values.get("INSI", path.stem), latitude, longitude, max(elevation, 0.0))

    column_line = next((i for i in range(site_header + 2, len(lines))
                        if lines[i].lstrip("@ ").upper().startswith("DATE")), None)
    if column_line is None:
        raise WeatherError(f"{source}: no 'DATE SRAD TMAX TMIN RAIN' column header")
    columns = lines[column_line].lstrip("@ ").split()
    for required in ("DATE", "SRAD", "TMAX", "TMIN", "RAIN"):
        if required not in columns:
            raise WeatherError(f"{source}, line {column_line + 1}: column {required} is missing "
                               f"(columns: {' '.join(columns)})")
    dates, line_numbers, rows = [], [], []
    for number, line in enumerate(lines[column_line + 1:], start=column_line + 2):
        if not line.strip() or line.lstrip().startswith(("!", "*", "@")):
            continue
        cells = line.split()
        if len(cells) < len(columns):
            raise WeatherError(f"{source}, line {number}: {len(cells)} values for {len(columns)} columns "
                               f"({' '.join(columns)})")
        dates.append(dssat_date(cells[0], f"{source}, line {number}, column DATE"))
        row = []
        for column, cell in zip(columns[1:], cells[1:len(columns)]):
            try:
                value = float(cell)
            except ValueError:
                raise WeatherError(f"{source}, line {number}, column {column}: {cell!r} is not a number") from None
            row.append(math.nan if value <= DSSAT_MISSING else value)
        rows.append(row)
        line_numbers.append(number)
    if not rows:
        raise WeatherError(f"{source}: no daily rows after the column header")
    table = dict(zip(columns[1:], np.array(rows, dtype=float).T))
    vap = None
    if "VPRS" in table:
        vap = table["VPRS"]
    elif "VAPR" in table:
        vap = table["VAPR"] * 10.0  # kPa -> hPa
    elif "DEWP" in table:
        vap = saturation_vapour_pressure_hpa(table["DEWP"])
    wind = None
    if "WIND" in table:
        wind = table["WIND"] / KM_PER_DAY_PER_M_S
        if wind_height > 0 and wind_height != 2.0:
            wind = wind_at_2m(wind, wind_height)
    return make_series(site, dates, source=source, line_numbers=line_numbers,
                       tmax_degc=table["TMAX"], tmin_degc=table["TMIN"], srad_mj_m2=table["SRAD"],
                       rain_mm=table["RAIN"], vap_hpa=vap, wind_m_s=wind,
                       tavg_degc=table.get("TAVG"))


# AgWeatherNet export: the header repeats names ("Min°C" for air and soil), so columns go by position.
_AWN_COLUMNS = {"date": 0, "tmin_degc": 2, "tavg_degc": 3, "tmax_degc": 4, "dewpoint_degc": 5,
                "wind_m_s": 9, "rain_mm": 15, "srad_mj_m2": 16, "eto_mm": 17}
_AWN_HEADER_CHECKS = {2: "Min", 3: "Avg", 4: "Max", 5: "DP", 9: "Speed", 15: "Prec", 16: "Solar", 17: "ETo"}
# Benton E. station (AgWeatherNet), approximate: the file itself carries no coordinates.
BENTON_E_SITE = Site("Benton E. (AgWeatherNet), WA", 46.2, -119.2, 200.0)


def read_agweathernet_csv(path: str | Path, site: Site = BENTON_E_SITE) -> WeatherSeries:
    """Read an AgWeatherNet daily CSV export. Vapour pressure comes from the 1.5 m dew point."""
    path = Path(path)
    source = str(path)
    try:
        with path.open(newline="", encoding="utf-8", errors="replace") as handle:
            rows = list(csv.reader(handle))
    except OSError as error:
        raise WeatherError(f"{source}: cannot read: {error}") from None
    if not rows:
        raise WeatherError(f"{source}: empty file")
    header = rows[0]
    for index, fragment in _AWN_HEADER_CHECKS.items():
        if index >= len(header) or fragment not in header[index]:
            raise WeatherError(f"{source}, line 1, column {index + 1}: expected a header containing "
                               f"{fragment!r}, got {header[index] if index < len(header) else None!r}")
    dates, line_numbers = [], []
    values = {name: [] for name in _AWN_COLUMNS if name != "date"}
    for number, row in enumerate(rows[1:], start=2):
        if not any(cell.strip() for cell in row):
            continue
        if len(row) < len(header):
            raise WeatherError(f"{source}, line {number}: {len(row)} cells for {len(header)} columns")
        try:
            dates.append(date.fromisoformat(row[0].replace("/", "-")))
        except ValueError:
            raise WeatherError(f"{source}, line {number}, column {header[0]}: {row[0]!r} is not a date") from None
        for name, index in _AWN_COLUMNS.items():
            if name == "date":
                continue
            cell = row[index].strip()
            try:
                values[name].append(math.nan if cell in ("NA", "") else float(cell))
            except ValueError:
                raise WeatherError(f"{source}, line {number}, column {header[index]!r}: {cell!r} "
                                   "is not a number") from None
        line_numbers.append(number)
    arrays = {k: np.array(v, dtype=float) for k, v in values.items()}
    return make_series(site, dates, source=source, line_numbers=line_numbers,
                       tmax_degc=arrays["tmax_degc"], tmin_degc=arrays["tmin_degc"],
                       tavg_degc=arrays["tavg_degc"], srad_mj_m2=arrays["srad_mj_m2"],
                       rain_mm=arrays["rain_mm"], wind_m_s=arrays["wind_m_s"],
                       vap_hpa=saturation_vapour_pressure_hpa(arrays["dewpoint_degc"]))


def read_agweathernet_reference_et0(path: str | Path) -> np.ndarray:
    """The station's own Penman-Monteith ETo column, mm d-1 (a cross-check for ours)."""
    with Path(path).open(newline="", encoding="utf-8", errors="replace") as handle:
        rows = list(csv.reader(handle))[1:]
    index = _AWN_COLUMNS["eto_mm"]
    return np.array([math.nan if r[index] in ("NA", "") else float(r[index]) for r in rows if r], dtype=float)
