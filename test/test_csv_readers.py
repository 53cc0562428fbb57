"""Plain CSV and NASA POWER readers: round trips, a realistic NASA POWER file, and errors that name the file,
line and column."""

from datetime import date
from pathlib import Path

import numpy as np
import pytest

from crop_sim_ros.weather.csv_readers import read_nasa_power_csv, read_plain_csv, write_plain_csv
from crop_sim_ros.weather.generator import benton_parameters, generate_season
from crop_sim_ros.weather.readers import read_agweathernet_csv
from crop_sim_ros.weather.series import VARIABLES, Site, WeatherError, make_series

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
SITE = Site("Test farm", 46.2, -119.2, 200.0)

PLAIN = """\
# name: Test farm
# latitude_deg: 46.2
# longitude_deg: -119.2
# elevation_m: 200
date,tmax_degc,tmin_degc,srad_mj_m2,rain_mm,wind_m_s
2000-04-01,25.8,6.5,19.24,0.0,1.6
2000-04-02,23.6,4.6,21.70,0.0,
2000-04-03,23.9,2.5,20.74,1.02,0.9
"""


def _assert_same_weather(a, b):
    assert a.site == b.site
    np.testing.assert_array_equal(a.dates, b.dates)
    for name in VARIABLES:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_generated_season_round_trips_exactly(tmp_path):
    season = generate_season(benton_parameters(), date(2000, 4, 1), 183, seed=3)
    path = tmp_path / "season.csv"
    write_plain_csv(season, path)
    back = read_plain_csv(path)
    _assert_same_weather(season, back)
    assert back.source == str(path)
    assert "# source: generator(benton, seed=3)" in path.read_text()


def test_observed_file_with_missing_values_round_trips(tmp_path):
    observed = read_agweathernet_csv(DATA / "agweathernet" / "benton_e_2000-04-01_2000-09-30.csv")
    observed = make_series(observed.site, observed.dates, **{name: getattr(observed, name) for name in VARIABLES
                                                             if name != "wind_m_s"})  # wind all NaN
    write_plain_csv(observed, tmp_path / "benton.csv")
    _assert_same_weather(observed, read_plain_csv(tmp_path / "benton.csv"))


def test_plain_csv_reads_site_columns_and_empty_cells(tmp_path):
    path = tmp_path / "farm.csv"
    path.write_text(PLAIN)
    series = read_plain_csv(path)
    assert series.site == SITE
    assert series.start == date(2000, 4, 1) and len(series) == 3
    np.testing.assert_array_equal(series.rain_mm, [0.0, 0.0, 1.02])
    np.testing.assert_array_equal(series.wind_m_s[[0, 2]], [1.6, 0.9])
    assert np.isnan(series.wind_m_s[1]) and np.all(np.isnan(series.vap_hpa))
    assert list(series.line_numbers) == [6, 7, 8]
    other = Site("Elsewhere", 10.0, 20.0, 5.0)
    assert read_plain_csv(path, site=other).site == other
    path.write_text("\n".join(line for line in PLAIN.splitlines() if "name" not in line))
    assert read_plain_csv(path).site.name == "farm"  # the file stem


@pytest.mark.parametrize("old, new, line, column", [
    (",rain_mm,wind_m_s", ",wind_m_s", 5, "rain_mm"),                    # missing required column
    (",rain_mm,wind_m_s", ",rain_mm,wind", 5, "wind"),                   # unknown column
    ("2000-04-02,23.6,4.6,21.70", "2000-04-02,23.6,4.6,lots", 7, "srad_mj_m2"),   # non-numeric cell
    ("2000-04-02,", "2000-04-32,", 7, "date"),                           # bad date
    ("2000-04-03,", "2000-04-04,", 8, "date"),                           # gap
    ("2000-04-03,23.9,2.5,20.74,1.02,0.9", "2000-04-03,23.9,2.5", 8, "srad_mj_m2"),  # short row
    ("2000-04-01,25.8,6.5,", "2000-04-01,5.8,6.5,", 6, "tmin_degc"),     # TMIN > TMAX
    ("0.0,1.6", "-1.0,1.6", 6, "rain_mm"),                               # negative rain
    ("# latitude_deg: 46.2", "# latitude_deg: north", 2, "latitude_deg"),  # bad site value
])
def test_malformed_plain_csv_names_file_line_and_column(tmp_path, old, new, line, column):
    assert old in PLAIN
    path = tmp_path / "broken_farm.csv"
    path.write_text(PLAIN.replace(old, new, 1))
    with pytest.raises(WeatherError) as error:
        read_plain_csv(path)
    message = str(error.value)
    assert "broken_farm.csv" in message
    assert f"line {line}" in message
    assert column in message


