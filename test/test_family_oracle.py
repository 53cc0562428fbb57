"""The task family's hindsight oracle (crop_agent_ros.policies.family_oracle) and its dynamic programme
(family_dp): feasible plans the environment pays in full, at least any rule's return, starts that agree,
bounds that hold, and the paper task's oracle reproduced. Small search budgets: the whole file runs in well
under a minute."""

from dataclasses import replace

import numpy as np
import pytest

from crop_agent_ros.policies import family_dp, family_oracle as fo
from crop_agent_ros.policies.family import FarmFacts, WaterBudgetRule
from crop_agent_ros.policies.rollout import contexts_with_terms, run_episodes, season_contexts
from crop_sim_ros import model
from crop_sim_ros.task import get_scenario

# A cheap search: steps 4, 2, 1 mm, few rounds per step (the tests check properties, not the last 0.1 %).
CHEAP = {"first_step_mm": 4.0, "finest_step_mm": 1.0, "max_rounds_per_step": 6}
# One field's terms: tuber price (USD/t), water cost (USD/mm), quota (mm).
ONE_FIELD_TERMS = {"yield_value_per_t": np.array([1100.0]), "water_cost_per_mm": np.array([1.5]),
                   "quota_mm": np.array([250.0])}


@pytest.fixture(scope="module")
def quota_task():
    scenario = get_scenario("benton-quota")
    return scenario, season_contexts(scenario)


def events_scenario():
    """benton-capacity (4.5 mm/d) with a 40 USD cost per day of irrigation: every move kind of the search."""
    scenario = get_scenario("benton-capacity")
    return replace(scenario, name="benton-capacity-events",
                   economics=replace(scenario.economics, event_cost_usd=40.0))


def problems_of(scenario, contexts, seasons, terms):
    return fo.field_problems(contexts_with_terms([contexts[k] for k in seasons], terms),
                             fo.TaskConstants.of_scenario(scenario))


def test_planned_schedules_are_feasible_and_the_environment_pays_their_return(quota_task):
    scenario, contexts = quota_task
    seasons = np.array([0, 1, 2])
    terms = {"yield_value_per_t": np.array([750.0, 1100.0, 1500.0]), "water_cost_per_mm": np.array([3.0, 1.5, 0.5]),
             "quota_mm": np.array([150.0, 300.0, 450.0])}
    policy = fo.FamilyOraclePolicy.for_scenario(scenario, starts=("family",), **CHEAP)
    episodes = run_episodes(policy, scenario, seasons, seed=4, contexts=contexts, terms=terms, record=True)
    for k, result in enumerate(policy.results):
        schedule = result.schedule_mm
        assert np.all(schedule >= 0.0) and np.all(schedule <= 8.0)  # benton-quota's pivot: 8 mm/d
        assert schedule.sum() <= terms["quota_mm"][k]
        assert np.all(schedule[result.maturity_day + 1:] == 0.0)
        days = int(episodes.days[k])
        applied = episodes.daily["irrigation_mm"][:days, k]
        np.testing.assert_array_equal(applied, schedule[:days])  # nothing cut by capacity or quota
    planned = np.array([r.return_value for r in policy.results])
    np.testing.assert_allclose(episodes.episode_return, planned, rtol=1e-6)
    np.testing.assert_allclose(episodes.water_mm, [r.water_mm for r in policy.results], rtol=1e-9)
    assert episodes.matured.all()
    # the tight quota binds (the crop could use far more than 150 mm), the loose one need not
    assert policy.results[0].water_mm == pytest.approx(150.0, abs=1e-3)


def test_event_costs_and_capacity_are_paid_as_planned():
    scenario = events_scenario()
    contexts = season_contexts(scenario)
    seasons = np.array([3, 4])
    terms = {"yield_value_per_t": np.array([900.0, 1300.0]), "water_cost_per_mm": np.array([2.0, 1.0])}
    policy = fo.FamilyOraclePolicy.for_scenario(scenario, starts=("family",), **CHEAP)
    episodes = run_episodes(policy, scenario, seasons, seed=1, contexts=contexts, terms=terms, record=True)
    for k, result in enumerate(policy.results):
        assert np.all(result.schedule_mm <= 4.5) and np.all(result.schedule_mm >= 0.0)
        days = int(episodes.days[k])
        applied = episodes.daily["irrigation_mm"][:days, k]
        assert result.events == int(np.count_nonzero(applied))
        # the return by hand: value x yield - cost x water - 40 x days with water
        by_hand = (terms["yield_value_per_t"][k] * episodes.yield_t_ha[k]
                   - terms["water_cost_per_mm"][k] * applied.sum() - 40.0 * np.count_nonzero(applied))
        assert episodes.episode_return[k] == pytest.approx(by_hand, rel=1e-9)
        assert result.return_value == pytest.approx(episodes.episode_return[k], rel=1e-6)


