"""Policies: the shared interface, the rules on hand-made observations, the hindsight oracle, the SB3
policy file loader and the evaluation table (fast: no training)."""

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from crop_agent_ros.policies import (ConstantPolicy, Policy, RefillPolicy, ZeroPolicy, make_policy)
from crop_agent_ros.policies.base import (OBS_SIZE, SeasonContext)

ROOT = Path(__file__).resolve().parents[1]


# The observation below: TMAX 25, TMIN 10 degC, SRAD 25 MJ/m2, VAP 12 hPa, wind 2 m/s on day 50 after an
# early-April sowing (day of year 95 + 50), at Benton County, WA (46.2 N, 200 m).
OBSERVED_DAY_OF_YEAR = 95 + 50
BENTON_LATITUDE_DEG, BENTON_ELEVATION_M = 46.2, 200.0
UPTAKE_PER_DAY = 0.096  # ARID's water uptake coefficient


def fao56_et0_mm(tmax, tmin, srad_mj_m2, vap_hpa, wind_m_s, day_of_year, latitude_deg, elevation_m):
    """FAO-56 Penman-Monteith grass reference ET0, mm/day, written out from FAO-56 eqs. 6-40 (Allen et al.
    1998), G = 0; independent of the library the code uses (they agree to ~1e-4)."""
    def e0(t):
        return 0.6108 * math.exp(17.27 * t / (t + 237.3))
    tmean = (tmax + tmin) / 2
    gamma = 0.000665 * 101.3 * ((293 - 0.0065 * elevation_m) / 293) ** 5.26
    es, ea = (e0(tmax) + e0(tmin)) / 2, vap_hpa / 10
    delta = 4098 * e0(tmean) / (tmean + 237.3) ** 2
    phi = math.radians(latitude_deg)
    dr = 1 + 0.033 * math.cos(2 * math.pi * day_of_year / 365)
    declination = 0.409 * math.sin(2 * math.pi * day_of_year / 365 - 1.39)
    ws = math.acos(-math.tan(phi) * math.tan(declination))
    ra = 24 * 60 / math.pi * 0.0820 * dr * (ws * math.sin(phi) * math.sin(declination)
                                            + math.cos(phi) * math.cos(declination) * math.sin(ws))
    rso = (0.75 + 2e-5 * elevation_m) * ra
    rnl = (4.903e-9 * ((tmax + 273.16) ** 4 + (tmin + 273.16) ** 4) / 2 * (0.34 - 0.14 * math.sqrt(ea))
           * (1.35 * min(srad_mj_m2 / rso, 1.0) - 0.35))
    rn = 0.77 * srad_mj_m2 - rnl
    return ((0.408 * delta * rn + gamma * 900 / (tmean + 273) * wind_m_s * (es - ea))
            / (delta + gamma * (1 + 0.34 * wind_m_s)))


# ET0 / 0.096 of observation(): the plant-available water at which transpiration meets the day's demand.
NO_STRESS_LEVEL_MM = fao56_et0_mm(25, 10, 25, 12, 2, OBSERVED_DAY_OF_YEAR, BENTON_LATITUDE_DEG,
                                  BENTON_ELEVATION_M) / UPTAKE_PER_DAY
LEVEL_TOLERANCE_MM = 0.02  # the hand FAO-56 and the library's ASCE form differ by ~0.007 mm here


def observation(paw=60.0, today_rain=0.0, forecast_rain=0.0, day=50):
    obs = np.array([5.0, 800.0, day, 25, 10, 17.5, today_rain, 25, 369, 12, 2,
                    25, 10, 17.5, forecast_rain, 25, 369, 12, 2, paw], dtype=np.float32)
    assert obs.shape == (OBS_SIZE,)
    return obs


@pytest.mark.parametrize("name", ["zero", "constant10", "constant3.5", "best-constant", "refill", "margin4"])
def test_every_rule_has_the_interface(name):
    policy = make_policy(name)
    assert isinstance(policy, Policy)
    assert isinstance(policy.name, str) and policy.name
    policy.reset(seed=0)
    single = policy.act(observation())
    assert isinstance(single, float) and 0.0 <= single <= 100.0
    batch = policy.act(np.stack([observation(paw=p) for p in (10.0, 60.0, 119.0)]))
    assert batch.shape == (3,) and np.all((batch >= 0) & (batch <= 100))


def test_bad_observation_shape_and_unknown_names_are_rejected():
    with pytest.raises(ValueError, match="shape"):
        ZeroPolicy().act(np.zeros(19))
    with pytest.raises(ValueError, match="unknown policy"):
        make_policy("sprinkler")
    with pytest.raises(ValueError):
        ConstantPolicy(150.0)