def test_plain_csv_without_site_or_rows_is_an_error(tmp_path):
    path = tmp_path / "nosite.csv"
    path.write_text("\n".join(line for line in PLAIN.splitlines() if "longitude" not in line))
    with pytest.raises(WeatherError, match="nosite.csv.*longitude_deg"):
        read_plain_csv(path)
    path.write_text(PLAIN.splitlines()[4] + "\n")
    with pytest.raises(WeatherError, match="nosite.csv.*no daily rows"):
        read_plain_csv(path, site=SITE)
    with pytest.raises(WeatherError, match="absent.csv.*cannot read"):
        read_plain_csv(tmp_path / "absent.csv")


NASA_HEADER = """\
-BEGIN HEADER-
NASA/POWER CERES/MERRA2 Native Resolution Daily Data
Dates (month/day/year): 12/30/2019 through 01/02/2020
Location: Latitude  46.2   Longitude -119.2
Elevation from MERRA-2: Average for 0.5 x 0.625 degree lat/lon region = 238.48 meters
The value for missing source data that cannot be computed or is outside of the sources availability range: -999
Parameter(s):
T2M_MAX               MERRA-2 Temperature at 2 Meters Maximum (C)
T2M_MIN               MERRA-2 Temperature at 2 Meters Minimum (C)
T2M                   MERRA-2 Temperature at 2 Meters (C)
ALLSKY_SFC_SW_DWN     CERES SYN1deg All Sky Surface Shortwave Downward Irradiance ({srad_unit})
PRECTOTCORR           MERRA-2 Precipitation Corrected (mm/day)
WS2M                  MERRA-2 Wind Speed at 2 Meters (m/s)
QV2M                  MERRA-2 Specific Humidity at 2 Meters (g/kg)
RH2M                  MERRA-2 Relative Humidity at 2 Meters (%)
-END HEADER-
"""
NASA_ROWS = """\
YEAR,DOY,T2M_MAX,T2M_MIN,T2M,ALLSKY_SFC_SW_DWN,PRECTOTCORR,WS2M,QV2M,RH2M
2019,364,3.52,-2.61,0.12,4.11,0.35,2.87,3.42,80.56
2019,365,5.01,-1.98,1.40,-999,1.21,3.40,3.91,84.12
2020,1,4.45,-0.37,2.03,3.02,4.02,4.11,4.27,88.25
2020,2,2.10,-4.20,-1.05,5.47,0.00,1.95,2.89,79.31
"""


def _nasa_file(tmp_path, rows=NASA_ROWS, srad_unit="MJ/m^2/day", name="POWER_Point_Daily.csv"):
    path = tmp_path / name
    path.write_text(NASA_HEADER.format(srad_unit=srad_unit) + rows)
    return path


def test_nasa_power_file_is_parsed(tmp_path):
    series = read_nasa_power_csv(_nasa_file(tmp_path))
    assert (series.site.latitude_deg, series.site.longitude_deg, series.site.elevation_m) == (46.2, -119.2, 238.48)
    assert series.start == date(2019, 12, 30) and series.end == date(2020, 1, 2)  # across the new year
    np.testing.assert_array_equal(series.tmax_degc, [3.52, 5.01, 4.45, 2.10])
    np.testing.assert_array_equal(series.tmin_degc, [-2.61, -1.98, -0.37, -4.20])
    np.testing.assert_array_equal(series.tavg_degc, [0.12, 1.40, 2.03, -1.05])
    np.testing.assert_array_equal(series.rain_mm, [0.35, 1.21, 4.02, 0.0])
    np.testing.assert_array_equal(series.wind_m_s, [2.87, 3.40, 4.11, 1.95])
    assert series.srad_mj_m2[0] == 4.11 and np.isnan(series.srad_mj_m2[1])  # -999 is missing
    # e = q p / (0.622 + 0.378 q), q = 3.42 g/kg, p = FAO-56 pressure at 238.48 m (98.5 kPa): ~5.4 hPa.
    pressure_kpa = 101.3 * ((293 - 0.0065 * 238.48) / 293) ** 5.26
    q = 3.42e-3
    assert series.vap_hpa[0] == pytest.approx(10 * q * pressure_kpa / (0.622 + 0.378 * q), rel=1e-9)
    assert 5.0 < series.vap_hpa[0] < 6.0
    assert list(series.line_numbers) == [18, 19, 20, 21]
    with pytest.raises(WeatherError, match=r"POWER_Point_Daily.csv, line 19, column srad_mj_m2: missing"):
        series.require()