def test_oracle_returns_at_least_the_water_budget_rule_on_the_same_terms(quota_task):
    scenario, contexts = quota_task
    seasons = np.array([5, 6, 7])
    terms = {"yield_value_per_t": np.array([800.0, 1200.0, 1400.0]), "water_cost_per_mm": np.array([2.5, 1.0, 2.0]),
             "quota_mm": np.array([200.0, 350.0, 420.0])}
    rule = WaterBudgetRule(FarmFacts.of_scenario(scenario))
    ruled = run_episodes(rule, scenario, seasons, seed=2, terms=terms, record=True)
    problems = problems_of(scenario, contexts, seasons, terms)
    results = fo.plan_fields(problems, starts=("family",), **CHEAP)
    assert all(r.return_value >= ep for r, ep in zip(results, ruled.episode_return))
    # From the rule's own (feasible) schedule: the search scores it as the environment paid it, and improves it.
    given = np.zeros((problems[0].days, len(problems)))  # the applied mm; 0 after the episode
    given[:len(ruled.daily["irrigation_mm"])] = np.nan_to_num(ruled.daily["irrigation_mm"])
    from_rule = fo.plan_fields(problems, starts=[list(given.T)], first_step_mm=2.0, finest_step_mm=2.0,
                               max_rounds_per_step=1)
    scored = fo._run(fo._Fields(problems), given, np.arange(len(problems)))[0].returns
    np.testing.assert_allclose(scored, ruled.episode_return, rtol=1e-9)
    assert all(r.return_value > ep for r, ep in zip(from_rule, ruled.episode_return))


def test_searches_from_different_starts_end_close_together(quota_task):
    """The search (to 1/4 mm) from the dynamic programme's plan, the family's best and the uniform spread of
    the quota: three different starts end within 0.2 % of each other (measured: 0.03 %)."""
    scenario, contexts = quota_task
    terms = {"yield_value_per_t": np.array([1000.0]), "water_cost_per_mm": np.array([1.5]),
             "quota_mm": np.array([300.0])}
    problems = problems_of(scenario, contexts, np.array([8]), terms)
    result = fo.plan_fields(problems, starts=("plan", "family", "uniform"), finest_step_mm=0.25)[0]
    ends = np.array(list(result.start_returns.values()))
    assert result.return_value == pytest.approx(ends.max(), rel=1e-12)
    assert (ends.max() - ends.min()) / ends.max() < 0.002, result.start_returns


def test_upper_bounds_hold_and_are_tight_without_a_quota(quota_task):
    scenario, contexts = quota_task
    seasons = np.array([0, 3])
    terms = {"yield_value_per_t": np.array([900.0, 1200.0]), "water_cost_per_mm": np.array([2.0, 1.0]),
             "quota_mm": np.array([220.0, np.inf])}
    problems = problems_of(scenario, contexts, seasons, terms)
    results = fo.plan_fields(problems, starts=("family",), **CHEAP)
    for p, r in zip(problems, results):
        bound = family_dp.upper_bound(p, water_step_mm=1.0).bound
        assert r.return_value <= bound
        assert r.return_value <= r.potential_bound
    # without a quota the bound sits within a few per cent (grid slack, senescence ignored)
    assert (family_dp.upper_bound(problems[1], water_step_mm=1.0).bound - results[1].return_value) \
        < 0.03 * results[1].return_value


def test_the_bound_follows_the_true_model_where_its_grid_is_its_only_slack(quota_task):
    """No irrigation possible (capacity 0) and water stress never advancing senescence (I50maxW = 0): the only
    schedule is none, the bound's only slack is rounding the soil water up. Its value must match SIMPLE's
    yield computed independently by simulate_season, from above, within the rounding's effect."""
    _, contexts = quota_task
    context = contexts[2]
    params = replace(context.params, i50_max_water_degc_d=np.zeros(1))
    context = replace(context, params=params)
    problem = fo.FieldProblem(context, 1000.0, 1.0, np.inf, 0.0)
    run = model.simulate_season(params, context.tmax_degc, context.tmin_degc, context.srad_mj_m2, context.rain_mm,
                                context.et0_mm, 0.0)
    assert run.final_state.mature[0]
    truth = 1000.0 * run.harvested_yield_kg_ha[0] / 1000.0
    bound = family_dp.upper_bound(problem, water_step_mm=0.05).bound
    # rounding up adds at most 0.05 mm of water a day (159 days): a few tenths of a per cent of this stressed crop
    assert truth <= bound < truth * 1.005


