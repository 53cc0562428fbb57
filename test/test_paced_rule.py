"""The paced rule (crop_agent_ros/policies/paced_rule.py): what it reads, the limits it keeps, its tuned file and
its tuner's refusals. Fast: a few seasons, no tuning run."""

from __future__ import annotations

import json

import numpy as np
import pytest

from crop_agent_ros.policies import family_tuning
from crop_agent_ros.policies.base import SeasonContext
from crop_agent_ros.policies.paced_rule import PacedFacts, PacedParameters, PacedRule
from crop_agent_ros.policies.rollout import draw_terms, run_episodes
from crop_sim_ros.task.layout import EXTENDED
from crop_sim_ros.task.scenario import get_scenario

TASK = "benton-quota"
QUOTA = EXTENDED.index("quota_remaining_mm")
CAPACITY = EXTENDED.index("capacity_mm_per_day")
PAW = EXTENDED.index("paw_mm")


class Recorder:
    """Wraps a policy: keeps every observation batch it was shown and every action it gave."""

    def __init__(self, policy):
        self.policy, self.name = policy, policy.name
        self.observations, self.actions = [], []

    def reset(self, seed=None):
        self.policy.reset(seed)

    def act(self, obs):
        action = np.asarray(self.policy.act(obs), dtype=float)
        self.observations.append(np.array(obs, dtype=float))
        self.actions.append(action.copy())
        return action


@pytest.fixture(scope="module")
def scenario():
    return get_scenario(TASK)


@pytest.fixture(scope="module")
def shipped(scenario):
    return family_tuning.tuned_rule(TASK, "paced-rule")


@pytest.fixture(scope="module")
def recorded(scenario, shipped):
    """The shipped paced rule on 6 training seasons with tight quotas (the quota binds)."""
    seasons = np.arange(6)
    terms = draw_terms(scenario, seasons, 0)
    terms["quota_mm"] = np.linspace(150.0, 300.0, len(seasons))
    recorder = Recorder(shipped)
    episodes = run_episodes(recorder, scenario, seasons, seed=3, terms=terms)
    return recorder, episodes, terms


def test_facts_are_the_published_parameters_and_the_sensor_error(scenario):
    facts = PacedFacts.of_scenario(scenario)
    assert (facts.capacity_mm, facts.tsum_degc_d, facts.i50a_degc_d, facts.i50b_degc_d) == (120.0, 2300.0, 500.0, 400.0)
    assert (facts.i50_max_water_degc_d, facts.i50_max_heat_degc_d, facts.water_stress_sensitivity) == (30.0, 50.0, 0.4)
    assert facts.sensor_sd_mm == scenario.noise.paw_mm == 1.0
    assert PacedFacts.of_scenario(get_scenario("benton-sensing")).sensor_sd_mm == 10.0


def test_reads_only_the_observation(recorded, shipped):
    """Replaying the recorded observations into a fresh rule, told a false season (other weather, other terms)
    before it starts, gives the same actions: nothing but the observation enters."""
    recorder, _, _ = recorded
    fresh = family_tuning.tuned_rule(TASK, "paced-rule")
    fresh.reset(123)
    lie = SeasonContext(name="not this season", params=None, tmax_degc=np.full(200, 45.0), tmin_degc=np.zeros(200),
                        srad_mj_m2=np.ones(200), rain_mm=np.full(200, 50.0), et0_mm=np.ones(200),
                        extra={"terms": {"quota_mm": 1e6}})
    fresh.begin_season([lie] * len(recorder.observations[0]))
    for obs, action in zip(recorder.observations, recorder.actions):
        assert np.array_equal(fresh.act(obs), action)
    # ... and the observation does enter: a drier reading asks for more water on some day
    fresh.reset()
    drier = []
    for obs in recorder.observations:
        changed = obs.copy()
        changed[:, PAW] = np.maximum(changed[:, PAW] - 30.0, 0.0)
        drier.append(fresh.act(changed))
    assert sum(a.sum() for a in drier) > sum(a.sum() for a in recorder.actions)


