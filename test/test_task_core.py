"""The task's scenarios and functional core: loading, observation layout, reward, ends, seed-paper defects."""

import csv
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from crop_sim_ros.model import UnknownNameError
from crop_sim_ros.model.et0 import penman_monteith
from crop_sim_ros.task import core
from crop_sim_ros.task.scenario import (ObservationNoise, Scenario, get_scenario, scenario_from_dict,
                                        scenario_names)
from crop_sim_ros.weather.readers import dssat_date, read_agweathernet_reference_et0
from simple_reference import reference_of_table_season

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
BENTON_FILE = DATA / "agweathernet" / "benton_e_2000-04-01_2000-09-30.csv"
needs_data = pytest.mark.usefixtures("shared_data")  # fails, never skips, without the data


def noise_free(name: str) -> Scenario:
    return replace(get_scenario(name, DATA), noise=ObservationNoise.none())


KG_PER_T = 1000.0
COST_PER_MM = -1.25e-4  # the paper's C_I, t/ha per mm


def reference_of_season(table: core.SeasonTable, k: int, irrigation_mm: float, water_stress: bool = True):
    """Season ``k`` of ``table`` grown by the independent formulation (test/simple_reference.py)."""
    return reference_of_table_season(table, core.WEATHER_NAMES, k, irrigation_mm, co2_ppm=369.0,
                                     water_stress=water_stress)


# --- scenarios -------------------------------------------------------------------------------------------

def test_builtin_scenarios_are_listed():
    assert {"benton-generated", "benton-2000", "heldout", "paterson-1992", "paterson-1993", "paterson-1994",
            "paterson-1995"} <= set(scenario_names())


def test_generated_scenario_needs_no_data_directory(tmp_path):
    scenario = get_scenario("benton-generated", data_dir=tmp_path / "absent")
    assert scenario.weather.kind == "generator" and scenario.n_seasons == 1000
    table = core.scenario_table(scenario)
    assert len(table) == 1000 and np.all(table.n_days == scenario.max_season_days)
    # Potential yield: no water stress, no irrigation, at maturity (or the weather's end), in t/ha.
    for k in range(4):
        expected = reference_of_season(table, k, 0.0, water_stress=False)
        assert expected.maturity_day is not None
        assert table.potential_yield_t_ha[k] == pytest.approx(expected.yield_kg_ha / KG_PER_T, rel=1e-12)


def test_file_scenario_names_the_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="benton_e_2000"):
        get_scenario("benton-2000", data_dir=tmp_path)


@needs_data
def test_benton_2000_is_the_papers_season():
    scenario = get_scenario("benton-2000", DATA)
    (season,) = scenario.load_seasons()
    assert str(season.start) == "2000-04-01" and len(season) == 183
    assert scenario.co2_ppm == 369.0 and scenario.cultivar == "Russet Burbank"
    assert scenario.soil == "Benton USA potato"


@needs_data
def test_paterson_sowing_dates_come_from_treatment_csv():
    with (DATA / "simple_r_inputs" / "Input" / "Treatment.csv").open(newline="") as handle:
        sowing = {row["weather"]: dssat_date(row["SowingDate"]) for row in csv.DictReader(handle)
                  if row["Cultivar"] == "Russet Burbank" and row["weather"].startswith("WAPA")}
    for year in (1992, 1993, 1994, 1995):
        scenario = get_scenario(f"paterson-{year}", DATA)
        (season,) = scenario.load_seasons()
        assert season.start == sowing[f"WAPA{year % 100}01"]
        # The DSSAT files have neither vapour pressure nor wind: filled by FAO-56, and said so.
        assert any("vap_hpa" in f for f in season.filled) and any("wind_m_s" in f for f in season.filled)
        assert np.all(season.wind_m_s == 2.0)


@needs_data
def test_heldout_holds_the_five_real_seasons():
    scenario = get_scenario("heldout", DATA)
    starts = [str(s.start) for s in scenario.load_seasons()]
    assert starts == ["2000-04-01", "1992-04-11", "1993-04-06", "1994-04-05", "1995-04-05"]


@pytest.mark.parametrize("field, value", [("crop", "turnip"), ("cultivar", "Purple Haze"), ("soil", "Moon dust")])
def test_unknown_names_raise_the_models_error(field, value):
    scenario = replace(get_scenario("benton-generated"), **{field: value})
    with pytest.raises(UnknownNameError, match=value):
        core.task_params(scenario)


GOOD = {"name": "x", "sowing_date": "2000-04-01", "weather": {"kind": "generator", "seed": 1, "n_seasons": 2}}