def test_family_oracle_matches_the_paper_oracle_on_the_paper_prices():
    """No quota, the action bound as capacity and the paper's price ratio (1 per t/ha, 1.25e-4 per mm): the
    paper task's oracle (crop_agent_ros.policies.oracle) and this one find the same return within 0.1 %."""
    from crop_agent_ros.policies.oracle import find_best_schedule
    context = season_contexts("benton-generated")[0]
    problem = fo.FieldProblem(context, 1.0, 1.25e-4, np.inf, 100.0)
    budget = {"first_step_mm": 8.0, "finest_step_mm": 1.0, "max_rounds_per_step": 6}
    ours = fo.plan_fields([problem], starts=("family",), **budget)[0]
    paper = find_best_schedule(context, **budget)
    assert ours.return_value == pytest.approx(paper.return_value, rel=1e-3)


def test_bad_problems_and_starts_are_refused_with_a_clear_error(quota_task):
    scenario, contexts = quota_task
    constants = fo.TaskConstants.of_scenario(scenario)
    assert constants == fo.TaskConstants(8.0, 0.0)
    with pytest.raises(ValueError, match="carries no episode terms"):
        fo.field_problems([contexts[0]], constants)
    with pytest.raises(ValueError, match="water_cost_per_mm of 'benton-quota\\[0\\]' must be a finite number >= 0"):
        fo.FieldProblem(contexts[0], 1000.0, -1.0, 300.0, 8.0)
    problem = fo.FieldProblem(contexts[0], 1000.0, 1.0, 100.0, 8.0)
    over_quota = np.full(problem.days, 1.0)  # 200 mm > 100 mm
    with pytest.raises(ValueError, match="is not feasible"):
        fo.plan_fields([problem], starts=[[over_quota]])
    with pytest.raises(ValueError, match="has shape \\(3,\\), not one amount per day"):
        fo.plan_fields([problem], starts=[[np.zeros(3)]])
    with pytest.raises(ValueError, match="unknown start 'best'"):
        fo.plan_fields([problem], starts=("best",))


def test_report_command_refuses_bad_input_with_one_line(capsys):
    assert fo.main(["--task", "benton-generated", "--seasons", "0..1"]) == 2
    assert fo.main(["--seasons", "5..2"]) == 2
    assert fo.main(["--seasons", "0..5000"]) == 2
    assert fo.main(["--seasons", "0..100000000000"]) == 2  # refused before anything is allocated
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 4 and all(line.startswith("family_oracle: --") for line in err)
    assert "not a family task" in err[0] and "names no season" in err[1] and "has seasons 0..999" in err[2]
    assert "goes past season 9999" in err[3]


def test_the_backward_pass_reads_shifted_offsets_as_the_general_lookup_does(quota_task):
    """The backward pass's lookup (the next offsets are the grid's shifted by one amount per state) must give
    the bilinear values of the general lookup: for shifts below the offset step (its slicing), beyond it (its
    fallback), and offsets pushed past the grid's end (its last column)."""
    scenario, contexts = quota_task
    problem = problems_of(scenario, contexts, [1], {"yield_value_per_t": np.array([1000.0]),
                                                   "water_cost_per_mm": np.array([1.0]),
                                                   "quota_mm": np.array([300.0])})[0]
    programme = family_dp.SeasonProgramme(problem, water_step_mm=4.0, offset_step_degc_d=40.0)
    rng = np.random.default_rng(3)
    tables = rng.normal(size=(3, len(programme.water), len(programme.offsets)))
    water = rng.uniform(-5.0, programme.water[-1] + 10.0, size=(len(programme.water), 5))
    for shift in (rng.uniform(0.0, 39.9, len(programme.water)), rng.uniform(0.0, 130.0, len(programme.water))):
        general = programme._lookup(tables, water, programme.offsets[None, :] + shift[:, None], False)
        np.testing.assert_allclose(programme._lookup_shifted(tables, water, shift, False), general, rtol=0, atol=1e-12)
    # by hand at one point: W halfway between grid levels 2 and 3, offset a quarter past the last-but-one level
    shift = np.full(len(programme.water), 10.0)
    at = programme._lookup_shifted(tables, np.full((len(programme.water), 1), 10.0), shift, False)[0, 0, 0, -2]
    corners = tables[0, 2:4, -2:]
    assert at == pytest.approx(0.5 * (0.75 * corners[0, 0] + 0.25 * corners[0, 1])
                               + 0.5 * (0.75 * corners[1, 0] + 0.25 * corners[1, 1]))


