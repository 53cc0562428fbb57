"""The task family: layout by name, farm terms, quota and capacity, money reward, sensing, derived scenarios."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from crop_sim_ros.task import IrrigationEnv, IrrigationVectorEnv, core
from crop_sim_ros.task.layout import EXTENDED, PAPER, WEATHER_NAMES, layout_of_size
from crop_sim_ros.task.scenario import ObservationNoise, get_scenario, load_scenario, scenario_from_dict
from crop_sim_ros.task.terms import Economics, FarmLimits, Range

COL = {name: EXTENDED.index(name) for name in EXTENDED.names}


def family(**limits) -> object:
    """benton-generated with fixed prices (250 USD/t fresh, 0.2 dry matter, 1.5 USD/mm) and ``limits``."""
    base = get_scenario("benton-generated")
    money = Economics(tuber_price_usd_per_t=250.0, tuber_dry_matter_fraction=0.2, water_price_usd_per_mm=0.5,
                      pumping_energy_usd_per_mm=1.0)
    return replace(base, name="family-test", economics=money, limits=FarmLimits(**limits))


def test_extended_layout_starts_with_the_papers_and_names_are_unique():
    assert EXTENDED.names[:PAPER.size] == PAPER.names
    assert len(set(EXTENDED.names)) == EXTENDED.size == 29
    assert EXTENDED.index("paw_mm") == 19 and EXTENDED.index("et0_mm") == 28
    assert layout_of_size(29) is EXTENDED and layout_of_size(20) is PAPER
    with pytest.raises(KeyError, match="no observation column 'paw'"):
        EXTENDED.index("paw")
    with pytest.raises(ValueError, match="no observation layout has 21 values"):
        layout_of_size(21)


@pytest.mark.parametrize("value, message", [([3, 1], "low > high"), ([1, 2, 3], "a range is"),
                                            ("x", "expected a number"), (-1, "not a finite number")])
def test_bad_ranges_are_refused_naming_the_field(value, message):
    with pytest.raises(ValueError, match=message):
        Economics(tuber_price_usd_per_t=value)


def test_limits_without_economics_are_refused_and_unknown_fields_named():
    base = get_scenario("benton-generated")
    with pytest.raises(ValueError, match="give it economics too"):
        replace(base, limits=FarmLimits(capacity_mm_per_day=5.0))
    with pytest.raises(ValueError, match="limits.quota: unknown field"):
        FarmLimits.from_dict({"quota": 100})
    with pytest.raises(ValueError, match="limits.paw_dropout_probability"):
        FarmLimits(paw_dropout_probability=1.5)


def test_the_papers_task_is_not_a_family_task_and_keeps_20_values():
    scenario = get_scenario("benton-generated")
    assert not scenario.is_family_task and scenario.reward_unit == "t/ha"
    obs, info = IrrigationEnv(scenario).reset(seed=0)
    assert obs.shape == (20,) and info["yield_value_per_t"] == 1.0 and info["quota_mm"] == np.inf


def test_capacity_and_quota_cut_irrigation_and_the_observation_counts_them():
    env = IrrigationEnv(family(quota_mm=100.0, capacity_mm_per_day=8.0))
    obs, info = env.reset(seed=3)
    assert obs.shape == (29,) and obs[COL["quota_remaining_mm"]] == 100.0
    assert obs[COL["capacity_mm_per_day"]] == 8.0 and obs[COL["irrigation_yesterday_mm"]] == 0.0
    applied = []
    for _ in range(20):
        obs, reward, terminated, truncated, info = env.step([30.0])
        applied.append(info["irrigation_applied_mm"])
        assert info["irrigation_clipped"]
        assert obs[COL["irrigation_yesterday_mm"]] == pytest.approx(applied[-1])
        assert obs[COL["quota_remaining_mm"]] == pytest.approx(100.0 - sum(applied), abs=1e-4)
    # 8 mm a day (the capacity) until the last 4 mm of the quota, then nothing
    assert applied[:12] == [8.0] * 12 and applied[12] == pytest.approx(4.0) and applied[13:] == [0.0] * 7


def test_reward_is_net_return_in_usd_per_ha():
    env = IrrigationEnv(family())
    obs, info = env.reset(seed=1)
    value_per_t = 250.0 / 0.2
    assert info["yield_value_per_t"] == value_per_t and info["water_cost_per_mm"] == 1.5
    assert obs[COL["tuber_price_usd_per_t"]] == 250.0 and obs[COL["water_cost_usd_per_mm"]] == 1.5
    total = 0.0
    while True:
        obs, reward, terminated, truncated, info = env.step([6.0])
        total += reward
        if terminated or truncated:
            break
        assert reward == pytest.approx(-1.5 * 6.0)
    assert terminated
    # the harvest day pays the fresh tubers: dry yield t/ha / 0.2 x 250 USD/t, minus that day's water
    assert reward == pytest.approx(info["yield_t_ha"] / 0.2 * 250.0 - 9.0)
    assert info["normalized_return"] == pytest.approx(total / (info["potential_yield_t_ha"] * value_per_t))


def test_drawn_terms_lie_in_their_ranges_and_differ_between_fields_and_seeds():
    scenario = get_scenario("benton-quota")
    env = IrrigationVectorEnv(256, scenario)
    obs, info = env.reset(seed=0)
    price = obs[:, COL["tuber_price_usd_per_t"]]
    quota = info["quota_mm"]
    assert price.min() >= 150 and price.max() <= 300 and np.ptp(price) > 100
    assert quota.min() >= 150 and quota.max() <= 450 and np.ptp(quota) > 200
    np.testing.assert_allclose(obs[:, COL["quota_remaining_mm"]], quota, rtol=1e-6)
    again, _ = env.reset(seed=0)
    other, _ = env.reset(seed=1)
    np.testing.assert_array_equal(again[:, 20:], obs[:, 20:])
    assert not np.allclose(other[:, COL["quota_remaining_mm"]], obs[:, COL["quota_remaining_mm"]])


def test_given_terms_at_reset_are_used_and_checked():
    env = IrrigationVectorEnv(3, get_scenario("benton-quota"))
    terms = {"quota_mm": np.array([10.0, 20.0, 30.0])}
    obs, info = env.reset(seed=0, options={"season": [0, 1, 2], "terms": terms})
    np.testing.assert_array_equal(info["quota_mm"], terms["quota_mm"])
    obs, *_ = env.step(np.full(3, 50.0))
    np.testing.assert_allclose(obs[:, COL["irrigation_yesterday_mm"]], [8.0, 8.0, 8.0])
    with pytest.raises(ValueError, match="terms: unknown"):
        env.reset(seed=0, options={"terms": {"price": np.ones(3)}})
    with pytest.raises(ValueError, match="terms.quota_mm"):
        env.reset(seed=0, options={"terms": {"quota_mm": np.ones(2)}})


def test_single_and_vector_family_envs_agree_without_noise():
    scenario = replace(family(quota_mm=200.0, capacity_mm_per_day=7.0), noise=ObservationNoise.none())
    single = IrrigationEnv(scenario)
    vector = IrrigationVectorEnv(2, scenario)
    vobs, _ = vector.reset(seed=0, options={"season": [4, 9]})
    for field, season in enumerate((4, 9)):
        obs, _ = single.reset(seed=0, options={"season": season})
        np.testing.assert_array_equal(obs, vobs[field])
    actions = np.array([[12.0, 3.0], [0.0, 9.0], [5.0, 5.0]] * 30)
    returns = np.zeros(2)
    for field, season in enumerate((4, 9)):
        obs, _ = single.reset(seed=0, options={"season": season})
        for day, action in enumerate(actions):
            obs, reward, terminated, truncated, _ = single.step([action[field]])
            returns[field] += reward
    vector.reset(seed=0, options={"season": [4, 9]})
    vector_returns = np.zeros(2)
    for action in actions:
        vobs, rewards, *_ = vector.step(action)
        vector_returns += rewards
    np.testing.assert_allclose(vector_returns, returns, rtol=1e-12)
    np.testing.assert_allclose(vobs[1], obs, rtol=1e-6)


def test_paw_dropouts_happen_at_their_rate_and_are_flagged():
    env = IrrigationVectorEnv(400, family(paw_dropout_probability=0.3))
    obs, _ = env.reset(seed=2)
    flags = []
    for _ in range(10):
        flags.append(obs[:, COL["paw_observed"]])
        missing = obs[:, COL["paw_observed"]] == 0.0
        assert np.all(obs[missing, COL["paw_mm"]] == 0.0) and np.all(obs[~missing, COL["paw_mm"]] > 0.0)
        obs, *_ = env.step(np.full(400, 4.0))
    missing_share = 1.0 - np.mean(flags)
    # 4,000 readings: the binomial sd of the share is 0.0072
    assert 0.27 < missing_share < 0.33


def test_without_a_sensor_paw_is_never_read():
    env = IrrigationEnv(family(paw_sensor=False))
    obs, _ = env.reset(seed=0)
    for _ in range(5):
        assert obs[COL["paw_mm"]] == 0.0 and obs[COL["paw_observed"]] == 0.0
        obs, *_ = env.step([5.0])


def test_today_et0_in_the_observation_is_the_tables():
    scenario = family()
    env = IrrigationEnv(scenario)
    obs, info = env.reset(seed=0, options={"season": 7})
    table = core.scenario_table(scenario)
    for day in range(3):
        assert obs[COL["et0_mm"]] == pytest.approx(table.et0_mm[7, day], rel=1e-6)
        obs, *_ = env.step([0.0])


def test_derived_scenarios_merge_their_base(tmp_path):
    path = tmp_path / "mine.yaml"
    path.write_text("base: benton-quota\nname: mine\nlimits: {capacity_mm_per_day: 5}\nnoise: {paw_mm: 4}\n")
    scenario = load_scenario(path)
    assert scenario.limits.capacity_mm_per_day == 5.0 and scenario.limits.quota_mm == Range(150.0, 450.0)
    assert scenario.noise.paw_mm == 4.0 and scenario.noise.tmax_degc == 3.0
    assert scenario.economics == Economics()
    (tmp_path / "a.yaml").write_text("base: b.yaml\nname: a\n")
    (tmp_path / "b.yaml").write_text("base: a.yaml\nname: b\n")
    with pytest.raises(ValueError, match="is a cycle"):
        load_scenario(tmp_path / "a.yaml")
    (tmp_path / "c.yaml").write_text("base: nowhere\nname: c\n")
    with pytest.raises(ValueError, match="'nowhere' is neither a built-in scenario"):
        load_scenario(tmp_path / "c.yaml")


def test_a_mixture_holds_the_seasons_of_its_parts():
    scenario = scenario_from_dict({"name": "m", "weather": {"kind": "mixture",
                                                            "mixture": ["paterson-1992", "paterson-1993"]}})
    table = core.scenario_table(scenario)
    assert len(table) == scenario.n_seasons == 2
    assert [str(d) for d in table.sowing_dates] == ["1992-04-11", "1993-04-06"]
    climates = get_scenario("climates-quota")
    assert climates.n_seasons == 2000 and climates.is_family_task


def test_climates3_holds_climates_quota_seasons_first_and_names_the_early_benton_part_apart():
    from crop_sim_ros.task.scenario import climates
    two, three = get_scenario("climates-quota"), get_scenario("climates3-quota")
    assert three.n_seasons == 3000
    assert list(climates(two)) == ["benton", "gainesville"]
    parts = climates(three)
    assert list(parts) == ["benton", "gainesville", "benton-early"]
    assert str(parts["benton-early"].sowing_date) == "2000-03-01" and parts["benton-early"].weather.generator == "benton"
    assert list(climates(get_scenario("benton-early-quota"))) == ["benton"]  # one part: its generator's name
    # pool positions 0..1999 are climates-quota's seasons (its demonstrations' season numbers mean the same)
    table2, table3 = core.scenario_table(two), core.scenario_table(three)
    for k in (0, 999, 1000, 1999):
        np.testing.assert_array_equal(table3.weather[k], table2.weather[k])
    assert str(table3.sowing_dates[2000]) == "2000-03-01"


def test_climates4_holds_climates3s_seasons_first_and_a_warmed_early_benton_part():
    from crop_sim_ros.task.scenario import climates
    three, four = get_scenario("climates3-quota"), get_scenario("climates4-quota")
    assert four.n_seasons == 4000
    assert list(climates(four)) == ["benton", "gainesville", "benton-early", "benton-early-warm"]
    table3, table4 = core.scenario_table(three), core.scenario_table(four)
    for k in (0, 1999, 2000, 2999):
        np.testing.assert_array_equal(table4.weather[k], table3.weather[k])
    assert str(table4.sowing_dates[3000]) == "2000-03-01" and table4.sources[3000].startswith("generator(benton+4C")
    # warming is a generator's option only
    values = {"name": "x", "crop": "potato", "cultivar": "Russet Burbank", "soil": "Benton USA potato",
              "weather": {"kind": "seasons", "warming_degc": 1.0,
                          "seasons": [{"path": "a.wth", "format": "dssat", "sowing_date": "2000-04-01"}]}}
    with pytest.raises(ValueError, match="weather.warming_degc, drying_degc, diurnal_range_degc, rain_factor, "
                                         "radiation_factor, spread: only a 'generator' source can be warmed"):
        scenario_from_dict(values)
    with pytest.raises(ValueError, match="weather.warming_degc"):
        scenario_from_dict({**values, "sowing_date": "2000-04-01",
                            "weather": {"kind": "generator", "generator": "benton", "warming_degc": 12}})


def test_climates6_holds_climates4s_seasons_first_and_two_warmed_parts_that_develop_faster():
    from crop_sim_ros.task.scenario import climates
    four, six = get_scenario("climates4-quota"), get_scenario("climates6-quota")
    assert six.n_seasons == 6000 and six.economics == four.economics and six.limits == four.limits
    assert list(climates(six)) == ["benton", "gainesville", "benton-early", "benton-early-warm", "benton-warm",
                                   "gainesville-warm"]
    table4, table6 = core.scenario_table(four), core.scenario_table(six)
    for k in (0, 1999, 3000, 3999):
        np.testing.assert_array_equal(table6.weather[k], table4.weather[k])
    assert str(table6.sowing_dates[4000]) == "2000-04-01" and table6.sources[4000].startswith("generator(benton+4C")
    assert str(table6.sowing_dates[5000]) == "2001-02-01" and table6.sources[5000].startswith("generator(gainesville+4C")
    # the warmed parts are warmer on average than the parts they warm, sown on the same dates (the warming itself
    # is the generator's, tested in test_climates); the table's weather columns are WEATHER_NAMES, tmax first
    tmax = WEATHER_NAMES.index("tmax_degc")
    for warm, cool in ((4000, 0), (5000, 1000)):
        assert table6.weather[warm:warm + 50, :100, tmax].mean() > table6.weather[cool:cool + 50, :100, tmax].mean() + 2


def _grown_task_tables(smaller: str, larger: str, added_parts: list[str], added_sources: list[str],
                       added_sowing_dates: list[str], part_seasons: int = 1000):
    """Check that task ``larger`` is ``smaller`` (same terms, same seasons at the same pool positions) plus one
    ``part_seasons``-season part per ``added_parts`` name, whose first season is sown on its date with a source
    starting as given; return both tasks' season tables."""
    from crop_sim_ros.task.scenario import climates
    small, large = get_scenario(smaller), get_scenario(larger)
    n = small.n_seasons
    assert large.n_seasons == n + part_seasons * len(added_parts)
    assert large.economics == small.economics and large.limits == small.limits
    assert list(climates(large)) == list(climates(small)) + added_parts
    table_small, table_large = core.scenario_table(small), core.scenario_table(large)
    for k in (0, n // 2, n - 1):
        np.testing.assert_array_equal(table_large.weather[k], table_small.weather[k])
    for i, (source, sown) in enumerate(zip(added_sources, added_sowing_dates)):
        assert str(table_large.sowing_dates[n + part_seasons * i]) == sown
        assert table_large.sources[n + part_seasons * i].startswith(f"generator({source}")
    return table_small, table_large


def test_climates8_holds_climates6s_seasons_first_and_two_parts_sown_may_1():
    _grown_task_tables("climates6-quota", "climates8-quota", ["benton-late", "benton-late-warm"],
                       ["benton, seed=4", "benton+4C, seed=5"], ["2000-05-01", "2000-05-01"])


def test_climates10_holds_climates8s_seasons_first_and_two_hotter_drier_parts():
    _, table10 = _grown_task_tables("climates8-quota", "climates10-quota", ["benton-hot-dry", "benton-march15-hot-dry"],
                                    ["benton+6C+8DPD, seed=6", "benton+6C+8DPD, seed=7"], ["2000-04-01", "2000-03-15"])
    assert get_scenario("benton-hot-dry-generated").weather.generated_climate == "benton+6C+8DPD"
    # drier air than the part warmed as much without drying would have: vapour pressure is WEATHER_NAMES' vap_hpa
    vap = WEATHER_NAMES.index("vap_hpa")
    assert table10.weather[8000:8050, :100, vap].mean() < 0.8 * table10.weather[4000:4050, :100, vap].mean()
    # drying is a generator's option, for a generator fitted with humidity data, within +-10 degC
    values = {"name": "x", "crop": "potato", "cultivar": "Russet Burbank", "soil": "Benton USA potato",
              "sowing_date": "2000-04-01"}
    with pytest.raises(ValueError, match="only a 'generator' source can be warmed, dried"):
        scenario_from_dict({**values, "weather": {"kind": "seasons", "drying_degc": 1.0, "seasons": [
            {"path": "a.wth", "format": "dssat", "sowing_date": "2000-04-01"}]}})
    with pytest.raises(ValueError, match="weather.drying_degc"):
        scenario_from_dict({**values, "weather": {"kind": "generator", "generator": "benton", "drying_degc": -11}})
    with pytest.raises(ValueError, match="gainesville was fitted without humidity data"):
        scenario_from_dict({**values, "weather": {"kind": "generator", "generator": "gainesville", "drying_degc": 2}})


def test_climates12_holds_climates10s_seasons_first_and_its_hot_dry_parts_with_a_third_of_the_rain():
    _, table12 = _grown_task_tables("climates10-quota", "climates12-quota", ["benton-hot-arid", "benton-march15-hot-arid"],
                                    ["benton+6C+8DPDx0.3R, seed=8", "benton+6C+8DPDx0.3R, seed=9"],
                                    ["2000-04-01", "2000-03-15"])
    rain = WEATHER_NAMES.index("rain_mm")
    arid, dry = table12.weather[10_000:10_100, :100, rain].sum(axis=1), table12.weather[8000:8100, :100, rain].sum(axis=1)
    assert 0 < arid.mean() < 0.5 * dry.mean()
    values = {"name": "x", "crop": "potato", "cultivar": "Russet Burbank", "soil": "Benton USA potato",
              "sowing_date": "2000-04-01"}
    with pytest.raises(ValueError, match="weather.rain_factor"):
        scenario_from_dict({**values, "weather": {"kind": "generator", "generator": "benton", "rain_factor": -1}})
    with pytest.raises(ValueError, match="only a 'generator' source can be warmed, dried, its diurnal range widened, "
                                         "its rain scaled"):
        scenario_from_dict({**values, "weather": {"kind": "seasons", "rain_factor": 0.5, "seasons": [
            {"path": "a.wth", "format": "dssat", "sowing_date": "2000-04-01"}]}})


def test_climates_spread_holds_climates12s_seasons_first_and_6000_seasons_each_in_its_own_climate():
    from crop_sim_ros.weather.generator import climate_parameters, generator_of_source
    first = get_scenario("benton-spread-generated").load_seasons()[0]
    _, table = _grown_task_tables("climates12-quota", "climates-spread-quota", ["benton-spread"],
                                  [f"{generator_of_source(first.source)}, seed=10, season=0"], [str(first.start)],
                                  part_seasons=6000)
    spread = table.sources[12_000:]
    climates = {generator_of_source(source) for source in spread}
    assert len(climates) > 5000  # (nearly) every season its own climate, each one a climate the generator reads back
    assert all(climate_parameters(c).name == c for c in list(climates)[:50])
    sown = np.array([np.datetime64(d, "D") for d in table.sowing_dates[12_000:]]) - np.datetime64("2000-03-01")
    assert sown.astype(int).min() == 0 and sown.astype(int).max() == 61
    with pytest.raises(ValueError, match="each season draws its own climate"):
        get_scenario("benton-spread-generated").weather.generated_climate
    values = {"name": "x", "crop": "potato", "cultivar": "Russet Burbank", "soil": "Benton USA potato",
              "sowing_date": "2000-04-01"}
    generator = {"kind": "generator", "generator": "benton"}
    for weather, message in (
            ({**generator, "warming_degc": 1.0, "spread": {"warming_degc": [0, 2]}},
             "weather.spread: each season draws"),
            ({**generator, "spread": {"warming_degc": [2, 0]}},
             r"weather.spread.warming_degc: \[2(\.0)?, 0(\.0)?\] is not a range"),
            ({**generator, "spread": {"rain_factor": [0.5, 4]}}, "weather.spread.rain_factor: 4 is not"),
            ({**generator, "spread": {"sowing_delay_days": [0, 1.5]}}, "weather.spread.sowing_delay_days: .* whole"),
            ({**generator, "spread": {"warming": [0, 1]}}, "weather.spread.warming: unknown field"),
            ({**generator, "spread": {"warming_degc": 3}}, r"weather.spread.warming_degc: expected \[least, most\]"),
            ({**generator, "spread": [0, 1]}, "weather.spread: expected a mapping"),
            ({**generator, "generator": "gainesville", "spread": {"drying_degc": [0, 2]}}, "without humidity data"),
            ({"kind": "seasons", "spread": {"warming_degc": [0, 2]},
              "seasons": [{"path": "a.wth", "format": "dssat", "sowing_date": "2000-04-01"}]},
             "only a 'generator' source can be warmed, dried, its diurnal range widened, its rain scaled, brightened or "
             "spread"),
            ({**generator, "radiation_factor": 1.2, "spread": {"warming_degc": [0, 2]}},
             "weather.spread: each season draws"),
            ({**generator, "radiation_factor": 2.5}, r"weather.radiation_factor: 2.5 is not"),
            ({**generator, "diurnal_range_degc": -12}, r"weather.diurnal_range_degc: -12 is not"),
            ({**generator, "diurnal_range_degc": 2, "spread": {"warming_degc": [0, 2]}},
             "weather.spread: each season draws"),
            ({"kind": "seasons", "radiation_factor": 1.2,
              "seasons": [{"path": "a.wth", "format": "dssat", "sowing_date": "2000-04-01"}]},
             "only a 'generator' source can be warmed, dried, its diurnal range widened, its rain scaled, brightened")):
        with pytest.raises(ValueError, match=message):
            scenario_from_dict({**values, "weather": weather})


def test_real_seasons_name_their_sites_climate_and_only_they_do():
    assert [get_scenario(n).weather.climate for n in ("heldout", "maricopa-real", "gainesville-real")] == [
        "benton", "maricopa", "gainesville"]
    assert get_scenario("maricopa-generated").weather.climate == ""
    real = {"kind": "seasons", "seasons": [{"path": "a.wth", "format": "dssat", "sowing_date": "2000-04-01"}]}
    values = {"name": "x", "crop": "potato", "cultivar": "Russet Burbank", "soil": "Benton USA potato",
              "sowing_date": "2000-04-01"}
    assert scenario_from_dict({**values, "weather": {**real, "climate": "maricopa"}}).weather.climate == "maricopa"
    with pytest.raises(ValueError, match="weather.climate: 'mars' is not one of benton"):
        scenario_from_dict({**values, "weather": {**real, "climate": "mars"}})
    with pytest.raises(ValueError, match="a 'generator' source's climate is its generator's"):
        scenario_from_dict({**values, "weather": {"kind": "generator", "generator": "benton", "climate": "benton"}})


def test_the_smaller_pivot_task_grows_benton_early_quotas_seasons_within_5_5_mm_a_day():
    pivot, early = get_scenario("benton-early-pivot"), get_scenario("benton-early-quota")
    assert pivot.limits.capacity_mm_per_day == 5.5 and early.limits.capacity_mm_per_day == 8.0
    assert pivot.limits.quota_mm == early.limits.quota_mm and pivot.weather == early.weather
    small, large = IrrigationVectorEnv(3, pivot), IrrigationVectorEnv(3, early)
    obs_small, _ = small.reset(seed=4)
    obs_large, _ = large.reset(seed=4)
    capacity = EXTENDED.index("capacity_mm_per_day")
    assert np.all(obs_small[:, capacity] == 5.5) and np.all(obs_large[:, capacity] == 8.0)
    np.testing.assert_array_equal(np.delete(obs_small, capacity, axis=1), np.delete(obs_large, capacity, axis=1))
    obs_small, *_ = small.step(np.full(3, 20.0))
    obs_large, *_ = large.step(np.full(3, 20.0))
    yesterday = EXTENDED.index("irrigation_yesterday_mm")
    assert np.all(obs_small[:, yesterday] == 5.5) and np.all(obs_large[:, yesterday] == 8.0)


def test_climates_hot_holds_climates12s_four_hot_dry_parts_alone_with_their_seasons():
    from crop_sim_ros.task.scenario import climates
    hot, twelve = get_scenario("climates-hot-quota"), get_scenario("climates12-quota")
    assert list(climates(hot)) == list(climates(twelve))[8:] and hot.n_seasons == 4000
    assert (hot.economics, hot.limits, hot.noise) == (twelve.economics, twelve.limits, twelve.noise)
    table_hot, table12 = core.scenario_table(hot), core.scenario_table(twelve)
    for k in (0, 3999):  # the parts' own seasons, as climates12-quota holds them from position 8000 on
        np.testing.assert_array_equal(table_hot.weather[k], table12.weather[8000 + k])


def test_maricopa_sown_spread_sows_each_maricopa_season_on_its_own_day_from_february_7_to_march_31():
    from crop_sim_ros.weather.generator import generator_of_source
    table = core.scenario_table(get_scenario("maricopa-sown-spread-quota"))
    sown = np.array([np.datetime64(d, "D") for d in table.sowing_dates])
    assert len(sown) == 1000 and {generator_of_source(s) for s in table.sources} == {"maricopa"}
    assert str(sown.min()) == "2001-02-07" and str(sown.max()) == "2001-03-31"
    assert len(np.unique(sown)) == 53  # every day of the window
    assert {"2001-02-28", "2001-03-15"} <= {str(d) for d in sown}  # both late-sown held-out sets' dates


def test_every_family_scenario_loads_and_steps():
    for name in ("benton-money", "benton-quota", "benton-capacity", "benton-sensing", "benton-blind",
                 "climates-quota", "climates3-quota", "benton-early-quota", "benton-early-pivot",
                 "climates4-quota", "benton-early-warm-quota", "climates6-quota", "maricopa-late-quota",
                 "climates8-quota", "climates10-quota", "climates12-quota", "maricopa-sown-spread-quota",
                 "climates-hot-quota"):
        env = IrrigationVectorEnv(4, name)
        obs, _ = env.reset(seed=0)
        obs, rewards, *_ = env.step(np.full(4, 5.0))
        assert obs.shape == (4, 29) and np.all(np.isfinite(obs)) and np.all(rewards < 0)


@pytest.mark.parametrize("env_id", ["crop-sim/benton-quota-v0", "crop-sim/benton-sensing-v0"])
def test_family_env_ids_pass_the_gymnasium_and_sb3_checkers(env_id):
    import gymnasium as gym
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env
    env = gym.make(env_id)
    assert env.observation_space.shape == (29,)
    check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(env.unwrapped, warn=False)