def test_zero_and_constant():
    assert ZeroPolicy().act(observation()) == 0.0
    assert ConstantPolicy(10.0).act(observation()) == 10.0
    assert np.all(make_policy("constant10").act(np.stack([observation()] * 4)) == 10.0)


def test_refill_irrigates_to_target_below_threshold():
    rule = RefillPolicy(threshold_mm=70.0, target_mm=100.0, skip_rain_mm=10.0)
    assert rule.act(observation(paw=50.0)) == pytest.approx(50.0)           # 100 - 50
    assert rule.act(observation(paw=50.0, today_rain=8.0)) == pytest.approx(42.0)  # today's rain counts
    assert rule.act(observation(paw=80.0)) == 0.0                            # above the threshold
    assert rule.act(observation(paw=0.0)) == 100.0                           # capped at 100 mm


def test_refill_skips_when_rain_is_forecast():
    rule = RefillPolicy(threshold_mm=70.0, target_mm=100.0, skip_rain_mm=10.0)
    assert rule.act(observation(paw=50.0, forecast_rain=25.0)) == 0.0
    assert rule.act(observation(paw=50.0, forecast_rain=5.0)) == pytest.approx(50.0)


def test_refill_parameters_per_field():
    rule = RefillPolicy(threshold_mm=np.array([70.0, 40.0]), target_mm=np.array([100.0, 90.0]), skip_rain_mm=10.0)
    np.testing.assert_allclose(rule.act(np.stack([observation(paw=50.0)] * 2)), [50.0, 0.0])


def test_demand_margin_rule_refills_to_the_no_stress_level_plus_margin():
    level = NO_STRESS_LEVEL_MM  # ~50.3 mm
    assert make_policy("margin4").act(observation(paw=30.0)) == pytest.approx(level + 4.0 - 30.0,
                                                                              abs=LEVEL_TOLERANCE_MM)
    assert make_policy("margin4").act(observation(paw=30.0, today_rain=5.0)) == pytest.approx(
        level + 4.0 - 5.0 - 30.0, abs=LEVEL_TOLERANCE_MM)
    assert make_policy("margin0").act(observation(paw=level + 1.0)) == 0.0
    assert make_policy("margin0").act(observation(paw=level - 1.0)) == pytest.approx(1.0, abs=LEVEL_TOLERANCE_MM)


def test_tuned_rules_come_from_generated_seasons():
    from crop_agent_ros.policies.rules import BEST_CONSTANT_FILE, REFILL_FILE
    from crop_agent_ros.policies.tuning import MARGIN_FILE
    for path in (BEST_CONSTANT_FILE, REFILL_FILE, MARGIN_FILE):
        tuned = json.loads(path.read_text())
        assert tuned["tuned_on"]["scenario"] == "benton-generated"
    # The loader gives the file's rate, and the file's rate is the best of its own grid.
    constant = json.loads(BEST_CONSTANT_FILE.read_text())
    assert make_policy("best-constant").mm_per_day == constant["mm_per_day"]
    best_rate, best_return = max(constant["grid"].items(), key=lambda item: item[1])
    assert float(best_rate) == constant["mm_per_day"] and best_return == constant["mean_return"]
    refill = json.loads(REFILL_FILE.read_text())["parameters"]
    rule = make_policy("refill")
    below, above = refill["threshold_mm"] - 1.0, refill["threshold_mm"] + 1.0
    assert rule.act(observation(paw=below)) == pytest.approx(refill["target_mm"] - below)
    assert rule.act(observation(paw=above)) == 0.0
    assert rule.act(observation(paw=below, forecast_rain=refill["skip_rain_mm"] + 1.0)) == 0.0


# --- the hindsight oracle -------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def short_season():
    """The first 70 days of the paper's real season (Benton E. 2000), harvested on day 60."""
    from crop_agent_ros.policies.rollout import season_contexts
    full = season_contexts("benton-2000")[0]
    days = 70
    params = replace(full.params, harvest_day=np.array([60.0]))
    return SeasonContext("benton-2000-short", params, full.tmax_degc[:days], full.tmin_degc[:days],
                         full.srad_mj_m2[:days], full.rain_mm[:days], full.et0_mm[:days], full.water_cost_per_mm)