def test_keeps_the_quota_and_the_capacity(recorded):
    recorder, episodes, terms = recorded
    for obs, action in zip(recorder.observations, recorder.actions):
        assert np.all(action >= 0.0)
        assert np.all(action <= obs[:, QUOTA] + 1e-9) and np.all(action <= obs[:, CAPACITY] + 1e-9)
    assert np.all(episodes.water_mm <= terms["quota_mm"] + 1e-6)
    assert np.all(episodes.water_mm > 0.5 * terms["quota_mm"])  # and it does spend a tight quota


def test_deterministic(scenario, shipped, recorded):
    _, episodes, terms = recorded
    again = run_episodes(shipped, scenario, np.arange(6), seed=3, terms=terms)
    assert np.array_equal(again.episode_return, episodes.episode_return)
    # one field alone acts as it does in a batch
    recorder, _, _ = recorded
    single = family_tuning.tuned_rule(TASK, "paced-rule")
    single.reset()
    for obs, action in zip(recorder.observations[:40], recorder.actions[:40]):
        assert single.act(obs[2]) == pytest.approx(action[2], abs=1e-12)


def test_batched_parameters_match_one_by_one(scenario, recorded):
    """The tuner's batched candidates (one parameter value per field) act as each candidate alone."""
    recorder, _, _ = recorded
    facts = PacedFacts.of_scenario(scenario)
    n = recorder.observations[0].shape[0]
    candidates = {"pace": np.linspace(0.6, 2.5, n), "narrow_degc_d": np.linspace(0.0, 900.0, n),
                  "senescence_weight": np.linspace(0.0, 2.0, n)}
    batched = PacedRule(facts, candidates)
    alone = [PacedRule(facts, {k: v[i] for k, v in candidates.items()}) for i in range(n)]
    for obs in recorder.observations:
        together = batched.act(obs)
        assert np.allclose(together, [rule.act(obs[i]) for i, rule in enumerate(alone)], atol=1e-12)


def test_tuned_file_loads_and_records_its_training(shipped):
    record = json.loads(family_tuning.family_file(TASK, "paced-rule").read_text())
    assert record["rule"] == "paced-rule" and record["scenario"] == TASK
    assert record["seasons"] == list(range(150))  # generated training seasons 0..149 only
    names = set(PacedParameters.names())
    assert names - set(PacedParameters.later()) <= set(record["parameters"]) <= names
    assert shipped.name == "paced-rule" and shipped.facts == PacedFacts.from_record(record["facts"])


@pytest.mark.parametrize("change", [
    lambda r: r["parameters"].pop("pace"),
    lambda r: r["parameters"].update(pace="fast"),
    lambda r: r["parameters"].update(extra=1.0),
    lambda r: r["facts"].pop("sensor_sd_mm"),
    lambda r: r.update(parameters=[1, 2]),
])
def test_malformed_file_is_refused_in_one_line(change, tmp_path, monkeypatch):
    record = json.loads(family_tuning.family_file(TASK, "paced-rule").read_text())
    change(record)
    monkeypatch.setattr(family_tuning, "HERE", tmp_path)
    (tmp_path / f"family_{TASK}-paced.json").write_text(json.dumps(record))
    with pytest.raises(ValueError) as error:
        family_tuning.tuned_rule(TASK, "paced-rule")
    text = str(error.value)
    assert "\n" not in text and f"family_{TASK}-paced.json" in text and "paced-rule" in text
    (tmp_path / f"family_{TASK}-paced.json").write_text("{not json")
    with pytest.raises(ValueError, match="not a tuned paced-rule file"):
        family_tuning.tuned_rule(TASK, "paced-rule")


