"""The climate outlook a family agent may read (crop_agent_ros.policies.outlook): normals, its two values, the
climates of a pool's seasons, and an agent that reads it in training, from a file and in an evaluation."""

from __future__ import annotations

import datetime
import json

import numpy as np
import pytest

from crop_agent_ros.policies import outlook
from crop_agent_ros.policies.rollout import season_contexts
from crop_sim_ros.task import get_scenario
from crop_sim_ros.task.layout import EXTENDED

from policy_files import tiny_task_training

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


def test_an_outlook_agent_trains_from_files_and_reads_its_climates_in_an_evaluation(tmp_path):
    from crop_agent_ros.learning import imitation
    from crop_agent_ros.learning.agent import LearnedPolicy
    from crop_agent_ros.learning.evaluate_task import Unit, evaluation_sets, run_unit, set_terms
    from crop_agent_ros.policies import family_mpc as fm
    from crop_agent_ros.policies.rollout import run_episodes
    cheap = fm.MpcSettings(scenarios=1, decision_every_days=30, replan_first_step_mm=2.0, finest_step_mm=1.0)
    data = imitation.demonstrate("benton-early-quota", np.array([5]), cheap, action_noise_mm=0.0, seed=2)
    np.savez_compressed(tmp_path / "early.npz", **data)
    loaded = imitation.load_demonstrations([str(tmp_path / "early.npz")], "climates3-quota")
    assert set(loaded["climate"]) == {"benton"} and set(loaded["sowing_day"]) == {60}  # March 1 (2000: leap)
    out = tmp_path / "run"
    tiny_task_training(out, "climates3-quota", 1, "--outlook", "--imitate", str(tmp_path / "early.npz"),
                       "--imitation-epochs", "2", timesteps=256)
    config = json.loads((out / "model.json").read_text())
    assert config["outlook"] == outlook.ClimateOutlook().record()
    agent = LearnedPolicy(out / "model.zip")
    assert agent.interface.input_size == EXTENDED.size + 2 and agent.describe()["outlook"] == config["outlook"]
    inputs, order = imitation.network_inputs(agent.interface, loaded)
    np.testing.assert_allclose(inputs[:, -2:], outlook.features(
        loaded["climate"][order], loaded["sowing_day"][order], loaded["observations"][order]), rtol=1e-6)
    assert np.all(np.isfinite(run_episodes(agent, "climates3-quota", np.array([1, 2500]), seed=0).episode_return))
    # the evaluation tells it a real set's site climate; a generated set's seasons carry their own
    sets = {s.name: s for s in evaluation_sets(get_scenario("climates3-quota"), 2)}
    assert (sets["heldout-real"].site_climate, sets["maricopa-real"].site_climate) == ("benton", "maricopa")
    assert sets["maricopa-generated"].site_climate is None
    real = sets["maricopa-real"]
    terms = set_terms(real, 1)
    result = run_unit(Unit(0, "agent", 0, 0, len(real.seasons)), real, terms, agent)
    assert result.returns.shape == (len(real.seasons),) and np.all(np.isfinite(result.returns))
    assert agent.interface.outlook.climates == ["maricopa"] * len(real.seasons)
    # the agent node's policy: its climate parameter is the site climate; an unknown one is refused at load
    from crop_agent_ros.ros.agent import make_agent_policy
    node_policy = make_agent_policy("agent", policy_file=str(out / "model.zip"), climate="maricopa")
    assert node_policy.site_climate == "maricopa" and node_policy.outlook is not None
    with pytest.raises(ValueError, match="no climate 'mars'"):
        make_agent_policy("agent", policy_file=str(out / "model.zip"), climate="mars")
    # one field's season, as a simulator's reset gives it: the generator of its weather, else the site climate
    node_policy.begin_field_season("generator(gainesville, seed=0, season=3)", "2001-01-15")
    assert node_policy.outlook.climates == ["gainesville"] and list(node_policy.outlook.sowing_days) == [14]
    node_policy.begin_field_season("simple_r_inputs/Weather/AZ000701.WTH", "2008-01-15")
    assert node_policy.outlook.climates == ["maricopa"]
    node_policy.site_climate = None
    with pytest.raises(ValueError, match="was not generated and no site climate was given"):
        node_policy.begin_field_season("simple_r_inputs/Weather/AZ000701.WTH", "2008-01-15")


def test_todays_share_of_the_normal_demand_left_and_the_rule_that_budgets_by_it():
    from crop_agent_ros.policies.family import FarmFacts, WaterBudgetRule
    obs = np.zeros((2, EXTENDED.size))
    days_left = EXTENDED.index("season_days_left")
    obs[:, DAY], obs[:, days_left], obs[:, QUOTA] = [10, 100], [140, 0], [200.0, 50.0]
    share = outlook.normal_share_today(["maricopa", "benton"], [14, 300], obs)
    normals_m, normals_b = outlook.normal_et0_mm("maricopa"), outlook.normal_et0_mm("benton")
    np.testing.assert_allclose(share[0], normals_m[24] / normals_m[24:164].sum())
    np.testing.assert_allclose(share[1], 1.0)  # the last day: all that is left is today's
    # a rule with outlook_pace spends at most pace x quota left x that share
    facts = FarmFacts(capacity_mm=120.0, tsum_degc_d=1500.0)
    plain = WaterBudgetRule(facts, {"margin_mm": 40.0})
    paced = WaterBudgetRule(facts, {"margin_mm": 40.0, "outlook_pace": 2.0})
    assert plain.outlook is None and paced.outlook is not None
    field = np.zeros((1, EXTENDED.size))
    field[0, DAY], field[0, days_left], field[0, QUOTA] = 30, 120, 100.0
    field[0, EXTENDED.index("capacity_mm_per_day")], field[0, EXTENDED.index("et0_mm")] = 25.0, 5.0
    field[0, EXTENDED.index("paw_mm")], field[0, EXTENDED.index("paw_observed")] = 20.0, 1.0
    field[0, EXTENDED.index("tuber_price_usd_per_t")] = 200.0
    with pytest.raises(ValueError, match="reads its fields' climate"):
        paced.act(field)
    paced.outlook.set_fields(["benton"], [90])
    wanted = plain.act(field)[0]
    limit = 2.0 * 100.0 * outlook.normal_share_today(["benton"], [90], field)[0]
    assert 0.0 < limit < wanted and paced.act(field)[0] == pytest.approx(limit)


def test_the_tuner_searches_the_climatological_budget_only_when_asked():
    from crop_agent_ros.policies import family_tuning
    task = get_scenario("climates3-quota")
    seasons = family_tuning.training_seasons(task, 0, 0)
    plain = family_tuning.tune_rule(task, seasons, candidates=3, rounds=0, log=lambda *_: None)
    assert "outlook_pace" not in plain["parameters"]
    names = family_tuning.tuned_names(outlook=True)
    assert names == family_tuning.tuned_names(outlook=False) + ("outlook_pace",)
    asked = family_tuning.tune_rule(task, seasons, candidates=6, rounds=0, names=names, log=lambda *_: None)
    assert "outlook_pace" in asked["parameters"]
    assert family_tuning.rule_file("x", outlook=True).name == "family_x-outlook.json"


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
