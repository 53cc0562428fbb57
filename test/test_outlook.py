"""The climate outlook a family agent may read (crop_agent_ros.policies.outlook): normals, its two values, the
climates of a pool's seasons, and an agent that reads it in training, from a file and in an evaluation."""

from __future__ import annotations

import datetime

import numpy as np
import pytest

from crop_agent_ros.policies import outlook
from crop_agent_ros.policies.rollout import season_contexts
from crop_sim_ros.task import get_scenario
from crop_sim_ros.task.layout import EXTENDED


DAY, QUOTA = EXTENDED.index("days_since_sowing"), EXTENDED.index("quota_remaining_mm")


def test_normals_are_the_generators_mean_year_and_a_warmed_climate_has_its_own():
    benton, maricopa = outlook.normal_et0_mm("benton"), outlook.normal_et0_mm("maricopa")
    assert benton.shape == maricopa.shape == (365,) and np.all(benton > 0)
    np.testing.assert_array_equal(outlook._normal_et0_mm.__wrapped__("benton"), benton)  # seeded: the same year
    assert benton[170:200].mean() > 2.0 * benton[:30].mean()  # a Washington summer against its winter
    assert maricopa[150:180].mean() > benton[150:180].mean()  # the desert in June
    assert np.all(outlook.normal_et0_mm("benton+4C")[120:240] > benton[120:240])
    for bad in ("atlantis", "benton+4", "benton*4C", "benton+xC"):
        with pytest.raises(ValueError, match="climate outlook: no climate"):
            outlook.normal_et0_mm(bad)


def test_the_two_values_are_water_left_against_demand_ahead_and_that_demands_trend():
    obs = np.zeros((3, EXTENDED.size))
    obs[:, DAY], obs[:, QUOTA] = [0, 40, 40], [300.0, 120.0, 0.0]
    climates, sown = ["benton", "maricopa", "maricopa"], [59, 14, 14]  # March 1, January 15
    values = outlook.features(climates, sown, obs)
    for i in range(3):
        normals = outlook.normal_et0_mm(climates[i])
        start = sown[i] + int(obs[i, DAY])
        ahead = normals[start:start + 60].sum()
        behind = normals[start - 14:start].mean()
        np.testing.assert_allclose(values[i], [np.log(max(obs[i, QUOTA], 1.0) / ahead),
                                               2.0 * np.log(ahead / (60.0 * behind))], rtol=1e-5)
    assert values[1, 1] > 0.0  # Maricopa's demand rises from mid-February
    # the year wraps: a field late in the year reads January's normals
    late = outlook.features(["benton"], [360], obs[:1])
    normals = outlook.normal_et0_mm("benton")
    ahead = normals[(360 + np.arange(60)) % 365].sum()
    np.testing.assert_allclose(late[0, 0], np.log(300.0 / ahead), rtol=1e-5)


def test_a_pools_seasons_have_their_parts_climates_and_sowing_days():
    pool = outlook.pool_climates(get_scenario("climates4-quota"))
    assert len(pool) == 4000
    assert [pool[k] for k in (0, 1000, 2000, 3999)] == [("benton", 91), ("gainesville", 31), ("benton", 60),
                                                         ("benton+4C", 60)]


def test_an_agent_is_told_its_fields_climates_before_the_season_or_refuses_to_act():
    reader = outlook.ClimateOutlook()
    obs = np.zeros((2, EXTENDED.size))
    with pytest.raises(ValueError, match="reads its fields' climate; .* was not"):
        reader(obs)
    contexts = season_contexts(get_scenario("climates4-quota"))
    reader.begin_season([contexts[5], contexts[3005]])
    assert reader.climates == ["benton", "benton+4C"] and list(reader.sowing_days) == [91, 60]
    assert reader(obs).shape == (2, 2)
    real = season_contexts(get_scenario("maricopa-real"))[:1]
    with pytest.raises(ValueError, match="was not generated and no site climate was given"):
        reader.begin_season(real)
    reader.begin_season(real, "maricopa")
    assert reader.climates == ["maricopa"] and reader.sowing_days[0] == 14
    with pytest.raises(ValueError, match="was told 1 fields, not 2"):
        reader(obs)


def test_a_rain_factor_leaves_a_climates_normals_and_a_spread_pool_reads_each_seasons_own():
    from crop_sim_ros.weather.generator import climate_parameters, generate_seasons
    years = generate_seasons(climate_parameters("benton+6C+8DPDx0.3R"), datetime.date(2001, 1, 1), 730,
                             outlook.NORMAL_YEARS, outlook.NORMALS_SEED)
    et0 = np.stack([y.et0_mm("penman_monteith") for y in years])
    direct = et0.reshape(outlook.NORMAL_YEARS, 2, 365).mean(axis=(0, 1))
    np.testing.assert_array_equal(outlook.normal_et0_mm("benton+6C+8DPDx0.3R"), direct)
    assert outlook.normal_et0_mm("benton+6C+8DPDx0.3R") is outlook.normal_et0_mm("benton+6C+8DPD")
    assert outlook.normal_et0_mm("benton+6C+8DPD").mean() > outlook.normal_et0_mm("benton").mean() + 0.5
    pool = outlook.pool_climates(get_scenario("climates-spread-quota"))
    assert len(pool) == 18_000 and pool[0] == ("benton", 91)
    spread = pool[12_000:]
    contexts = season_contexts(get_scenario("benton-spread-generated"))
    assert spread[17] == (outlook.climate_of_source(contexts[17].extra["source"]),
                          outlook.day_of_year(contexts[17].extra["sowing_date"]))
    assert len({climate for climate, _ in spread}) > 5000 and {day for _, day in spread} == set(range(60, 122))