def test_missing_file_says_how_to_tune(tmp_path, monkeypatch):
    monkeypatch.setattr(family_tuning, "HERE", tmp_path)
    with pytest.raises(FileNotFoundError, match="--rule paced-rule"):
        family_tuning.tuned_rule(TASK, "paced-rule")


def test_unknown_parameter_is_refused():
    with pytest.raises(ValueError, match="unknown paced rule parameters"):
        PacedRule(PacedFacts.of_scenario(get_scenario(TASK)), {"speed": 1.0})


@pytest.mark.parametrize("arguments, message", [
    (["--rule", "fancy-rule"], "crop-sim tune-rule: --rule: unknown rule 'fancy-rule'; known: budget-rule, paced-rule"),
    (["--rule", "paced-rule", "--seasons", "5..1"], "crop-sim tune-rule: --seasons: '5..1' names no season"),
    (["--rule", "paced-rule", "--candidates", "0"], "crop-sim tune-rule: --candidates must be in 1..10000"),
    (["--rule", "paced-rule", "--seed", "-1"], "crop-sim tune-rule: --seed"),
    (["--rule", "paced-rule", "--term-draws", "0"], "crop-sim tune-rule: --term-draws: 0 is not in 1..20"),
    (["--rule", "paced-rule", "--space", "wide"], "crop-sim tune-rule: --space: unknown search space 'wide' of "
                                                  "paced-rule; known: full, canopy"),
])
def test_tuner_refuses_bad_input_in_one_line(arguments, message, capsys):
    from crop_agent_ros.cli import main
    assert main(["tune-rule", "--task", TASK, *arguments]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(message), err


def test_tuner_writes_a_loadable_paced_file(tmp_path, monkeypatch, scenario):
    """A tiny tuning run (2 seasons, 3 candidates, 1 round) writes family_<task>-paced.json that loads."""
    monkeypatch.setattr(family_tuning, "HERE", tmp_path)
    result = family_tuning.tune_rule(scenario, np.arange(2), candidates=3, rounds=1, rule="paced-rule",
                                     log=lambda message: None)
    path = family_tuning.write_tuned(TASK, result, "paced-rule")
    assert path == tmp_path / f"family_{TASK}-paced.json"
    rule = family_tuning.tuned_rule(TASK, "paced-rule")
    assert isinstance(rule, PacedRule) and set(rule.parameters) == set(PacedParameters.names())
    assert not (tmp_path / f"family_{TASK}.json").exists()  # the budget rule's file is another file


def test_registry_builds_it_by_name():
    from crop_agent_ros.policies.registry import NODE_POLICIES, PolicyArguments, build_policy
    assert "paced-rule" in NODE_POLICIES
    assert isinstance(build_policy("paced-rule", PolicyArguments(task=TASK)), PacedRule)
    with pytest.raises(ValueError, match="paced-rule needs a family task"):
        build_policy("paced-rule")


def test_late_reserve_waters_the_late_canopy_and_paces_for_it(scenario):
    """``late_factor``: after the window the rule still aims at a level (the late canopy), and the water it keeps
    for it is counted in the demand ahead, so the window's share of a tight quota falls; at 0 nothing is kept."""
    from crop_agent_ros.policies.paced_rule import _cover_integral
    facts = PacedFacts.of_scenario(scenario)
    # the antiderivative of SIMPLE's senescence cover: its derivative is the cover
    x, c = np.array([1500.0, 1900.0, 2200.0]), 1900.0
    slope = (_cover_integral(x + 0.5, c) - _cover_integral(x - 0.5, c)) / 1.0
    assert np.allclose(slope, 1.0 / (1.0 + np.exp(0.01 * (x - c))), atol=1e-6)
    seasons = np.arange(4)
    terms = draw_terms(scenario, seasons, 0)
    terms["quota_mm"] = np.full(len(seasons), 600.0)
    window = {"stop_offset_degc_d": -400.0, "narrow_stop_degc_d": 0.0, "pace": 1.0}
    late_water = {}
    for late in (0.0, 1.0):
        recorder = Recorder(PacedRule(facts, {**window, "late_factor": late}))
        run_episodes(recorder, scenario, seasons, seed=0, terms=terms)
        tt = np.stack([o[:, EXTENDED.index("thermal_time_degc_d")] for o in recorder.observations])
        actions = np.stack(recorder.actions)
        stop = facts.tsum_degc_d - facts.i50b_degc_d - 400.0
        late_water[late] = float(actions[tt > stop + 50.0].sum())
    assert late_water[0.0] == 0.0 < late_water[1.0]


def test_late_reserve_is_counted_in_the_pacing(scenario):
    """With a tight quota, water kept for the late canopy (``late_factor`` > 0) is water the window does not get."""
    facts = PacedFacts.of_scenario(scenario)
    seasons = np.arange(4)
    terms = draw_terms(scenario, seasons, 0)
    terms["quota_mm"] = np.full(len(seasons), 200.0)
    window = {"stop_offset_degc_d": -400.0, "narrow_stop_degc_d": 0.0, "narrow_degc_d": 0.0, "pace": 1.0}
    stop = facts.tsum_degc_d - facts.i50b_degc_d - 400.0
    in_window = {}
    for late in (0.0, 1.0):
        recorder = Recorder(PacedRule(facts, {**window, "late_factor": late, "senescence_weight": 0.0}))
        run_episodes(recorder, scenario, seasons, seed=0, terms=terms)
        tt = np.stack([o[:, EXTENDED.index("thermal_time_degc_d")] for o in recorder.observations])
        in_window[late] = float(np.stack(recorder.actions)[tt <= stop].sum())
    assert in_window[1.0] < in_window[0.0]


def test_tuner_meets_each_season_with_several_term_draws(scenario):
    """--term-draws K: the same training seasons, each with K drawn terms; the file records the seasons once."""
    result = family_tuning.tune_rule(scenario, np.arange(2), candidates=2, rounds=0, rule="paced-rule",
                                     log=lambda message: None, term_draws=3)
    assert result["seasons"] == [0, 1] and result["term_draws"] == 3
    assert "term_draws" not in family_tuning.tune_rule(scenario, np.arange(2), candidates=2, rounds=0,
                                                       rule="paced-rule", log=lambda message: None)


def _season(et0_mm: list[float], dtt_degc_d: list[float], fields: int = 1) -> list[np.ndarray]:
    """Synthetic observations (one (fields, 29) array a day): a season whose day d has ET0 ``et0_mm[d]`` and
    thermal time ``dtt_degc_d[d]``, no rain, a read soil full at 100 mm, a large quota."""
    days, tt = [], 0.0
    for day, (et0, dtt) in enumerate(zip(et0_mm, dtt_degc_d)):
        obs = np.zeros((fields, EXTENDED.size))
        for name, value in {"days_since_sowing": day, "thermal_time_degc_d": tt, "et0_mm": et0, "tmax_degc": 20.0,
                            "paw_mm": 100.0, "paw_observed": 1.0, "quota_remaining_mm": 400.0,
                            "capacity_mm_per_day": 8.0}.items():
            obs[:, EXTENDED.index(name)] = value
        days.append(obs)
        tt += dtt
    return days


def _rate_after(rule: PacedRule, days: list[np.ndarray]) -> np.ndarray:
    rule.reset()
    for obs in days:
        rule.act(obs)
    return rule.net_et_rate(rule._memory)


def test_rate_follows_a_rising_season_and_keeps_the_season_s_when_it_falls(scenario):
    """The rate is the larger of the season's and the recent one (``memory_degc_d``). 30 cool days (2 mm ET0 per
    10 degC d) then 30 hot ones (8 mm per 20 degC d): with a short memory, the hot days' 0.4 mm per degC d; with
    a memory longer than the season, the season's average so far, (60 + 240 - 8) / (300 + 600 - 20) (the last
    day is counted tomorrow). Hot days then cool ones: the season's average, however short the memory."""
    facts = PacedFacts.of_scenario(scenario)
    rising = _season([2.0] * 30 + [8.0] * 30, [10.0] * 30 + [20.0] * 30)
    season_average = (60.0 + 240.0 - 8.0) / (300.0 + 600.0 - 20.0)
    recent = _rate_after(PacedRule(facts, {"memory_degc_d": 60.0, "prior_weight_degc_d": 0.0}), rising)
    whole = _rate_after(PacedRule(facts, {"memory_degc_d": 1e9, "prior_weight_degc_d": 0.0}), rising)
    assert recent[0] == pytest.approx(0.4, rel=0.02)
    assert whole[0] == pytest.approx(season_average, rel=1e-6)
    falling = _season([8.0] * 30 + [2.0] * 31, [20.0] * 30 + [10.0] * 31)
    short = _rate_after(PacedRule(facts, {"memory_degc_d": 60.0, "prior_weight_degc_d": 0.0}), falling)
    assert short[0] == pytest.approx((240.0 + 60.0) / (600.0 + 300.0), rel=1e-6)


def test_rate_prior_counts_as_thermal_time_of_evidence(scenario):
    """``prior_weight_degc_d`` W: the rate is (net ET seen + prior x W) / (thermal time seen + W): a large W keeps
    the prior, and 290 degC d seen at 0.2 mm per degC d against W = 290 of a 0.6 prior give 0.4."""
    facts = PacedFacts.of_scenario(scenario)
    days = _season([2.0] * 30, [10.0] * 30)
    prior = {"memory_degc_d": 1e9, "rate_prior_mm_per_degc_d": 0.6}
    assert _rate_after(PacedRule(facts, {**prior, "prior_weight_degc_d": 1e9}), days)[0] == pytest.approx(0.6)
    assert _rate_after(PacedRule(facts, {**prior, "prior_weight_degc_d": 290.0}), days)[0] == pytest.approx(0.4)


def test_a_higher_recent_rate_paces_a_tight_quota_harder(scenario):
    """The rate is the demand ahead: the same season state after hot recent days (short memory) sees more demand
    than after the whole season's average (long memory), so under a tight quota it aims lower and irrigates less."""
    facts = PacedFacts.of_scenario(scenario)
    days = _season([2.0] * 40 + [8.0] * 20, [10.0] * 40 + [20.0] * 20)
    for obs in days:
        obs[:, PAW] = 30.0
        obs[:, QUOTA] = 150.0
    window = {"start_offset_degc_d": -500.0, "narrow_degc_d": 0.0, "narrow_stop_degc_d": 0.0, "pace": 1.0,
              "prior_weight_degc_d": 0.0, "margin_mm": 0.0}
    amounts = {}
    for memory in (60.0, 1e9):
        rule = PacedRule(facts, {**window, "memory_degc_d": memory})
        amounts[memory] = [float(rule.act(obs)[0]) for obs in days][-1]
    assert amounts[60.0] < amounts[1e9]


def test_bank_stores_water_only_where_recent_et0_nears_the_pump_s_capacity(scenario):
    """``bank_days`` x max(0, recent ET0 - ``bank_threshold`` x capacity) is added to the window's level: with
    6 mm of ET0 a day on an 8 mm/d pivot, a threshold of half the capacity banks (more water today), one of the
    whole capacity does not (the same water as without a bank)."""
    facts = PacedFacts.of_scenario(scenario)
    days = _season([6.0] * 60, [15.0] * 60)
    for obs in days:
        obs[:, PAW] = 60.0
    window = {"start_offset_degc_d": -500.0, "narrow_degc_d": 0.0, "prior_weight_degc_d": 0.0, "margin_mm": 0.0}

    def today(bank: dict) -> float:
        rule = PacedRule(facts, {**window, **bank})
        return [float(rule.act(obs)[0]) for obs in days][-1]

    none = today({"bank_days": 0.0})
    assert today({"bank_days": 1.0, "bank_threshold": 1.0}) == none
    assert today({"bank_days": 1.0, "bank_threshold": 0.5}) > none


def test_a_file_tuned_before_a_later_parameter_loads_as_that_rule(recorded, scenario, tmp_path, monkeypatch):
    """A file without ``rise_weight`` (tuned before it existed) loads with its default, 0, the rule it was
    tuned as: the same actions as with the parameter written out; an unknown parameter is still refused."""
    record = json.loads(family_tuning.family_file(TASK, "paced-rule").read_text())
    monkeypatch.setattr(family_tuning, "HERE", tmp_path)
    path = tmp_path / f"family_{TASK}-paced.json"
    rules = {}
    for share in (None, 0.0):
        parameters = {k: v for k, v in record["parameters"].items() if k != "rise_weight"}
        path.write_text(json.dumps({**record, "parameters": parameters if share is None
                                    else {**parameters, "rise_weight": share}}))
        rules[share] = family_tuning.tuned_rule(TASK, "paced-rule")
    assert float(rules[None].parameters["rise_weight"]) == 0.0
    seasons = np.arange(3)
    terms = draw_terms(scenario, seasons, 0)
    returns = [run_episodes(rule, scenario, seasons, seed=1, terms=terms).episode_return for rule in rules.values()]
    assert np.array_equal(returns[0], returns[1])


def test_a_search_space_holds_its_fixed_parameters_and_is_recorded(scenario, monkeypatch):
    """``space``: a named :class:`~family_tuning.SearchSpace`; its fixed parameters are held (every candidate and
    the result have them), its box bounds the rest, and the result names it (the full space is not named)."""
    space = family_tuning.SearchSpace("test", box={"prior_weight_degc_d": (0.0, 10.0)},
                                      fixed={"rate_prior_mm_per_degc_d": 0.0})
    monkeypatch.setitem(family_tuning.PACED_SPACES, "test", space)
    result = family_tuning.tune_rule(scenario, np.arange(2), candidates=4, rounds=1, rule="paced-rule",
                                     log=lambda message: None, space="test")
    assert result["search_space"] == "test" and result["parameters"]["rate_prior_mm_per_degc_d"] == 0.0
    assert 0.0 <= result["parameters"]["prior_weight_degc_d"] <= 10.0
    assert set(result["parameters"]) == set(PacedParameters.names())
    assert "search_space" not in family_tuning.tune_rule(scenario, np.arange(2), candidates=2, rounds=0,
                                                         rule="paced-rule", log=lambda message: None)


def test_rise_weight_spends_less_before_the_canopy_closes_and_the_same_after(scenario):
    """``rise_weight`` 1: the window's level follows SIMPLE's rising cover 1 / (1 + exp(-0.01 (TT - I50A))), so
    on a dry soil early in the window (TT 100, cover 0.02) the rule irrigates less than at 0; past full canopy
    (TT 1400, cover 0.9999) the same; with the default 0 the rule is the one tuned before it existed."""
    facts = PacedFacts.of_scenario(scenario)
    days = _season([5.0] * 100, [14.0] * 100)
    for obs in days:
        obs[:, PAW] = 20.0
    window = {"start_offset_degc_d": -500.0, "narrow_degc_d": 0.0, "stop_offset_degc_d": 400.0,
              "prior_weight_degc_d": 0.0, "margin_mm": 10.0}
    early, late = 7, 99  # TT 98 and 1386
    amounts = {}
    for rise in (0.0, 1.0):
        rule = PacedRule(facts, {**window, "rise_weight": rise})
        amounts[rise] = [float(rule.act(obs)[0]) for obs in days]
    assert amounts[1.0][early] < 0.5 * amounts[0.0][early]
    assert amounts[1.0][late] == pytest.approx(amounts[0.0][late], rel=1e-3) and amounts[0.0][late] > 0
