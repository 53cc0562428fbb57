"""The ROS edge's message fillers and readers (crop_sim_ros.ros_interface): the typed crop_sim_interfaces
messages carry the observation's values exactly, stamped in farm time with the field as frame, through the
wire format; the step and reset replies read back into the bridge's info dicts; the irrigation command goes
to the farm session and back into its status exactly."""

from __future__ import annotations

import math
from datetime import date

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from crop_sim_interfaces.msg import (CropState, FarmTerms, Forecast, IrrigationCommand, IrrigationStatus, StepResult,
                                     Weather)
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Header

from crop_sim_ros import ros_interface as ri
from crop_sim_ros.task.layout import EXTENDED, PAPER, WEATHER_NAMES
from crop_sim_ros.task.scenario import ObservationNoise


def wire(message):
    return deserialize_message(serialize_message(message), type(message))


def observation(layout, seed: int = 0) -> np.ndarray:
    """A float32 observation with values that float64 would round differently (0.1-like fractions)."""
    return (np.random.default_rng(seed).random(layout.size) * 40 + 0.1).astype(np.float32)


def test_crop_state_carries_the_observation_exactly_and_a_missing_reading_as_nan():
    obs = observation(PAPER)
    stamp = ri.sim_time(date(2000, 4, 1), 12)
    message = wire(ri.fill_crop_state(ri.stamped(CropState(), "field7"), stamp, 3, 12,
                                      obs.astype(np.float64).tolist(), 0.625, False))
    assert (message.header.frame_id, message.header.stamp.sec, message.episode, message.day) == ("field7",
                                                                                                   stamp.sec, 3, 12)
    assert np.float32(message.biomass_t_ha) == obs[ri.OBS_BIOMASS] and message.biomass_t_ha == float(obs[0])
    assert message.paw_mm == float(obs[ri.OBS_PAW]) and message.paw_observed
    assert message.thermal_time_degc_d == float(obs[ri.OBS_THERMAL_TIME])
    assert (message.canopy_fsolar, message.mature) == (0.625, False)
    family = observation(EXTENDED)
    family[ri.OBS_PAW_OBSERVED] = 0.0  # a dropout
    missing = ri.fill_crop_state(CropState(), stamp, 3, 12, family.astype(np.float64).tolist(), 0.5, True)
    assert math.isnan(wire(missing).paw_mm) and not missing.paw_observed


def test_weather_and_forecast_name_the_observation_columns_and_carry_the_noise():
    obs = observation(PAPER, 1)
    wide = obs.astype(np.float64).tolist()
    today = wire(ri.fill_weather(Weather(), ri.sim_time(date(2000, 4, 1), 5), 5, wide[ri.OBS_TODAY]))
    assert ri.weather_of(today) == wide[ri.OBS_TODAY] and today.day == 5
    assert [f"forecast_{name}" for name in WEATHER_NAMES] == list(PAPER.names[ri.OBS_FORECAST])
    forecast = ri.forecast_noise(Forecast(), ObservationNoise())
    ri.fill_weather(forecast.weather, ri.sim_time(date(2000, 4, 1), 6), 6, wide[ri.OBS_FORECAST])
    forecast = wire(forecast)
    assert ri.weather_of(forecast.weather) == wide[ri.OBS_FORECAST]
    noise = ObservationNoise()
    assert [getattr(forecast, f) for f in ri.FORECAST_SD_FIELDS] == [getattr(noise, n) for n in WEATHER_NAMES]
    assert ri.FORECAST_SD_FIELDS[0] == "tmax_sd_degc" and ri.FORECAST_SD_FIELDS[-1] == "wind_sd_m_s"


def test_a_step_result_reads_back_as_the_bridge_info():
    result = StepResult(episode=3, day=41, irrigation_mm=7.25, irrigation_requested_mm=9.0, reward=-1.5,
                        episode_return=812.5, reward_unit="USD/ha", terminated=False, truncated=True,
                        yield_t_ha=0.0, command_sequence=17)
    result.header.stamp = ri.sim_time(date(2000, 4, 1), 41)
    obs = observation(EXTENDED, 2)
    summary = ri.step_summary(wire(result), obs)
    assert summary == {"episode": 3, "day": 41, "irrigation_mm": 7.25, "reward": -1.5, "terminated": False,
                       "truncated": True, "yield_t_ha": 0.0, "return": 812.5, "command_sequence": 17,
                       "date": "2000-05-12", "irrigation_requested_mm": 9.0, "reward_unit": "USD/ha",
                       "observation": obs.astype(float).tolist()}
    assert "observation" not in ri.step_summary(result)


def test_farm_terms_read_back_as_the_reset_info_with_no_limit_as_none():
    terms = FarmTerms(episode=2, scenario="benton-quota", seed=-1, weather_season=4, weather_source="gen",
                      site_climate="", sowing_date="2000-04-01", reward_unit="USD/ha", tuber_price_usd_per_t=218.0,
                      water_cost_usd_per_mm=1.25, event_cost_usd=0.0, quota_mm=math.inf, capacity_mm_per_day=8.0,
                      max_irrigation_mm=100.0, potential_yield_t_ha=14.5, yield_value_per_t=1090.0)
    obs = observation(EXTENDED, 3)
    obs[ri.OBS_DAY] = 0.0
    info = ri.reset_summary(wire(terms), obs)
    assert (info["episode"], info["day"], info["seed"], info["site_climate"], info["observation_size"]) == (
        2, 0, None, None, 29)
    assert info["farm_terms"] == {"tuber_price_usd_per_t": 218.0, "water_cost_usd_per_mm": 1.25,
                                  "event_cost_usd": 0.0, "quota_mm": None, "capacity_mm_per_day": 8.0}
    assert np.array(info["observation"], np.float32).tobytes() == obs.tobytes()


@pytest.mark.parametrize("namespace, frame", [("/", "farm"), ("/field7", "field7"), ("/a/b", "a/b")])
def test_the_frame_is_the_field_namespace(namespace, frame):
    assert ri.field_frame(namespace) == frame


def test_an_irrigation_command_reaches_the_session_and_its_status_carries_it_back_exactly():
    """IrrigationCommand -> the session's Command (stamp in ns, field) -> the IrrigationStatus's copy, through
    the wire; the farm time of a day is whole seconds at midnight UTC."""
    stamp = ri.sim_time(date(2000, 4, 1), 4)
    assert (stamp.sec, stamp.nanosec) == (954547200 + 4 * 86400, 0)
    sent = wire(IrrigationCommand(header=Header(stamp=Time(sec=stamp.sec, nanosec=7), frame_id="field7"), day=4,
                                  irrigation_mm=2.5, episode=7))
    command = ri.command_of(sent)
    assert (command.day, command.mm, command.episode, command.field) == (4, 2.5, 7, "field7")
    assert command.stamp_ns == stamp.sec * 10**9 + 7
    today = Header(stamp=stamp, frame_id="field7")
    status = wire(ri.status_message(IrrigationStatus.CUT, "cut: ...", command, 12, today, 7, 5, applied_mm=1.5))
    assert status.command == sent and (status.fate, status.sequence, status.episode, status.current_day,
                                       status.applied_mm) == (IrrigationStatus.CUT, 12, 7, 5, 1.5)
    assert status.header == today and status.message == "cut: ..."
    refused = ri.status_message(IrrigationStatus.REFUSED, "rejected: ...", ri.command_of(IrrigationCommand()), 13,
                                today, 7, 4)
    assert math.isnan(refused.applied_mm) and refused.command.episode == IrrigationCommand.ANY_EPISODE == -1
