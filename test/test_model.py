"""The SIMPLE model against hand-computed values, conservation laws, extremes and the seed code's defects."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from crop_sim_ros.model import (DailyWeather, Management, Soil, UnknownNameError, field_parameters,
                                initial_state, repeat_parameters, simulate_season, stack_parameters, step,
                                zhao2019_library)
from crop_sim_ros.model import simple
from crop_sim_ros.model.et0 import penman_monteith, priestley_taylor
from simple_reference import bucket_day, reference_season

LIBRARY = zhao2019_library()


def potato(management: Management = Management(co2_ppm=369.0), cultivar="Russet Burbank"):
    return field_parameters(LIBRARY.species("potato"), LIBRARY.cultivar("potato", cultivar),
                            LIBRARY.soil("Benton USA potato"), management)


def constant_weather(days, tmax=25.0, tmin=11.0, srad=20.0, rain=0.0, et0=5.0):
    return [np.full(days, v, dtype=float) for v in (tmax, tmin, srad, rain, et0)]


# --- response functions against hand-computed values -----------------------------------------------

def test_thermal_time_and_temperature_response_by_hand():
    # Tmean (25 + 11) / 2 = 18; potato Tbase 4, Topt 22.
    assert simple.thermal_time_increment(18.0, 4.0) == 14.0
    assert simple.thermal_time_increment(2.0, 4.0) == 0.0
    assert simple.temperature_response(18.0, 4.0, 22.0) == pytest.approx(14 / 18)
    assert simple.temperature_response(3.0, 4.0, 22.0) == 0.0
    assert simple.temperature_response(30.0, 4.0, 22.0) == 1.0


def test_heat_response_by_hand():
    assert simple.heat_response(34.0, 34.0, 45.0) == 1.0
    assert simple.heat_response(40.0, 34.0, 45.0) == pytest.approx(1 - 6 / 11)
    assert simple.heat_response(46.0, 34.0, 45.0) == 0.0


def test_co2_response_is_per_100_ppm_and_capped():
    assert simple.co2_response(369.0, 0.10) == pytest.approx(1.019)
    assert simple.co2_response(300.0, 0.10) == 1.0
    assert simple.co2_response(700.0, 0.10) == pytest.approx(1.35)
    # The seed code used 1017 ppm without the /100: f_CO2 = 1 + 0.1 * 350 = 36 (above the 700 ppm cap).
    assert simple.co2_response(1017.0, 0.10) == pytest.approx(1.35)


def test_water_and_canopy_water_responses_by_hand():
    assert simple.water_response(0.5, 0.4) == pytest.approx(0.8)
    assert simple.water_response(1.0, 2.5) == 0.0
    assert simple.canopy_water_response(0.05) == pytest.approx(0.95)
    assert simple.canopy_water_response(0.5) == 1.0


@pytest.mark.parametrize("f_water, fsw", [(0.0, 0.9), (0.06, 0.96), (0.08, 0.98), (0.099, 0.999), (0.1, 1.0),
                                          (0.1001, 1.0), (0.12, 1.0)])
def test_canopy_water_response_switches_at_0_1(f_water, fsw):
    """fsw = 0.9 + f_water up to f_water = 0.1, 1 above (spec eq. 6): checked on both sides of 0.1."""
    assert simple.canopy_water_response(f_water) == pytest.approx(fsw, abs=1e-12)
    assert simple.canopy_water_response(np.array([f_water]))[0] == pytest.approx(fsw, abs=1e-12)


def test_severe_drought_shrinks_the_next_days_canopy_by_fsw():
    # PAW 0 and ET0 8 mm: ARID = 1, f_water = 1 - 0.4 * ARID = 0.6 for potato. With S_water 0.92,
    # f_water = 0.08 and tomorrow's canopy is 0.98 of its no-stress value (0.9 + 0.08).
    dry = DailyWeather(np.array([25.0]), np.array([11.0]), np.array([20.0]), np.array([0.0]), np.array([8.0]))
    params = potato()
    state = initial_state(params)._replace(plant_available_water_mm=np.array([0.0]))
    mild, _ = step(params, state, dry, np.array([0.0]))  # f_water 0.6: fsw 1
    stressed_params = replace(params, water_stress_sensitivity=np.array([0.92]))
    stressed, flux = step(stressed_params, state, dry, np.array([0.0]))
    assert flux.f_water[0] == pytest.approx(0.08)
    assert stressed.fsolar[0] == pytest.approx(0.98 * mild.fsolar[0], rel=1e-12)


def test_canopy_cover_is_the_minimum_of_growth_and_senescence_curves():
    # At TT = I50A the growth curve is at half of fSolar_max; senescence is far away.
    assert simple.canopy_cover(500.0, 500.0, 2300.0, 400.0, 0.95) == pytest.approx(0.475)
    # Late: TT = Tsum - I50B puts the senescence curve at half of fSolar_max.
    assert simple.canopy_cover(1900.0, 500.0, 2300.0, 400.0, 0.95) == pytest.approx(0.475, rel=1e-5)


def test_water_balance_by_hand():
    # W 100 mm, P 50 mm, ET0 5 mm, Benton soil: S = 25400/64 - 254 = 142.875 mm.
    retention = simple.runoff_retention_mm(64.0)
    assert retention == pytest.approx(142.875)
    flux = simple.water_balance(100.0, 50.0, 5.0, retention, 0.10, 0.8, 1200.0)
    runoff = (50 - 0.2 * 142.875) ** 2 / (50 + 0.8 * 142.875)
    assert flux.runoff_mm == pytest.approx(runoff)
    drainage = 0.8 * (100 + 50 - runoff - 120)
    assert flux.drainage_mm == pytest.approx(drainage)
    assert flux.transpiration_mm == pytest.approx(5.0)  # 0.096 * W2 > ET0
    assert flux.arid == pytest.approx(0.0)
    dry = simple.water_balance(20.0, 0.0, 5.0, retention, 0.10, 0.8, 1200.0)
    assert dry.transpiration_mm == pytest.approx(1.92)  # 0.096 * 20
    assert dry.arid == pytest.approx(1 - 1.92 / 5)


@pytest.mark.parametrize("water_input_mm, runoff_mm", [
    (0.0, 0.0),
    (28.575, 0.0),                                      # P = 0.2 S: the threshold, no runoff yet
    (40.0, 11.425 ** 2 / (40.0 + 114.3)),               # (P - 0.2 S)^2 / (P + 0.8 S), S = 142.875 mm
    (100.0, 71.425 ** 2 / (100.0 + 114.3)),
    (400.0, 371.425 ** 2 / (400.0 + 114.3)),
])
def test_scs_runoff_by_hand(water_input_mm, runoff_mm):
    flux = simple.water_balance(60.0, water_input_mm, 5.0, simple.runoff_retention_mm(64.0), 0.10, 0.8, 1200.0)
    assert flux.runoff_mm == pytest.approx(runoff_mm, abs=1e-12)
    # The rest of the day's water goes on to the bucket: W1 = 60 + P - runoff, drained above 120 mm.
    w1 = 60.0 + water_input_mm - runoff_mm
    assert flux.drainage_mm == pytest.approx(0.8 * max(w1 - 120.0, 0.0), abs=1e-12)


def test_priestley_taylor_by_hand():
    # Td = 0.6*30 + 0.4*15 = 24; EEQ = 20 * 23.923 * (2.04e-4 - 1.83e-4*0.23) * (24 + 29)
    eeq = 20 * 23.923 * (2.04e-4 - 1.83e-4 * 0.23) * 53
    assert priestley_taylor(30.0, 15.0, 20.0) == pytest.approx(1.1 * eeq)
    assert priestley_taylor(40.0, 15.0, 20.0) == pytest.approx(
        20 * 23.923 * (2.04e-4 - 1.83e-4 * 0.23) * (0.6 * 40 + 6 + 29) * (5 * 0.05 + 1.1))
    assert priestley_taylor(0.0, -5.0, 0.0) == pytest.approx(1e-4)


@pytest.mark.parametrize("tmax, tmin", [(-8.0, -15.0), (0.0, -6.0), (2.0, -4.0), (4.9, 0.0)])
def test_priestley_taylor_cold_branch_by_hand(tmax, tmin):
    # TMAX < 5 degC: ET0 = EEQ * 0.01 exp(0.18 (TMAX + 20)), above the 1e-4 floor at SRAD 15 MJ/m2.
    eeq = 15.0 * 23.923 * (2.04e-4 - 1.83e-4 * 0.23) * (0.6 * tmax + 0.4 * tmin + 29.0)
    expected = eeq * 0.01 * math.exp(0.18 * (tmax + 20.0))
    assert expected > 0.05  # well above the 1e-4 floor
    assert priestley_taylor(tmax, tmin, 15.0) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("tmax", [5.0, 20.0, 35.0])
def test_priestley_taylor_branch_edges_use_1_1(tmax):
    # At TMAX = 5 and 35 degC neither the cold nor the hot branch applies: ET0 = 1.1 EEQ.
    eeq = 15.0 * 23.923 * (2.04e-4 - 1.83e-4 * 0.23) * (0.6 * tmax + 0.4 * 0.0 + 29.0)
    assert priestley_taylor(tmax, 0.0, 15.0) == pytest.approx(1.1 * eeq, rel=1e-12)


def test_penman_monteith_fao56_example_18():
    # Brussels, 6 July (doy 187), 50.8 N, 100 m; wind 10 km/h at 10 m; Rs 22.07 MJ; ea 1.409 kPa -> 3.9 mm/day.
    et0 = penman_monteith(21.5, 12.3, 22.07, 14.09, 10 / 3.6, 187, 50.8, 100.0, wind_height_m=10.0)
    assert round(float(et0[0]), 1) == 3.9


# --- conservation, bounds, extremes ----------------------------------------------------------------

@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), irrigation=st.floats(0, 100), days=st.integers(1, 60))
def test_water_balance_closes_every_day_with_independently_computed_fluxes(seed, irrigation, days):
    """Every day's runoff, drainage, transpiration and PAW equal the spec's bucket written out on its own
    (tests/simple_reference.py), and with those fluxes water is conserved."""
    rng = np.random.default_rng(seed)
    n = 8
    params = repeat_parameters(potato(), n)
    state = initial_state(params)
    for _ in range(days):
        weather = DailyWeather(rng.uniform(-5, 45, n), rng.uniform(-15, 0, n), rng.uniform(0, 35, n),
                               rng.exponential(15, n) * (rng.random(n) < 0.3), rng.uniform(1e-4, 12, n))
        irrigation_mm = rng.uniform(0, irrigation, n)
        before = state.plant_available_water_mm
        state, flux = step(params, state, weather, irrigation_mm)
        expected = np.array([bucket_day(before[i], weather.rain_mm[i] + irrigation_mm[i], weather.et0_mm[i],
                                        0.10, 64.0, 0.8, 1200.0) for i in range(n)])
        runoff, drainage, transpiration, paw, arid = expected.T
        np.testing.assert_allclose(flux.runoff_mm, runoff, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(flux.drainage_mm, drainage, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(flux.transpiration_mm, transpiration, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(state.plant_available_water_mm, paw, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(flux.arid, arid, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(runoff + drainage + transpiration + paw - before,
                                   weather.rain_mm + irrigation_mm, rtol=0, atol=1e-9)
        assert np.all(state.plant_available_water_mm >= 0)
        # Above capacity only the undrained share (1 - DDC) of today's excess may remain (reference bucket).
        excess = np.maximum(before + weather.rain_mm + irrigation_mm - runoff - 120.0, 0)
        assert np.all(state.plant_available_water_mm <= 120.0 + 0.2 * excess + 1e-9)


@pytest.mark.parametrize("case", ["heat", "dark", "deluge", "flood_irrigation", "frost"])
def test_extreme_inputs_stay_physical(case):
    days = 250
    weather = {
        "heat": constant_weather(days, tmax=55.0, tmin=30.0, et0=15.0),
        "dark": constant_weather(days, srad=0.0),
        "deluge": constant_weather(days, rain=400.0),
        "flood_irrigation": constant_weather(days),
        "frost": constant_weather(days, tmax=-10.0, tmin=-30.0, et0=1e-4),
    }[case]
    irrigation = 100.0 if case == "flood_irrigation" else 0.0
    params = potato()
    result = simulate_season(params, *weather, irrigation)
    for series in (result.biomass_kg_ha, result.fsolar, result.plant_available_water_mm, result.arid,
                   result.thermal_time_degc_d):
        assert np.all(np.isfinite(series)), case
    assert np.all(result.biomass_kg_ha >= 0)
    assert np.all(np.diff(result.biomass_kg_ha, axis=0) >= 0)
    assert np.all((result.fsolar >= 0) & (result.fsolar <= 1))
    # Start of each day: PAW never exceeds the bucket plus today's undrained excess, never below 0.
    assert np.all(result.plant_available_water_mm >= 0)
    assert np.all(result.arid >= 0) and np.all(result.arid <= 1)
    if case in ("heat", "dark", "frost"):
        assert result.biomass_kg_ha.max() == pytest.approx(1.0)  # no growth at all


def test_paw_never_exceeds_capacity_after_drainage_when_ddc_is_one():
    params = field_parameters(LIBRARY.species("potato"), LIBRARY.cultivar("potato", "Russet Burbank"),
                              Soil("full-drain", 0.1, 64, 1.0, 1200),
                              Management())
    result = simulate_season(params, *constant_weather(100, rain=400.0), 100.0)
    assert np.all(result.plant_available_water_mm <= params.capacity_mm + 1e-9)


# --- batched and single-field paths ----------------------------------------------------------------

def test_batched_equals_single_fields_exactly():
    rng = np.random.default_rng(7)
    days = 200
    fields_ = [potato(), potato(cultivar="Sebago"), potato(Management(co2_ppm=550.0, water_stress=False)),
               field_parameters(LIBRARY.species("maize"), LIBRARY.cultivar("maize", "McCurdy 84aa"),
                                LIBRARY.soil("Gainesville USA maize"), Management(harvest_day=120))]
    n = len(fields_)
    weather = [rng.uniform(18, 32, (days, n)), rng.uniform(2, 14, (days, n)), rng.uniform(5, 30, (days, n)),
               rng.exponential(3, (days, n)) * (rng.random((days, n)) < 0.3), rng.uniform(2, 8, (days, n))]
    irrigation = rng.uniform(0, 10, (days, n))
    batched = simulate_season(stack_parameters(fields_), *weather, irrigation)
    for i, params in enumerate(fields_):
        single = simulate_season(params, *(w[:, i] for w in weather), irrigation[:, i])
        for name in ("biomass_kg_ha", "fsolar", "thermal_time_degc_d", "plant_available_water_mm", "arid"):
            np.testing.assert_array_equal(getattr(batched, name)[:, i], getattr(single, name)[:, 0], err_msg=name)
        assert batched.final_state.maturity_day[i] == single.final_state.maturity_day[0]


def test_scalar_backend_is_bit_identical_to_array_path():
    rng = np.random.default_rng(3)
    params = potato()
    array_state = initial_state(params)
    scalar_params = simple.scalar_parameters(params)
    scalar_state = simple.scalar_state(array_state)
    for _ in range(160):
        day = [float(v) for v in (rng.uniform(15, 36), rng.uniform(0, 12), rng.uniform(5, 30),
                                  rng.exponential(2), rng.uniform(2, 9))]
        irrigation = float(rng.uniform(0, 12))
        array_state, _ = step(params, array_state, DailyWeather(*(np.array([v]) for v in day)), np.array([irrigation]))
        scalar_state, _ = step(scalar_params, scalar_state, DailyWeather(*day), irrigation, xp=simple.SCALAR_MATH)
        for name in ("biomass_kg_ha", "fsolar", "i50b_degc_d", "plant_available_water_mm", "thermal_time_degc_d"):
            assert getattr(scalar_state, name) == getattr(array_state, name)[0], name
        assert scalar_state.mature == bool(array_state.mature[0])


# --- reference semantics and the seed code's defects -----------------------------------------------

def test_day_zero_state_excludes_its_own_increments():
    result = simulate_season(potato(), *constant_weather(3))
    assert result.thermal_time_degc_d[0, 0] == 0.0
    assert result.biomass_kg_ha[0, 0] == 1.0
    assert result.thermal_time_degc_d[1, 0] == pytest.approx(14.0)
    # dBiomass(0) = 10 * RUE * fSolar(0) * SRAD * f_co2 * f_temp * min(f_heat, f_water)
    expected = 10 * 1.3 * 0.001 * 20.0 * 1.019 * (14 / 18) * 1.0
    assert result.biomass_kg_ha[1, 0] - 1.0 == pytest.approx(expected)


def test_fsolar_follows_min_of_curves_without_an_invented_switch():
    params = potato(Management(co2_ppm=369.0, water_stress=False))
    days = 170
    result = simulate_season(params, *constant_weather(days, rain=5.0))
    mature_day = result.final_state.maturity_day[0]
    # Tmean 18 degC: TT(d) = 14 d. No stress, so I50B stays 400; spec eq. 7 written out.
    tt = 14.0 * np.arange(1, mature_day + 1)
    grow = 0.95 / (1 + np.exp(-0.01 * (tt - 500.0)))
    senesce = 0.95 / (1 + np.exp(0.01 * (tt - (2300.0 - 400.0))))
    np.testing.assert_allclose(result.fsolar[1:mature_day + 1, 0], np.minimum(grow, senesce), rtol=1e-12)
    assert mature_day == 164  # the last day with TT = 14 d <= 2300


def test_i50b_takes_the_larger_increment_not_the_sum_and_from_day_one():
    params = repeat_parameters(potato(), 1)
    state = initial_state(params)
    # Day 0: heat (TMAX 39.5 -> f_heat 0.5) and drought (ARID 1 -> f_water 0.6): increments 25 vs 12.
    state = state._replace(plant_available_water_mm=np.array([0.0]))
    hot_dry = DailyWeather(np.array([39.5]), np.array([20.0]), np.array([25.0]), np.array([0.0]), np.array([8.0]))
    after_one, flux = step(params, state, hot_dry, np.array([0.0]))
    assert flux.f_heat[0] == pytest.approx(0.5)
    assert flux.f_water[0] == pytest.approx(0.6)
    increment_heat = 50 * (1 - 0.5)
    increment_water = 30 * (1 - 0.6)
    assert after_one.i50b_degc_d[0] == pytest.approx(400 + max(increment_heat, increment_water))


def test_maturity_comes_from_thermal_time_not_a_fixed_season_length():
    warm = simulate_season(potato(), *constant_weather(300, tmax=30.0, tmin=14.0, rain=5.0))
    cool = simulate_season(potato(), *constant_weather(300, tmax=20.0, tmin=8.0, rain=5.0))
    warm_day, cool_day = warm.final_state.maturity_day[0], cool.final_state.maturity_day[0]
    assert warm_day not in (120, 180) and cool_day not in (120, 180)
    assert cool_day > warm_day
    # The last day with TT <= Tsum: TT(m) <= 2300 < TT(m) + dTT(m).
    tt = warm.thermal_time_degc_d[:, 0]
    assert tt[warm_day] <= 2300.0 < tt[warm_day] + 18.0
    # Frozen after maturity.
    assert np.all(warm.biomass_kg_ha[warm_day:, 0] == warm.biomass_kg_ha[warm_day, 0])


def test_harvest_date_ends_the_season():
    result = simulate_season(potato(Management(co2_ppm=369.0, harvest_day=60)), *constant_weather(100, rain=5.0))
    assert result.final_state.maturity_day[0] == 60
    assert result.harvested_yield_kg_ha[0] == pytest.approx(result.biomass_kg_ha[60, 0] * 0.9)


def test_irrigation_passes_through_runoff_like_rain():
    retention = simple.runoff_retention_mm(64.0)
    as_rain = simple.water_balance(60.0, 80.0, 5.0, retention, 0.1, 0.8, 1200.0)
    as_irrigation = simple.water_balance(60.0, 30.0 + 50.0, 5.0, retention, 0.1, 0.8, 1200.0)
    assert as_rain.runoff_mm == as_irrigation.runoff_mm > 0


def test_irrigation_increases_yield_in_the_papers_season_shape():
    rng = np.random.default_rng(0)
    days = 183
    weather = [rng.uniform(20, 32, days), rng.uniform(4, 14, days), rng.uniform(15, 30, days),
               rng.exponential(1.0, days) * (rng.random(days) < 0.15), rng.uniform(4, 8, days)]
    dry = simulate_season(potato(), *weather, 0.0).harvested_yield_kg_ha[0]
    wet = simulate_season(potato(), *weather, 10.0).harvested_yield_kg_ha[0]
    assert wet > 1.5 * dry
    # kg/ha as the spec computes it (not g/m2, not inflated by CO2): the independent formulation's yield.
    for irrigation_mm, ours in ((0.0, dry), (10.0, wet)):
        expected = reference_season(*(list(w) for w in weather), [irrigation_mm] * days).yield_kg_ha
        assert ours == pytest.approx(expected, rel=1e-12)


def _season_case(case: str, days: int = 200):
    """(weather arrays, irrigation, Management, reference_season keywords) of a named test season."""
    rng = np.random.default_rng(sum(map(ord, case)))
    weather = [rng.uniform(18, 36, days), rng.uniform(2, 16, days), rng.uniform(8, 30, days),
               rng.exponential(6.0, days) * (rng.random(days) < 0.2), rng.uniform(2, 9, days)]
    irrigation = rng.uniform(0, 8, days) * (rng.random(days) < 0.5)
    management, keywords = Management(co2_ppm=369.0), {}
    if case == "rainfed":
        irrigation = np.zeros(days)
    elif case == "heat_senescence":  # TMAX 44 degC: I50B +45 degC d a day, the canopy dies before Tsum
        weather[0], weather[1] = np.full(days, 44.0), np.full(days, 20.0)
    elif case == "harvest_date":
        management, keywords = Management(co2_ppm=369.0, harvest_day=75), {"harvest_day": 75}
    elif case == "co2_550_no_water_stress":
        management = Management(co2_ppm=550.0, water_stress=False)
        keywords = {"co2_ppm": 550.0, "water_stress": False}
    elif case == "flood":
        weather[3] = weather[3] * 20
        irrigation = np.full(days, 60.0)
    return weather, irrigation, management, keywords


@pytest.mark.parametrize("case", ["irrigated", "rainfed", "heat_senescence", "harvest_date",
                                  "co2_550_no_water_stress", "flood"])
def test_whole_season_equals_an_independent_formulation_of_the_spec(case):
    """Every daily state and flux, the maturity day and the yield equal the spec's equations written out on
    their own in plain Python (test/simple_reference.py)."""
    weather, irrigation, management, keywords = _season_case(case)
    result = simulate_season(potato(management), *weather, irrigation)
    expected = reference_season(*(list(w) for w in weather), list(irrigation), **keywords)
    assert expected.maturity_day is not None
    assert result.final_state.maturity_day[0] == expected.maturity_day
    assert result.harvested_yield_kg_ha[0] == pytest.approx(expected.yield_kg_ha, rel=1e-12)
    days = len(irrigation)
    for ours, theirs in (("thermal_time_degc_d", "thermal_time_degc_d"), ("biomass_kg_ha", "biomass_kg_ha"),
                         ("fsolar", "fsolar"), ("plant_available_water_mm", "paw_mm"), ("runoff_mm", "runoff_mm"),
                         ("drainage_mm", "drainage_mm"), ("transpiration_mm", "transpiration_mm"),
                         ("arid", "arid")):
        np.testing.assert_allclose(getattr(result, ours)[:, 0], getattr(expected, theirs)[:days], rtol=1e-12,
                                   atol=1e-12, err_msg=ours)


def test_maturity_by_senescence_is_the_day_fsolar_falls_to_0_005():
    weather, irrigation, management, _ = _season_case("heat_senescence")
    result = simulate_season(potato(management), *weather, irrigation)
    day = result.final_state.maturity_day[0]
    fsolar, tt = result.fsolar[:, 0], result.thermal_time_degc_d[:, 0]
    # The first day whose fSolar fell and is <= 0.005; thermal time is far from Tsum.
    assert fsolar[day] <= 0.005 < fsolar[day - 1]
    assert not np.any((fsolar[1:day] <= 0.005) & (np.diff(fsolar[:day]) < 0))
    assert tt[day] < 0.5 * 2300.0
    assert day == 34  # by hand: TT(d) = 28 d, I50B(d) = 400 + 45.45 d; fSolar(34) = 0.0038 <= 0.005 < fSolar(33)


# --- bad input --------------------------------------------------------------------------------------

@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -1.0, 5000.0])
def test_check_irrigation_rejects_bad_amounts(bad):
    with pytest.raises(ValueError, match="irrigation"):
        simple.check_irrigation(bad)


def test_unknown_names_list_what_exists():
    with pytest.raises(UnknownNameError, match="known crops: banana"):
        LIBRARY.species("kale")
    with pytest.raises(UnknownNameError, match="Russet Burbank"):
        LIBRARY.cultivar("potato", "King Edward")
    with pytest.raises(UnknownNameError, match="Benton USA potato"):
        LIBRARY.soil("mars regolith")


def test_library_has_all_zhao_crops_and_cultivars():
    assert len(LIBRARY.crops()) == 14
    assert sum(len(LIBRARY.cultivars(c)) for c in LIBRARY.crops()) == 22
    assert LIBRARY.cultivar("Dry bean", "porrillo sintetico").thermal_time_to_maturity_degc_d == 2700
    assert LIBRARY.cultivar("banana", "Prata An?").name == "Prata Ana"


def test_invalid_parameters_are_rejected_with_names():
    with pytest.raises(ValueError, match="fsolar_max"):
        Management(fsolar_max=1.5)
    with pytest.raises(ValueError, match="initial_paw_mm"):
        potato(Management(initial_paw_mm=500.0))
    assert math.isclose(potato().capacity_mm[0], 120.0)
