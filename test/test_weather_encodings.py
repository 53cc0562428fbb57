"""Weather files in other encodings: a UTF-8 byte-order mark and UTF-16/32 with a mark are read like UTF-8;
anything else is a WeatherError that names the encoding problem (not a confusing column error)."""

import numpy as np
import pytest

from crop_sim_ros.weather import WeatherError, read_agweathernet_csv, read_dssat_wth, read_plain_csv

READERS = {
    "dssat": (read_dssat_wth, "simple_r_inputs/Weather/WAPA9201.WTH"),
    "agweathernet": (read_agweathernet_csv, "agweathernet/benton_e_2000-04-01_2000-09-30.csv"),
}
PLAIN = ("# latitude_deg: 46.2\n# longitude_deg: -119.2\n# elevation_m: 200\ndate,tmax_degc,tmin_degc,srad_mj_m2,rain_mm\n"
         "2000-04-01,20.5,5.0,18.0,0.0\n2000-04-02,22.0,6.5,19.5,3.2\n2000-04-03,18.0,4.0,12.0,10.0\n")
# encodings whose byte-order mark the readers recognise (Python's "utf-16"/"utf-32" write one)
WITH_MARK = ["utf-8-sig", "utf-16", "utf-16-be-bom", "utf-32"]


def encode(text: str, encoding: str) -> bytes:
    if encoding == "utf-16-be-bom":
        return b"\xfe\xff" + text.encode("utf-16-be")
    return text.encode(encoding)


def same_series(a, b) -> None:
    assert a.dates.tolist() == b.dates.tolist()
    for name in ("tmax_degc", "tmin_degc", "srad_mj_m2", "rain_mm"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


@pytest.mark.parametrize("encoding", WITH_MARK)
@pytest.mark.parametrize("kind", READERS)
def test_reference_files_with_a_byte_order_mark_read_like_utf8(shared_data, tmp_path, kind, encoding):
    reader, name = READERS[kind]
    original = shared_data / name
    copy = tmp_path / original.name
    copy.write_bytes(encode(original.read_text(encoding="utf-8"), encoding))
    same_series(reader(copy), reader(original))


@pytest.mark.parametrize("encoding", WITH_MARK)
def test_plain_csv_with_a_byte_order_mark_reads_like_utf8(tmp_path, encoding):
    (tmp_path / "utf8.csv").write_text(PLAIN, encoding="utf-8")
    (tmp_path / "marked.csv").write_bytes(encode(PLAIN, encoding))
    series = read_plain_csv(tmp_path / "marked.csv")
    same_series(series, read_plain_csv(tmp_path / "utf8.csv"))
    assert series.tmax_degc.tolist() == [20.5, 22.0, 18.0]


@pytest.mark.parametrize("reader", [read_plain_csv, read_dssat_wth, read_agweathernet_csv])
def test_utf16_without_a_mark_names_the_encoding(tmp_path, reader):
    path = tmp_path / "weather.txt"
    path.write_bytes(PLAIN.encode("utf-16-le"))
    with pytest.raises(WeatherError, match=r"weather\.txt, line 1: NUL characters: UTF-16 or UTF-32 text without "
                                           r"a byte-order mark\? Save the file as UTF-8"):
        reader(path)


@pytest.mark.parametrize("reader", [read_plain_csv, read_dssat_wth, read_agweathernet_csv])
def test_latin1_bytes_name_the_line_and_the_byte(tmp_path, reader):
    path = tmp_path / "weather.txt"
    text = PLAIN.replace("2000-04-02,22.0", "2000-04-02,22°")  # the degree sign in Latin-1 is byte 0xb0
    path.write_bytes(text.encode("latin-1"))
    offset = text.index("°")
    with pytest.raises(WeatherError, match=rf"weather\.txt, line 6: byte {offset} \(0xb0\) is not utf-8 text; "
                                           r"save the file as UTF-8"):
        reader(path)