def test_nasa_power_month_day_columns_dew_point_and_kwh(tmp_path):
    rows = ("YEAR,MO,DY,T2M_MAX,T2M_MIN,ALLSKY_SFC_SW_DWN,PRECTOTCORR,T2MDEW\n"
            "2020,2,28,10.0,1.0,2.5,0.0,-1.5\n"
            "2020,2,29,11.0,2.0,3.0,0.5,0.0\n"
            "2020,3,1,12.0,3.0,3.5,0.0,1.0\n")
    series = read_nasa_power_csv(_nasa_file(tmp_path, rows, srad_unit="kW-hr/m^2/day"))
    assert series.end == date(2020, 3, 1)
    np.testing.assert_allclose(series.srad_mj_m2, [9.0, 10.8, 12.6])
    assert series.vap_hpa[1] == pytest.approx(6.108)  # e0(0 degC)
    assert np.all(np.isnan(series.wind_m_s)) and np.all(np.isnan(series.tavg_degc))


def test_nasa_power_relative_humidity_fallback(tmp_path):
    rows = "YEAR,DOY,T2M_MAX,T2M_MIN,T2M,ALLSKY_SFC_SW_DWN,PRECTOTCORR,RH2M\n2020,100,20.0,5.0,12.0,20.0,0.0,50.0\n"
    series = read_nasa_power_csv(_nasa_file(tmp_path, rows))
    assert series.start == date(2020, 4, 9)
    assert series.vap_hpa[0] == pytest.approx(0.5 * 6.108 * np.exp(17.27 * 12.0 / (12.0 + 237.3)))


@pytest.mark.parametrize("old, new, line, column", [
    ("2020,1,4.45,-0.37", "2020,1,4.45,cold", 20, "T2M_MIN"),
    ("2020,2,2.10", "2020,3,2.10", 21, "DOY"),                            # gap
    ("2019,365,", "2019,366,", 19, "DOY"),                               # 2019 has 365 days
    ("2020,2,", "20x0,2,", 21, "YEAR"),
    ("YEAR,DOY,T2M_MAX,T2M_MIN,", "YEAR,DOY,T2M_MAX,TMIN,", 17, "T2M_MIN"),   # missing column
    ("2020,2,2.10,-4.20,-1.05,5.47,0.00,1.95,2.89,79.31", "2020,2,2.10,-4.20", 21, "T2M"),  # short row
    ("2019,364,3.52,-2.61,0.12,4.11,0.35,2.87", "2019,364,3.52,-2.61,0.12,4.11,-0.35,2.87", 18, "rain_mm"),
])
def test_malformed_nasa_power_names_file_line_and_column(tmp_path, old, new, line, column):
    assert old in NASA_ROWS
    path = _nasa_file(tmp_path, NASA_ROWS.replace(old, new, 1), name="broken_power.csv")
    with pytest.raises(WeatherError) as error:
        read_nasa_power_csv(path)
    message = str(error.value)
    assert "broken_power.csv" in message
    assert f"line {line}" in message
    assert column in message


def test_nasa_power_header_problems(tmp_path):
    path = _nasa_file(tmp_path, srad_unit="W/m^2")
    with pytest.raises(WeatherError, match=r"line 11, column ALLSKY_SFC_SW_DWN: unit 'W/m\^2'"):
        read_nasa_power_csv(path)
    path.write_text(NASA_ROWS)
    with pytest.raises(WeatherError, match="no '-BEGIN HEADER-'"):
        read_nasa_power_csv(path)
    path.write_text(NASA_HEADER.replace("Location: Latitude  46.2   Longitude -119.2\n", "")
                    .format(srad_unit="MJ/m^2/day") + NASA_ROWS)
    with pytest.raises(WeatherError, match="latitude_deg, longitude_deg"):
        read_nasa_power_csv(path)
    assert read_nasa_power_csv(path, site=SITE).site == SITE
