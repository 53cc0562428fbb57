"""The ROS edge's array codecs (crop_sim_ros.ros_interface.ArrayCodec): each Float64MultiArray the simulator
publishes is declared once as a typed record; writing and reading it round-trip through the wire format, a
message of the wrong size is refused by name, and the step's JSON summary decodes into the same record."""

from __future__ import annotations

import math

import pytest
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Float64MultiArray

from crop_sim_ros import ros_interface as ri

CODECS = {
    "step_result": (ri.STEP_RESULT, ri.StepResult(3, 41, 7.25, -1.5, False, True, 0.0, 812.5, 17)),
    "family_step_result": (ri.FAMILY_STEP_RESULT, ri.StepResult(1, 150, 0.0, 16000.25, True, False, 18.2, 15432.0, -1)),
    "farm_terms": (ri.FARM_TERMS, ri.FarmTerms(2, 218.0, 1.25, 0.0, math.inf, 8.0)),
    "irrigation": (ri.IRRIGATION, ri.IrrigationCommand(12, 4.5, 2)),
    "biomass": (ri.BIOMASS_READING, ri.BiomassReading(12, 3.75)),
    "paw": (ri.PAW_READING, ri.PawReading(12, math.nan)),
    "weather_today": (ri.WEATHER_TODAY, ri.WeatherToday(12, 28.5, 11.0, 19.75, 2.5, 24.0, 369.0, 12.5, 2.25)),
    "weather_forecast": (ri.WEATHER_FORECAST, ri.WeatherForecast(13, 30.0, 12.0, 21.0, 0.0, 25.5, 369.0, 13.0, 3.0)),
}


def same(a, b) -> bool:
    return all(x == y or (isinstance(x, float) and math.isnan(x) and math.isnan(y)) for x, y in zip(a, b, strict=True))


@pytest.mark.parametrize("name", sorted(CODECS))
def test_a_record_round_trips_through_the_wire(name):
    codec, record = CODECS[name]
    message = codec.message(record)
    assert message.layout.dim[0].label == ",".join(codec.labels) and message.layout.dim[0].size == len(record)
    back = codec.read(deserialize_message(serialize_message(message), Float64MultiArray))
    assert type(back) is codec.record and same(back, record)
    # the field types survive: whole numbers come back as int, flags as bool
    for field, value in zip(back._fields, back):
        assert type(value) is type(getattr(record, field)), field
    # a reused message carries the next record
    other = record._replace(**{record._fields[0]: 99})
    assert codec.read(codec.fill(message, other))[0] == 99
    blank = codec.labelled()  # labelled before its first day
    assert blank.layout.dim[0].label == message.layout.dim[0].label and len(blank.data) == 0
    assert same(codec.read(codec.fill(blank, record)), record)


def test_labels_name_every_field_with_its_unit():
    for codec, record in CODECS.values():
        assert len(codec.labels) == len(record._fields)
        assert all(label.endswith("]") and "[" in label for label in codec.labels)
    assert ri.STEP_RESULT.labels[3] == "reward[1]" and ri.FAMILY_STEP_RESULT.labels[3] == "reward[USD/ha]"
    assert ri.WEATHER_TODAY.labels[1:] == ri.OBSERVATION_LABELS[ri.OBS_TODAY]
    assert ri.WeatherToday._fields[1] == "tmax_degc" and ri.WeatherForecast._fields[1] == "forecast_tmax_degc"


def test_a_message_of_the_wrong_size_is_refused_by_name():
    message = Float64MultiArray()
    message.data = [1.0, 2.0, 3.0]
    with pytest.raises(ValueError, match=r"StepResult message has 3 values, expected 9 \(episode\[1\],day\[d\]"):
        ri.STEP_RESULT.read(message)
    with pytest.raises(ValueError, match="BiomassReading message has 3 values, expected 2"):
        ri.BIOMASS_READING.read(message)


def test_a_codec_whose_labels_do_not_match_its_fields_is_refused():
    with pytest.raises(ValueError, match="PawReading: 2 fields, 3 labels"):
        ri.ArrayCodec(ri.PawReading, ("day[d]", "paw_mm[mm]", "extra[1]"))


def test_the_step_summary_decodes_into_the_step_record():
    record = CODECS["step_result"][1]
    summary = {**record.summary(), "date": "2000-05-12", "irrigation_requested_mm": 9.0, "observation": [0.0] * 20}
    assert summary["return"] == 812.5 and "episode_return" not in summary
    assert ri.StepResult.from_summary(summary) == record
    with pytest.raises(KeyError, match="command_sequence"):
        ri.StepResult.from_summary({k: v for k, v in summary.items() if k != "command_sequence"})


def test_irrigation_commands_with_and_without_an_episode():
    with_episode = ri.irrigation_command(4, 2.5, 7)
    assert ri.IRRIGATION.read(with_episode) == ri.IrrigationCommand(4, 2.5, 7)
    without = ri.irrigation_command(4, 2.5)
    assert list(without.data) == [4.0, 2.5] and without.layout.dim[0].label == "day[d],irrigation[mm]"