@pytest.mark.parametrize("change, field", [
    ({"co2_ppm": "lots"}, "co2_ppm"),
    ({"co2_ppm": -5}, "co2_ppm"),
    ({"max_irrigation_mm": float("nan")}, "max_irrigation_mm"),
    ({"irrigation_cost_per_mm": 0.1}, "irrigation_cost_per_mm"),
    ({"max_season_days": 0}, "max_season_days"),
    ({"et0_method": "hargreaves"}, "et0_method"),
    ({"sowing_date": "April"}, "sowing_date"),
    ({"colour": "green"}, "colour"),
    ({"noise": {"wind_m_s": -1}}, "noise.wind_m_s"),
    ({"noise": {"hail": 1}}, "noise.hail"),
    ({"weather": {"kind": "oracle"}}, "weather.kind"),
    ({"weather": {"kind": "generator", "n_seasons": 0}}, "weather.n_seasons"),
    ({"weather": {"kind": "file", "path": "a.csv", "format": "xls"}}, "weather.format"),
    ({"weather": {"kind": "seasons", "seasons": [{"path": "a.wth", "format": "dssat"}]}},
     "weather.seasons[0].sowing_date"),
])
def test_bad_scenario_fields_name_the_field(change, field):
    with pytest.raises(ValueError, match=field.replace("[", r"\[").replace("]", r"\]")):
        scenario_from_dict({**GOOD, **change})


# --- observation, reward, ends ---------------------------------------------------------------------------

@needs_data
def test_observation_layout_without_noise_is_the_true_state():
    scenario = noise_free("benton-2000")
    params, table = core.task_params(scenario, 1), core.scenario_table(scenario)
    state = core.initial(params, np.array([0]))
    rng = np.random.default_rng(0)
    for _ in range(40):
        state, _ = core.transition(params, table, state, np.array([2.0]))
    obs = core.observation(params, table, state, rng)[0]
    (season,) = scenario.load_seasons()
    d = 40
    assert obs.dtype == np.float32 and obs.shape == (20,)
    assert obs[0] == np.float32(state.crop.biomass_kg_ha[0] / 1000)
    assert obs[1] == np.float32(state.crop.thermal_time_degc_d[0]) and obs[2] == d
    for offset, day in ((3, d), (11, d + 1)):
        expected = [season.tmax_degc[day], season.tmin_degc[day], (season.tmax_degc[day] + season.tmin_degc[day]) / 2,
                    season.rain_mm[day], season.srad_mj_m2[day], 369.0, season.vap_hpa[day], season.wind_m_s[day]]
        np.testing.assert_array_equal(obs[offset:offset + 8], np.float32(expected))
    assert obs[19] == np.float32(state.crop.plant_available_water_mm[0])


@needs_data
def test_forecast_on_the_last_weather_day_is_todays_true_weather():
    scenario = noise_free("benton-2000")
    params, table = core.task_params(scenario, 1), core.scenario_table(scenario)
    last = int(table.n_days[0]) - 1
    state = core.initial(params, np.array([0]))
    state = state._replace(crop=state.crop._replace(days_since_sowing=np.array([last])))
    obs = core.observation(params, table, state, np.random.default_rng(0))[0]
    np.testing.assert_array_equal(obs[11:19], obs[3:11])


def test_noisy_values_are_clipped_at_their_physical_bound():
    scenario = replace(get_scenario("benton-generated"),
                       noise=ObservationNoise(biomass_t_ha=50, paw_mm=1e4, tmax_degc=1e3, rain_mm=1e3, srad_mj_m2=1e3, co2_ppm=1e5,
                                              vap_hpa=1e3, wind_m_s=1e3))
    params, table = core.task_params(scenario, 500), core.scenario_table(scenario)
    obs = core.observation(params, table, core.initial(params, np.arange(500)), np.random.default_rng(1))
    low = core.OBSERVATION_LOW
    assert np.all(obs >= low) and np.any(obs[:, 0] == 0) and np.any(obs[:, 19] == 0) and np.any(obs[:, 14] == 0)
    assert np.any(obs[:, 11] < 0)  # temperatures have no bound


def test_reward_is_cost_every_day_plus_yield_in_t_ha_at_maturity():
    scenario = get_scenario("benton-generated")
    params, table = core.task_params(scenario, 8), core.scenario_table(scenario)
    state = core.initial(params, np.arange(8))
    irrigation = np.full(8, 6.0)
    harvest_rewards, harvest_days = np.full(8, np.nan), np.full(8, -1)
    while not np.all(core.terminal(state) | core.truncated(table, state)):
        next_state, fluxes = core.transition(params, table, state, irrigation)
        reward = core.reward(params, state, irrigation, next_state)
        harvest = fluxes.matured
        np.testing.assert_allclose(reward[~harvest], COST_PER_MM * 6.0, rtol=1e-12)
        harvest_rewards[harvest] = reward[harvest] - COST_PER_MM * 6.0
        harvest_days[harvest] = state.crop.days_since_sowing[harvest]
        state = next_state
    # The harvest day pays the dry yield in t/ha (biomass in g/m2 would pay 100 times more), once.
    for k in range(8):
        expected = reference_of_season(table, k, 6.0)
        assert harvest_days[k] == expected.maturity_day
        assert harvest_rewards[k] == pytest.approx(expected.yield_kg_ha / KG_PER_T, rel=1e-9)