def test_oracle_beats_constant_and_zero_on_a_short_real_season(short_season):
    from crop_agent_ros.policies.oracle import find_best_schedule, schedule_returns
    result = find_best_schedule(short_season, finest_step_mm=0.25)
    schedule = result.schedule_mm
    assert schedule.shape == (70,) and np.all(np.isfinite(schedule))
    assert np.all((schedule >= 0.0) & (schedule <= 100.0))
    days = len(schedule)
    returns, _ = schedule_returns(short_season, np.stack([schedule, np.zeros(days), np.full(days, 10.0),
                                                          np.full(days, 5.0)], axis=1))
    assert returns[0] == pytest.approx(result.return_value)
    assert returns[0] >= returns[1] and returns[0] >= returns[2] and returns[0] >= returns[3]
    assert result.return_value <= result.potential_yield_t_ha + 1e-9  # the rigorous bound
    assert result.bound_gap >= 0.0


def test_oracle_policy_plays_its_schedule_by_day(short_season):
    from crop_agent_ros.policies.oracle import OraclePolicy
    oracle = make_policy("oracle")
    assert isinstance(oracle, OraclePolicy)
    with pytest.raises(RuntimeError):
        oracle.act(observation())
    oracle.search_options = {"finest_step_mm": 1.0}
    oracle.begin_season(short_season)
    schedule = oracle.result.schedule_mm
    assert oracle.act(observation(day=30)) == pytest.approx(schedule[30])
    oracle.begin_season([short_season, short_season])
    np.testing.assert_allclose(oracle.act(np.stack([observation(day=3), observation(day=40)])),
                               [schedule[3], schedule[40]])


# --- the SB3 policy file ------------------------------------------------------------------------------

# A network whose action is 0.25 whatever it sees, and the mm each mode makes of it (action mapping in
# crop_agent_ros/policies/sb3.py) at PAW 20, 45 and 110 mm, with the policy file's margin centre of 6 mm:
NETWORK_ACTION = 0.25
EXPECTED_MM = {
    "mm": lambda paw: (NETWORK_ACTION + 1) / 2 * 100,
    "target": lambda paw: min(max(20 + (NETWORK_ACTION + 1) / 2 * (140 - 20) - paw, 0.0), 100.0),
    "margin": lambda paw: min(max(NO_STRESS_LEVEL_MM + 6.0 + 15 * NETWORK_ACTION - paw, 0.0), 100.0),
    "demand": lambda paw: min(max((1 + NETWORK_ACTION) * NO_STRESS_LEVEL_MM + 6.0 - paw, 0.0), 100.0),
}


@pytest.mark.parametrize("mode", ["mm", "target", "margin", "demand"])
def test_sb3_loader_round_trips_a_ppo_with_a_known_action(tmp_path, mode):
    import gymnasium as gym
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    from crop_agent_ros.policies.sb3 import N_FEATURES, SB3Policy

    class Dummy(gym.Env):
        observation_space = gym.spaces.Box(-10, 10, (N_FEATURES,), np.float32)
        action_space = gym.spaces.Box(-1, 1, (1,), np.float32)

        def reset(self, *, seed=None, options=None):
            return np.zeros(N_FEATURES, np.float32), {}

        def step(self, action):
            return np.zeros(N_FEATURES, np.float32), 0.0, True, False, {}

    model = PPO("MlpPolicy", make_vec_env(Dummy, 1), n_steps=8, batch_size=8, policy_kwargs={"net_arch": [8]},
                seed=0, device="cpu")
    with torch.no_grad():  # the mean action is the output layer's bias alone
        model.policy.action_net.weight.zero_()
        model.policy.action_net.bias.fill_(NETWORK_ACTION)
    path = tmp_path / "tiny.zip"
    model.save(path)
    (tmp_path / "tiny.json").write_text(json.dumps({"action_mode": mode, "feature_set": "full",
                                                    "action_mapping": {"margin_center_mm": 6.0}}))
    policy = make_policy(f"ppo:{path}")
    assert isinstance(policy, SB3Policy) and policy.action_mode == mode
    paws = (20.0, 45.0, 110.0)
    got = policy.act(np.stack([observation(paw=p) for p in paws]))
    np.testing.assert_allclose(got, [EXPECTED_MM[mode](p) for p in paws], rtol=0, atol=1.25 * LEVEL_TOLERANCE_MM)
    single = policy.act(observation(paw=20.0))
    assert isinstance(single, float) and single == pytest.approx(EXPECTED_MM[mode](20.0), abs=1.25 * LEVEL_TOLERANCE_MM)


def test_missing_policy_file_says_so(tmp_path):
    with pytest.raises(FileNotFoundError):
        make_policy(f"ppo:{tmp_path / 'none.zip'}")


def test_features_are_finite_and_bounded():
    from crop_agent_ros.policies.sb3 import N_FEATURES, features
    x = features(np.stack([observation(paw=p, today_rain=r) for p, r in ((0, 0), (60, 30), (150, 0))]))
    assert x.shape == (3, N_FEATURES) and x.dtype == np.float32
    assert np.all(np.isfinite(x)) and np.all(np.abs(x) <= 10)


