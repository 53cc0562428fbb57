"""The DSSAT .WTH reader on every file of the SIMPLE input set and on malformed content."""

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


@pytest.mark.parametrize("path", WEATHER_FILES, ids=lambda p: p.name)
def test_every_shared_weather_file_reads(path):
    series = read_dssat_wth(path)
    assert len(series) > 30
    assert np.all(np.diff(series.dates).astype(int) == 1)
    assert np.isfinite(series.tmax_degc).mean() > 0.25


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


def test_missing_inside_a_window_names_file_line_and_column(tmp_path):
    path = write(tmp_path, "08001  11.0  20.0   5.0   0.0   1.0 100.0\n08002   -99  20.0   5.0   0.0\n")
    with pytest.raises(WeatherError, match=r"TEST0101\.WTH, line 7, column srad_mj_m2"):
        read_dssat_wth(path).require()
