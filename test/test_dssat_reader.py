"""The DSSAT .WTH reader on every file of the SIMPLE input set and on malformed content."""

import math
from pathlib import Path

import numpy as np
import pytest

from crop_sim_ros.weather import WeatherError, read_dssat_wth

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
WEATHER_FILES = sorted((DATA / "simple_r_inputs" / "Weather").glob("*"))

HEADER = ("*WEATHER DATA : test\n\n@ INSI      LAT     LONG  ELEV   TAV   AMP REFHT WNDHT\n"
          "  TEST  33.069   -114.53   361  21.2  11.1 -99.0 -99.0\n"
          "@DATE  SRAD  TMAX  TMIN  RAIN  DEWP  WIND\n")


def write(tmp_path, body: str) -> Path:
    path = tmp_path / "TEST0101.WTH"
    path.write_text(HEADER + body)
    return path


def test_the_shared_weather_folder_is_there(shared_data):
    assert len(WEATHER_FILES) == 54  # every file below is read by the next test


MODEL_COLUMNS = {"SRAD": "srad_mj_m2", "TMAX": "tmax_degc", "TMIN": "tmin_degc", "RAIN": "rain_mm"}


def model_columns_by_line(path: Path) -> dict[int, list[float]]:
    """{line number: [SRAD, TMAX, TMIN, RAIN]} of every data line, NaN for DSSAT's -99, read on its own:
    in every file of the set the header starts DATE SRAD TMAX TMIN RAIN and only trailing cells are blank,
    so these are a data line's first five words."""
    rows, header = {}, None
    for number, line in enumerate(path.read_text(encoding="latin-1").splitlines(), start=1):
        words = line.split()
        if words and words[0].lstrip("@") == "DATE":
            header = [w.lstrip("@") for w in words]
            assert header[:5] == ["DATE", *MODEL_COLUMNS], path
        elif header and words and words[0].isdigit():
            rows[number] = [math.nan if float(w) == -99 else float(w) for w in words[1:5]]
    return rows


@pytest.mark.parametrize("path", WEATHER_FILES, ids=lambda p: p.name)
def test_every_shared_weather_file_reads_every_value(path):
    series = read_dssat_wth(path)
    assert np.all(np.diff(series.dates).astype(int) == 1)
    expected = model_columns_by_line(path)
    day_of_line = {int(line): day for day, line in enumerate(series.line_numbers) if line}
    assert sorted(day_of_line) == sorted(expected)  # one day per data line
    days = [day_of_line[line] for line in expected]
    for j, name in enumerate(MODEL_COLUMNS.values()):
        np.testing.assert_array_equal(getattr(series, name)[days], [row[j] for row in expected.values()],
                                      err_msg=name)
    between_blocks = series.line_numbers == 0
    assert np.all(np.isnan(series.tmax_degc[between_blocks]))


@pytest.mark.usefixtures("shared_data")
def test_missing_value_rows_of_the_set_are_nan():
    # MAR29201.WTH starts with days whose four model values are all -99.
    series = read_dssat_wth(DATA / "simple_r_inputs" / "Weather" / "MAR29201.WTH")
    first = {name: getattr(series, name)[0] for name in MODEL_COLUMNS.values()}
    assert all(np.isnan(value) for value in first.values()), first


@pytest.mark.usefixtures("shared_data")
def test_blocks_out_of_order_are_sorted_and_keep_their_lines():
    series = read_dssat_wth(DATA / "simple_r_inputs" / "Weather" / "AUHU9801.WTH")
    assert str(series.start) == "1997-12-31" and str(series.end) == "1999-12-31"
    assert series.line_numbers[0] == 736 and series.line_numbers[1] == 6
    assert series.tmax_degc[0] == pytest.approx(-0.1)


@pytest.mark.usefixtures("shared_data")
def test_blank_fixed_width_cells_are_missing_values():
    series = read_dssat_wth(DATA / "simple_r_inputs" / "Weather" / "BDIS8103.WTH")
    assert np.isfinite(series.tmax_degc).all()
    assert np.isnan(series.wind_m_s).all()


def test_days_between_blocks_are_missing_and_reported_where_needed(tmp_path):
    path = write(tmp_path, "08003  11.0  20.0   5.0   0.0   1.0 100.0\n"
                           "08001  11.0  20.0   5.0   0.0   1.0 100.0\n")
    series = read_dssat_wth(path)
    assert len(series) == 3 and np.isnan(series.srad_mj_m2[1]) and series.line_numbers[1] == 0
    with pytest.raises(WeatherError, match="2008-01-02"):
        series.require()


def test_overlapping_blocks_raise_naming_file_lines_and_column(tmp_path):
    path = write(tmp_path, "08001  11.0  20.0   5.0   0.0   1.0 100.0\n"
                           "08002  11.0  20.0   5.0   0.0   1.0 100.0\n"
                           "08002  12.0  21.0   5.0   0.0   1.0 100.0\n")
    with pytest.raises(WeatherError, match=r"TEST0101\.WTH, line 8, column DATE: .*line 7"):
        read_dssat_wth(path)


def test_a_value_that_is_not_a_number_names_file_line_and_column(tmp_path):
    path = write(tmp_path, "08001  11.0  20.0   5.0   0.0   1.0 100.0\n08002  11.0  2x.0   5.0   0.0   1.0 100.0\n")
    with pytest.raises(WeatherError, match=r"TEST0101\.WTH, line 7, column TMAX: '2x\.0' is not a number"):
        read_dssat_wth(path)


def test_a_short_line_off_the_fixed_layout_names_file_line_and_column(tmp_path):
    path = write(tmp_path, "08001 11.0 20.0 5.0 0.0\n")
    with pytest.raises(WeatherError, match=r"TEST0101\.WTH, line 6, column \w+: 5 values for 7 columns"):
        read_dssat_wth(path)


def test_a_bad_date_names_file_line_and_column(tmp_path):
    path = write(tmp_path, "08400  11.0  20.0   5.0   0.0   1.0 100.0\n")
    with pytest.raises(WeatherError, match=r"TEST0101\.WTH, line 6, column DATE"):
        read_dssat_wth(path)


@pytest.mark.parametrize("column, name", [(1, "srad_mj_m2"), (2, "tmax_degc"), (3, "tmin_degc"), (4, "rain_mm")])
def test_minus_99_is_a_missing_value_named_by_file_line_and_column(tmp_path, column, name):
    cells = ["08002", "11.0", "20.0", "5.0", "0.0", "1.0", "100.0"]
    cells[column] = "-99"
    path = write(tmp_path, "08001  11.0  20.0   5.0   0.0   1.0 100.0\n" + "".join(f"{c:>6}" for c in cells)[1:] + "\n")
    series = read_dssat_wth(path)
    first_day = {"srad_mj_m2": 11.0, "tmax_degc": 20.0, "tmin_degc": 5.0, "rain_mm": 0.0}
    assert getattr(series, name)[0] == first_day[name] and np.isnan(getattr(series, name)[1])
    with pytest.raises(WeatherError, match=rf"TEST0101\.WTH, line 7, column {name}: missing value"):
        series.require()