# --- evaluation ----------------------------------------------------------------------------------------

def test_parse_seeds():
    from crop_agent_ros.learning.evaluate import parse_seeds
    assert parse_seeds("0..3") == [0, 1, 2, 3]
    assert parse_seeds("4,7") == [4, 7]


def test_evaluate_table_on_a_tiny_run(tmp_path):
    from crop_agent_ros.learning.evaluate import evaluate, format_table, paired_difference, summarize
    rows, episodes, oracle_results, contexts = evaluate(["zero", "constant10", "oracle"], "benton-2000", [0, 1],
                                                        record=True)
    assert len(rows) == 3 * 2 * 1
    summary = summarize(rows)
    assert summary["zero"]["irrigation_mm"]["mean"] == 0.0
    assert summary["constant10"]["irrigation_mm"]["mean"] > 1000
    assert summary["oracle"]["regret"]["mean"] == pytest.approx(0.0, abs=1e-9)
    for name in ("zero", "constant10"):
        assert summary[name]["regret"]["mean"] > 0.0
        assert summary[name]["return"]["mean"] <= oracle_results[0].return_value
    e = summary["constant10"]
    assert 0.9 < e["normalized_return"]["mean"] <= 1.0
    row = next(r for r in rows if r["policy"] == "constant10")
    assert row["water_productivity_kg_m3"] == pytest.approx(
        row["yield_t_ha"] * 1000 / ((row["irrigation_mm"] + row["rain_mm"]) * 10))
    diff = paired_difference(rows, "constant10", "zero")
    assert diff["n"] == 2 and diff["wins"] == 2 and diff["mean"] > 5
    table = format_table(summary)
    assert "constant10" in table and "regret" in table
    assert episodes["zero"][0].daily["paw_mm"].shape[1] == 1


@pytest.mark.parametrize("mode", ["mm", "target", "margin", "demand"])
@pytest.mark.parametrize("feature_set", ["full", "compact", "phenology"])
def test_every_action_mode_and_feature_set_is_well_formed(mode, feature_set):
    from crop_agent_ros.policies.sb3 import FEATURE_SETS, action_to_mm, features

    obs = np.stack([observation(paw=p, today_rain=r) for p, r in ((0, 0), (60, 30), (150, 0))])
    x = features(obs, feature_set)
    assert x.shape == (3, FEATURE_SETS[feature_set]) and np.all(np.isfinite(x))
    for action in (-1.0, 0.0, 1.0):
        mm = action_to_mm(np.full((3, 1), action, dtype=np.float32), obs, mode)
        assert mm.shape == (3,) and np.all((mm >= 0) & (mm <= 100))
    # More water in the soil never asks for more irrigation.
    mm = action_to_mm(np.zeros((2, 1), dtype=np.float32), obs[[0, 2]], mode)
    assert mm[0] >= mm[1]


def test_demand_mode_can_stop_irrigating():
    from crop_agent_ros.policies.sb3 import action_to_mm

    assert action_to_mm(np.array([[-1.0]], dtype=np.float32), observation(paw=10.0)[None], "demand")[0] == 0


def test_one_registry_names_every_policy_and_the_node_runs_its_kinds():
    from crop_agent_ros.policies import NODE_POLICIES, POLICY_KINDS, PolicyArguments, build_policy
    from crop_agent_ros.ros.agent import PARAMETERS

    assert set(NODE_POLICIES) == {name for name, kind in POLICY_KINDS.items() if kind.node}
    assert "oracle" not in NODE_POLICIES and {"budget-rule", "agent", "ppo"} <= set(NODE_POLICIES)
    # the node's parameter descriptor and the launch file's argument list the registry's node kinds
    assert PARAMETERS["policy"][1].additional_constraints == " | ".join(NODE_POLICIES)
    assert "description=\" | \".join(NODE_POLICIES)" in (ROOT / "launch" / "farm.launch.py").read_text()
    assert build_policy("constant", PolicyArguments(constant_mm=3.5)).act(observation()) == 3.5
    assert make_policy("constant").act(observation()) == 10.0  # the paper's baseline
    with pytest.raises(ValueError, match="unknown policy 'oracle'; known: zero, constant"):
        build_policy("oracle", node=True)
    with pytest.raises(ValueError, match="budget-rule needs a family task"):
        build_policy("budget-rule")
    with pytest.raises(ValueError, match="agent needs policy_file"):
        make_policy("agent")
    assert build_policy("budget-rule", PolicyArguments(task="benton-quota")).name
