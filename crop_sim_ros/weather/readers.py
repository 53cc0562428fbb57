"""Readers of daily weather files. Each returns a :class:`WeatherSeries` or raises :class:`WeatherError`
naming the file, line and column of the first problem.

- :func:`read_dssat_wth`: DSSAT ``.WTH`` (header with INSI, LAT, LONG, ELEV, ...; DATE as YYDDD or YYYYDDD;
  SRAD MJ m-2, TMAX/TMIN degC, RAIN mm; optional DEWP degC, WIND km d-1, VPRS/VAPR hPa/kPa); -99 and blank
  fixed-width cells are missing; several years may come as blocks out of order.
- :func:`read_agweathernet_csv`: AgWeatherNet daily CSV export (units in the header; "NA" is missing).

Every reader takes UTF-8 text, with or without a byte-order mark, and UTF-16 or UTF-32 with one
(:func:`read_weather_text`); other bytes are a WeatherError naming the encoding problem.
"""

from __future__ import annotations

import codecs
import csv
import io
import math
from datetime import date, timedelta
from pathlib import Path

import numpy as np

from .series import Site, WeatherError, WeatherSeries, make_series, saturation_vapour_pressure_hpa

DSSAT_MISSING = -99.0
# Width of each column after DATE in DSSAT's fixed layout, characters.
DSSAT_CELL_WIDTH = 6
# Ctrl-Z: old DOS editors ended files with it.
DOS_END_OF_FILE = "\x1a"
KM_PER_DAY_PER_M_S = 86.4
# Two-digit DSSAT years up to this belong to the 2000s (the SIMPLE set spans 1970-2009).
DSSAT_CENTURY_PIVOT = 40


# Byte-order marks and their encodings; UTF-32 first: its little-endian mark begins with UTF-16's.
_BYTE_ORDER_MARKS = ((codecs.BOM_UTF32_LE, "utf-32"), (codecs.BOM_UTF32_BE, "utf-32"), (codecs.BOM_UTF8, "utf-8-sig"),
                     (codecs.BOM_UTF16_LE, "utf-16"), (codecs.BOM_UTF16_BE, "utf-16"))


def read_weather_text(path: str | Path) -> str:
    """The text of a weather file: UTF-8 (a byte-order mark is dropped), or UTF-16 / UTF-32 with a byte-order
    mark. WeatherError names the file and the problem otherwise (unreadable, not UTF-8, or UTF-16 without a
    mark, whose NUL bytes would otherwise turn into confusing column errors)."""
    try:
        data = Path(path).read_bytes()
    except OSError as error:
        raise WeatherError(f"{path}: cannot read: {error}") from None
    encoding = next((name for mark, name in _BYTE_ORDER_MARKS if data.startswith(mark)), "utf-8")
    try:
        text = data.decode(encoding)
    except UnicodeDecodeError as error:
        line = data.count(b"\n", 0, error.start) + 1
        raise WeatherError(f"{path}, line {line}: byte {error.start} (0x{data[error.start]:02x}) is not {encoding} "
                           f"text; save the file as UTF-8") from None
    if "\x00" in text:
        raise WeatherError(f"{path}, line {text.count(chr(10), 0, text.index(chr(0))) + 1}: NUL characters: "
                           "UTF-16 or UTF-32 text without a byte-order mark? Save the file as UTF-8")
    return text


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
    lines = read_weather_text(path).splitlines()
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
        line = line.replace(DOS_END_OF_FILE, "")
        if not line.strip() or line.lstrip().startswith(("!", "*", "@")):
            continue
        cells = _dssat_cells(line, columns, f"{source}, line {number}")
        dates.append(dssat_date(cells[0], f"{source}, line {number}, column DATE"))
        row = []
        for column, cell in zip(columns[1:], cells[1:]):
            try:
                value = float(cell) if cell else math.nan
            except ValueError:
                raise WeatherError(f"{source}, line {number}, column {column}: {cell!r} is not a number") from None
            row.append(math.nan if value <= DSSAT_MISSING else value)
        rows.append(row)
        line_numbers.append(number)
    if not rows:
        raise WeatherError(f"{source}: no daily rows after the column header")
    dates, line_numbers, values = _dssat_calendar(dates, line_numbers, rows, source)
    table = dict(zip(columns[1:], values.T))
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


def _dssat_cells(line: str, columns: list[str], where: str) -> list[str]:
    """The cells of one DSSAT data line, one per column ('' where a fixed-width cell is blank).

    A line with a value for every column splits on white space. A shorter line is read by DSSAT's fixed
    layout (DATE as wide as its first value, then DSSAT_CELL_WIDTH characters per column, right-aligned):
    its blank cells are missing values. A short line that does not fit that layout is an error.
    """
    cells = line.split()
    if len(cells) >= len(columns):
        return cells[:len(columns)]
    date_width = len(line) - len(line.lstrip()) + len(cells[0])
    fixed = [line[:date_width].strip()] + [
        line[date_width + DSSAT_CELL_WIDTH * i: date_width + DSSAT_CELL_WIDTH * (i + 1)].strip()
        for i in range(len(columns) - 1)]
    beyond = line[date_width + DSSAT_CELL_WIDTH * (len(columns) - 1):].strip()
    misaligned = next((i for i, cell in enumerate(fixed) if " " in cell), None)
    if beyond or misaligned is not None or [cell for cell in fixed if cell] != cells:
        column = columns[misaligned] if misaligned is not None else columns[len(cells)]
        raise WeatherError(f"{where}, column {column}: {len(cells)} values for {len(columns)} columns "
                           f"({' '.join(columns)}) and the line does not fit DSSAT's fixed layout of "
                           f"{DSSAT_CELL_WIDTH}-character columns")
    return fixed


def _dssat_calendar(dates: list[date], line_numbers: list[int], rows: list[list[float]],
                    source: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows placed on consecutive calendar days: dates, line numbers (0 for a day the file lacks) and
    values (NaN for a day the file lacks), first to last day of the file.

    A file may hold several years in blocks out of order (AUHU9801.WTH: 1998, 1999, then 1997-12-31);
    sorting by date puts them together. A day missing between blocks (IAWM9901.WTH jumps from
    1997-12-31 to 1999-01-01) is a missing value, which ``WeatherSeries.require`` reports if a season
    needs it. A day given twice (overlapping blocks) is a WeatherError naming both lines.
    """
    first = min(dates)
    offsets = np.array([(day - first).days for day in dates])
    order = np.argsort(offsets, kind="stable")
    repeated = np.flatnonzero(np.diff(offsets[order]) == 0)
    if repeated.size:
        earlier, later = sorted((order[repeated[0]], order[repeated[0] + 1]))
        raise WeatherError(f"{source}, line {line_numbers[later]}, column DATE: {dates[later]} is already on "
                           f"line {line_numbers[earlier]} (blocks of days overlap)")
    days = int(offsets.max()) + 1
    calendar = np.datetime64(first, "D") + np.arange(days)
    lines = np.zeros(days, dtype=np.int64)
    lines[offsets] = line_numbers
    values = np.full((days, len(rows[0])), np.nan)
    values[offsets] = rows
    return calendar, lines, values


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
    rows = list(csv.reader(io.StringIO(read_weather_text(path), newline="")))
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
    rows = list(csv.reader(io.StringIO(read_weather_text(path), newline="")))[1:]
    index = _AWN_COLUMNS["eto_mm"]
    return np.array([math.nan if r[index] in ("NA", "") else float(r[index]) for r in rows if r], dtype=float)