def test_potential_yield_bounds_every_irrigation_policy():
    scenario = get_scenario("benton-generated")
    params, table = core.task_params(scenario, 20), core.scenario_table(scenario)
    state = core.initial(params, np.arange(20))
    for _ in range(scenario.max_season_days):
        state, _ = core.transition(params, table, state, np.full(20, 30.0))
    yield_t_ha = state.crop.biomass_kg_ha * params.fields.harvest_index / 1000
    potential = table.potential_yield_t_ha[:20]
    assert np.all(yield_t_ha <= potential + 1e-9) and np.all(yield_t_ha > 0.9 * potential)


# --- regression tests for the seed paper's defects that live in the task layer ---------------------------

def test_co2_369_gives_f_co2_1_019_for_potato():
    params = core.task_params(get_scenario("benton-generated"))
    np.testing.assert_allclose(params.fields.co2_factor, 1.019)


@needs_data
def test_et0_uses_the_benton_site_and_wind_in_m_s():
    """The station's own Penman-Monteith ETo column is the independent check of our site and units: ours is
    within 1.1 % a day of it on average. At the seed code's Idaho site (42.55 N, 1195 m) it would be 2.7 %
    off a day and 1.7 % over the season, with wind taken as km/h 48 %."""
    scenario = get_scenario("benton-2000", DATA)
    (season,) = scenario.load_seasons()
    table = core.scenario_table(scenario)
    station = read_agweathernet_reference_et0(BENTON_FILE)
    ok = np.isfinite(station)
    assert ok.sum() > 150
    ours = table.et0_mm[0, :len(station)]
    assert np.mean(np.abs(ours[ok] - station[ok]) / station[ok]) < 0.015
    assert np.mean(ours[ok]) == pytest.approx(np.mean(station[ok]), rel=0.005)
    idaho = penman_monteith(season.tmax_degc, season.tmin_degc, season.srad_mj_m2, season.vap_hpa,
                            season.wind_m_s, season.day_of_year, 42.55, 1195.0)
    assert np.mean(np.abs(idaho[ok] - station[ok]) / station[ok]) > 0.025
    times_3_6 = penman_monteith(season.tmax_degc, season.tmin_degc, season.srad_mj_m2, season.vap_hpa,
                                season.wind_m_s * 3.6, season.day_of_year, 46.2, 200.0)
    assert np.mean(times_3_6[ok]) > 1.3 * np.mean(station[ok])


def test_forecast_wind_is_the_noisy_tomorrows_wind():
    only_wind = replace(ObservationNoise.none(), wind_m_s=6.0)
    scenario = replace(get_scenario("benton-generated"), noise=only_wind)
    params, table = core.task_params(scenario, 200), core.scenario_table(scenario)
    state = core.initial(params, np.arange(200))
    obs = core.observation(params, table, state, np.random.default_rng(0))
    true_tomorrow = table.weather[np.arange(200), 1, core.WEATHER_NAMES.index("wind_m_s")]
    assert np.all(obs[:, 10] == np.float32(table.weather[np.arange(200), 0, 7]))  # today's: exact
    differs = obs[:, 18] != np.float32(true_tomorrow)
    assert differs.mean() > 0.9
    np.testing.assert_array_equal(obs[:, 11:18], table.observation_rows[np.arange(200), 0, 11:18])


def test_season_ends_at_maturity_not_a_fixed_length():
    scenario = get_scenario("benton-generated")
    params, table = core.task_params(scenario, 50), core.scenario_table(scenario)
    state = core.initial(params, np.arange(50))
    for _ in range(scenario.max_season_days):
        state, _ = core.transition(params, table, state, np.full(50, 5.0))
    assert np.all(core.terminal(state))
    lengths = state.crop.maturity_day + 1
    assert len(np.unique(lengths)) > 5 and not np.all(np.isin(lengths, (120, 180)))


@needs_data
def test_plain_csv_weather_file_scenario(tmp_path):
    from crop_sim_ros.weather.csv_readers import write_plain_csv
    from crop_sim_ros.weather import read_agweathernet_csv

    write_plain_csv(read_agweathernet_csv(BENTON_FILE), tmp_path / "benton.csv")
    scenario = scenario_from_dict({"name": "plain", "sowing_date": "2000-04-01",
                                   "weather": {"kind": "file", "path": "benton.csv", "format": "csv"}}, tmp_path)
    ours = core.scenario_table(scenario)
    paper = core.scenario_table(get_scenario("benton-2000", DATA))
    np.testing.assert_allclose(ours.weather, paper.weather, atol=1e-6)
    assert ours.n_days[0] == 183


@needs_data
def test_measured_tavg_is_observed_only_when_asked():
    from crop_sim_ros.weather import read_agweathernet_csv

    measured = read_agweathernet_csv(BENTON_FILE).tavg_degc
    for observe_measured, expected in ((True, measured[0]), (False, None)):
        scenario = replace(noise_free("benton-2000"), observe_measured_tavg=observe_measured)
        params, table = core.task_params(scenario), core.scenario_table(scenario)
        obs = core.observation(params, table, core.initial(params, np.array([0])), np.random.default_rng(0))[0]
        if expected is None:
            expected = (table.weather[0, 0, 0] + table.weather[0, 0, 1]) / 2
        assert obs[5] == np.float32(expected)