def test_value_tables_kept_day_terms_change_nothing(quota_task):
    """A planner asks one programme for tables at several sets of prices, keeping each day's price-independent
    terms in a dict: the tables must be those of a fresh computation, for either rounding, in either order."""
    scenario, contexts = quota_task
    problem = problems_of(scenario, contexts, [2], {"yield_value_per_t": np.array([1100.0]),
                                                   "water_cost_per_mm": np.array([1.5]),
                                                   "quota_mm": np.array([250.0])})[0]
    programme = family_dp.SeasonProgramme(problem, water_step_mm=4.0, offset_step_degc_d=80.0)
    kept = {}
    for prices, rounding in (([1.5, 20.0], False), ([1.5, 20.0], True), ([9.0], False), ([9.0, 30.0], True)):
        fresh_value, fresh = programme.value_tables(prices, rounding)
        value, tables = programme.value_tables(prices, rounding, day_terms=kept)
        np.testing.assert_array_equal(value, fresh_value)
        assert all((a is None and b is None) or np.array_equal(a, b) for a, b in zip(tables, fresh))


def test_a_replan_keeps_the_frozen_days_and_named_starts_are_refused(quota_task):
    # a causal planner re-plans in mid-season with the days already applied frozen (experiments/planners_mpc.py)
    scenario, contexts = quota_task
    problem = fo.field_problems(contexts_with_terms([contexts[0]], ONE_FIELD_TERMS), fo.TaskConstants.of_scenario(scenario))[0]
    start = np.zeros(problem.days)
    start[20:40] = 3.0  # 60 mm on days 20-39: a plan the search would change
    frozen = replace(problem, frozen_days=30)
    result = fo.plan_fields([frozen], starts=[[start]], first_step_mm=2.0, finest_step_mm=1.0)[0]
    np.testing.assert_array_equal(result.schedule_mm[:30], start[:30])
    assert not np.array_equal(result.schedule_mm[30:], start[30:])  # the free days were searched
    assert result.schedule_mm.sum() <= 250.0
    with pytest.raises(ValueError, match="frozen days need given start schedules"):
        fo.plan_fields([frozen], starts=("family",))
    with pytest.raises(ValueError, match="frozen_days .* must be in"):
        replace(problem, frozen_days=problem.days + 1)


def test_the_programme_restarted_in_mid_season_continues_its_own_plan(quota_task):
    # the dynamic programme's forward plan from sowing, and the same plan restarted on day 60 from the state it
    # reached with the quota it left: the same days after, and returns to go that add up (an error in the
    # restart's state, quota or first day changes both)
    scenario, contexts = quota_task
    problem = fo.field_problems(contexts_with_terms([contexts[0]], ONE_FIELD_TERMS), fo.TaskConstants.of_scenario(scenario))[0]
    programme = family_dp.SeasonProgramme(problem, 4.0, 80.0)
    prices = problem.water_cost_per_mm + np.array([0.0, 15.0])
    _, tables = programme.value_tables(prices, rounding=False)
    whole, whole_returns = family_dp._forward_plans(programme, tables, prices, amounts=9)
    _, later_tables = programme.value_tables(prices, rounding=False, first_day=61)
    for k in range(2):
        np.testing.assert_allclose(later_tables[61][k], tables[61][k], rtol=1e-12)
        schedule = whole[:, k]
        assert schedule[:60].sum() > 0 and schedule[60:].sum() > 0  # both parts irrigate
        c, params = contexts[0], contexts[0].params
        state, growth = model.initial_state(params), 0.0
        for d in range(60):
            before = state.biomass_kg_ha[0]
            state, _ = model.step(params, state, c.weather_on(d), schedule[d:d + 1])
            growth += programme.value_per_kg * (state.biomass_kg_ha[0] - before)
        price_tables = [None if t is None else t[k:k + 1] for t in later_tables]
        restarted, to_go = family_dp._forward_plans(programme, price_tables, prices[k:k + 1], amounts=9, first_day=60,
                                                    state=state, quota_left_mm=problem.quota_mm - schedule[:60].sum())
        np.testing.assert_array_equal(restarted[:60, 0], 0.0)
        np.testing.assert_allclose(restarted[60:, 0], schedule[60:], atol=1e-9)
        np.testing.assert_allclose(growth - problem.water_cost_per_mm * schedule[:60].sum() + to_go[0],
                                   whole_returns[k], rtol=1e-9)
