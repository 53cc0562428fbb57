"""experiments/planners*.py, the task family's causal planners (planners_mpc's mean of plans, planners_hindsight's
daily hindsight value, planners_expected's expected-value programme): a controller never reads the weather after
the day it acts on, nor a noisy value, its schedules are feasible, continuations are aligned as asked, and the
command refuses bad input with one line. Small budgets (2 continuations, coarse grids and search)."""

import json
from dataclasses import replace

import numpy as np
import pytest

from crop_agent_ros.learning.evaluate_task import evaluation_sets
from crop_agent_ros.policies import family_dp
from crop_agent_ros.policies import family_oracle as fo
from crop_agent_ros.policies.rollout import contexts_with_terms, run_episodes, season_contexts
from crop_sim_ros.task import get_scenario
from experiments import planners, planners_expected as fe, planners_hindsight as fh, planners_mpc as fm

CHEAP = fm.MpcSettings(scenarios=2, decision_every_days=14, replan_first_step_mm=2.0, finest_step_mm=1.0)
CHEAP_HINDSIGHT = fh.HindsightSettings(scenarios=2, decision_every_days=14, water_step_mm=4.0,
                                       offset_step_degc_d=80.0, amounts=9)
CHEAP_EXPECTED = fe.ExpectedSettings(scenarios=2, decision_every_days=14, water_step_mm=4.0,
                                     offset_step_degc_d=80.0, amounts=9, programme_amounts=5)
TERMS = {"yield_value_per_t": np.array([1100.0]), "water_cost_per_mm": np.array([1.5]),
         "quota_mm": np.array([250.0])}


@pytest.fixture(scope="module")
def quota_task():
    scenario = get_scenario("benton-quota")
    return scenario, season_contexts(scenario), fm.continuation_pool(get_scenario("benton-generated"), 2)


def test_the_continuation_is_aligned_by_the_day_of_the_year_or_by_the_days_after_sowing(quota_task):
    _, contexts, pool = quota_task
    truth = replace(contexts[0], extra={**contexts[0].extra, "sowing_date": "2000-04-10"})  # day 101 of 2000
    guess = replace(pool["benton"][0], extra={**pool["benton"][0].extra, "sowing_date": "2001-04-05"})         # day 95 of 2001
    out = fm.spliced(truth, guess, known_days=50)
    np.testing.assert_array_equal(out.rain_mm[:50], truth.rain_mm[:50])
    np.testing.assert_array_equal(out.et0_mm[50:60], guess.et0_mm[56:66])  # 6 days of the year later
    np.testing.assert_array_equal(out.tmax_degc[-1], guess.tmax_degc[-1])  # past its end: its last day
    assert len(out.rain_mm) == len(truth.rain_mm)
    # or by the days after sowing (a climate sown on another date): day d of the season is the guess's day d
    by_sowing = fm.spliced(truth, guess, known_days=50, align="sowing")
    np.testing.assert_array_equal(by_sowing.rain_mm[:50], truth.rain_mm[:50])
    np.testing.assert_array_equal(by_sowing.et0_mm[50:60], guess.et0_mm[50:60])
    with pytest.raises(ValueError, match="align must be one of day-of-year, sowing"):
        fm.spliced(truth, guess, known_days=50, align="month")
    # a planner reads its continuations as it is told, and says so where it is not the default
    constants = fo.TaskConstants.of_scenario(get_scenario("benton-quota"))
    assert "align" not in planners.planner(constants, pool, CHEAP).describe()
    for settings in (CHEAP, CHEAP_HINDSIGHT, CHEAP_EXPECTED):
        assert planners.planner(constants, pool, settings, align="sowing").describe()["align"] == "sowing"
    with pytest.raises(ValueError, match="align must be one of"):
        planners.planner(constants, pool, CHEAP_EXPECTED, align="month")


def _daily_irrigation(scenario, contexts, pool, seed, settings, seasons=(0,)):
    policy = planners.planner(fo.TaskConstants.of_scenario(scenario), pool, settings)
    episodes = run_episodes(policy, scenario, np.array(seasons), seed=seed, contexts=contexts, terms=TERMS,
                            record=True)
    return episodes, episodes.daily["irrigation_mm"][:int(episodes.days[0]), 0]


def test_a_planner_acts_without_the_future_weather_and_without_noisy_values(quota_task):
    scenario, contexts, pool = quota_task
    settings = CHEAP_EXPECTED  # the default planner (the others, 7-15 s each, share its bookkeeping)
    episodes, applied = _daily_irrigation(scenario, contexts, pool, seed=0, settings=settings)
    # the same season with other weather from day 29 on in what the policy is given: the days before are the
    # same, the later ones are not (the policy does read the given weather, up to the day it acts on)
    other = contexts[3]
    changed = replace(contexts[0], **{name: np.concatenate([getattr(contexts[0], name)[:29],
                                                           getattr(other, name)[29:len(contexts[0].rain_mm)]])
                                      for name in fm.WEATHER_SERIES})
    _, applied_changed = _daily_irrigation(scenario, [changed] + contexts[1:], pool, seed=0, settings=settings)
    np.testing.assert_array_equal(applied_changed[:29], applied[:29])
    assert not np.array_equal(applied_changed[29:], applied[29:len(applied_changed)])
    # another noise seed (observation and forecast noise): the same schedule
    _, applied_noise = _daily_irrigation(scenario, contexts, pool, seed=3, settings=settings)
    np.testing.assert_array_equal(applied_noise, applied)
    # feasible, as the oracle would see it: within the pivot and the quota, and no better than hindsight
    assert applied.max() <= 8.0 and applied.sum() <= 250.0 + 1e-9 and applied.sum() > 100.0
    problem = fo.field_problems(contexts_with_terms([contexts[0]], TERMS), fo.TaskConstants.of_scenario(scenario))
    oracle = fo.plan_fields(problem)[0]
    assert episodes.episode_return[0] <= oracle.return_value + 1e-6


def test_the_command_refuses_bad_input_with_one_line(tmp_path, capsys):
    assert planners.main(["--table", str(tmp_path / "missing.json"), "--set", "heldout-real"]) == 2
    assert "missing.json" in capsys.readouterr().err
    table = tmp_path / "table.json"
    table.write_text(json.dumps({"task": "benton-quota", "sets": [{"name": "heldout-real"}],
                                 "arguments": {"far_seasons": 5, "far_seed": 900_001}}))
    assert planners.main(["--table", str(table), "--set", "far-nowhere"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "'far-nowhere' is not in the table" in err
    assert planners.main(["--table", str(table), "--set", "heldout-real", "--scenarios", "0"]) == 2
    assert "scenarios" in capsys.readouterr().err
    assert planners.main(["--table", str(table), "--set", "heldout-real", "--continuations", "atlantis"]) == 2
    assert ("no generated-weather scenario 'atlantis-generated' (the fitted generators: benton, gainesville, "
            "maricopa)") in capsys.readouterr().err
    task = get_scenario("climates3-quota")
    sets = {s.name: s for s in evaluation_sets(task, far_seasons=2)}
    assert planners.continuation_source(task, sets["maricopa-generated"])[0] == "maricopa"
    assert planners.continuation_source(task, sets["maricopa-generated"], "gainesville")[0] == "gainesville"
    # a part named apart from its generator: Benton sown March 1, not benton-generated's April
    name, early = planners.continuation_source(task, sets["maricopa-generated"], "benton-early")
    assert (name, early.name, str(early.sowing_date)) == ("benton-early", "benton-early-generated", "2000-03-01")
    assert str(planners.continuation_source(task, sets["maricopa-generated"], "benton")[1].sowing_date) == "2000-04-01"
    # a delta-changed climate that no part of the task holds (a climate's weather a planner may be told)
    name, sunny = planners.continuation_source(task, sets["maricopa-generated"], "benton-hot-arid-sunny")
    assert (name, sunny.weather.generated_climate) == ("benton-hot-arid-sunny", "benton+6C+8DPDx1.25Sx0.3R")
    with pytest.raises(ValueError, match="no generated-weather scenario 'atlantis-generated' .* the task's climates: "
                                         r"benton-early\)"):
        planners.continuation_source(task, sets["maricopa-generated"], "atlantis")
    # each set's own: its site's pool sown on its date (the held-out climate sown late: that date's pool)
    for set_name, expected in (("heldout-real", ("benton", "benton-generated", "2000-04-01")),
                               ("maricopa-real", ("maricopa", "maricopa-generated", "2001-01-15")),
                               ("maricopa-late-real", ("maricopa", "maricopa-late-generated", "2001-02-28")),
                               ("maricopa-march15-generated", ("maricopa", "maricopa-march15-generated", "2001-03-15")),
                               ("far-benton-early", ("benton-early", "benton-early-generated", "2000-03-01")),
                               ("far-gainesville", ("gainesville", "gainesville-generated", "2001-02-01"))):
        name, pool = planners.continuation_source(task, sets[set_name])
        assert (name, pool.name, str(pool.sowing_date)) == expected, set_name
    with pytest.raises(ValueError, match="no weather generator known for set 'x'"):
        planners.continuation_source(task, replace(sets["far-benton"], name="x", continuations=None))
    (tmp_path / "list.json").write_text("[1, 2]")
    assert planners.main(["--table", str(tmp_path / "list.json"), "--set", "heldout-real"]) == 2
    assert "is not a table.json" in capsys.readouterr().err


def _planner_run(set_name: str, regrets: dict) -> dict:
    return {"task": "benton-quota", "set": set_name, "rows": [
        {"season": season, "rule_regret_usd_ha": 400.0, "mpc_regret_usd_ha": regret}
        for season, regret in regrets.items()]}


def test_two_planner_runs_are_compared_on_the_seasons_both_ran(tmp_path, capsys):
    base = _planner_run("far-benton", {1: 100.0, 2: 200.0, 3: 300.0})
    other = _planner_run("far-benton", {2: 150.0, 3: 330.0, 4: 50.0})  # seasons 2 and 3 in common: -50 and +30
    result = planners.paired_runs(base, other)
    assert result["seasons"] == 2 and result["other_lower_on"] == 1
    assert result["base_regret_usd_ha"] == 250.0 and result["other_regret_usd_ha"] == 240.0
    assert result["difference_usd_ha"] == -10.0
    low, high = result["difference_ci"]  # bootstrap means of two differences lie between them
    assert -50.0 <= low < -10.0 < high <= 30.0
    files = [tmp_path / "base.json", tmp_path / "other.json"]
    for path, run in zip(files, (base, other)):
        path.write_text(json.dumps(run))
    assert planners.main(["--paired", *map(str, files)]) == 0
    assert "difference -10 [" in capsys.readouterr().out
    files[1].write_text(json.dumps(_planner_run("heldout-real", {2: 1.0})))
    assert planners.main(["--paired", *map(str, files)]) == 2
    assert "pair runs of one task and set" in capsys.readouterr().err
    files[1].write_text(json.dumps(_planner_run("far-benton", {9: 1.0})))
    assert planners.main(["--paired", *map(str, files)]) == 2
    assert "share no season" in capsys.readouterr().err
    files[1].write_text("[1]")
    assert planners.main(["--paired", *map(str, files)]) == 2
    assert "must both be --out files" in capsys.readouterr().err
    assert planners.main(["--set", "far-benton"]) == 2
    assert "--table and --set are required" in capsys.readouterr().err


def test_the_expected_value_programme_of_one_weather_is_the_programme_of_that_weather(quota_task):
    # two discretisations of one dynamic programme: the expected-value programme chooses among amounts (0 ..
    # the capacity), SeasonProgramme among tomorrow's grid levels of soil water; on one weather they agree to
    # the choice grid's loss (measured: 1.47 USD/ha with 9 amounts, 0.37 with 129, of 18,272), and a weather
    # given twice is that weather (the mean of equal terms)
    scenario, contexts, _ = quota_task
    problem = fo.field_problems(contexts_with_terms([contexts[0]], TERMS), fo.TaskConstants.of_scenario(scenario))[0]
    prices = [1.5, 1.5 + 0.02 * 1100.0]
    exact = family_dp.SeasonProgramme(problem, 4.0, 80.0).value_tables(prices, rounding=False, first_day=30)[1]
    fine = fe.ExpectedProgramme([family_dp.SeasonProgramme(problem, 4.0, 80.0)], 129).value_tables(prices, 30)
    coarse = fe.ExpectedProgramme([family_dp.SeasonProgramme(problem, 4.0, 80.0)], 9).value_tables(prices, 30)
    twice = fe.ExpectedProgramme([family_dp.SeasonProgramme(problem, 4.0, 80.0) for _ in range(2)], 9).value_tables(
        prices, 30)
    for d in (30, 60, 90):
        np.testing.assert_allclose(fine[d], exact[d], atol=1.0)
        assert np.abs(coarse[d] - exact[d]).max() > np.abs(fine[d] - exact[d]).max()  # fewer choices lose more
        np.testing.assert_allclose(twice[d], coarse[d], rtol=1e-12)
    assert fine[29] is None and len(fine) == len(exact)


def test_the_expected_value_programme_averages_the_weather_of_each_day(quota_task):
    # two weathers: a rainless copy and a wet copy of one season. The value of a dry state is the mean of
    # what it is worth when tomorrow may bring either, so it lies between each weather's own value
    scenario, contexts, _ = quota_task
    problem = fo.field_problems(contexts_with_terms([contexts[0]], TERMS), fo.TaskConstants.of_scenario(scenario))[0]
    context = problem.context
    dry = replace(problem, context=replace(context, rain_mm=np.zeros_like(context.rain_mm)))
    wet = replace(problem, context=replace(context, rain_mm=np.full_like(context.rain_mm, 6.0)))
    tables = [fe.ExpectedProgramme([family_dp.SeasonProgramme(p, 4.0, 80.0) for p in problems], 9).value_tables(
        [1.5], 40)[40][0, :, 0] for problems in ([dry], [wet], [dry, wet])]
    low, high, mixed = tables
    assert np.all(high >= low - 1e-6) and (high - low)[:10].min() > 100.0  # rain is worth much to a dry soil
    assert np.all(mixed >= low - 1e-6) and np.all(mixed <= high + 1e-6)
    assert np.all((mixed - low)[:10] > 0.2 * (high - low)[:10])


def test_hindsight_settings_and_planner_names_are_checked(quota_task):
    scenario, contexts, pool = quota_task
    policy = planners.planner(fo.TaskConstants.of_scenario(scenario), pool, CHEAP_HINDSIGHT)
    policy.begin_season(contexts_with_terms(contexts[:1], TERMS))
    skipped = np.zeros((1, fm.EXTENDED.size))
    skipped[0, fm.DAYS_SINCE_SOWING] = 3.0  # a first observation on day 3: the crop's state is unknown
    with pytest.raises(ValueError, match="field 0 is on day 3 after day -1; it follows a season day by day"):
        policy.act(skipped)
    with pytest.raises(ValueError, match="scenarios and decision_every_days must be >= 1 and amounts >= 2"):
        fh.HindsightSettings(amounts=1)
    with pytest.raises(ValueError, match="grid steps must be > 0"):
        fh.HindsightSettings(water_step_mm=0.0)
    with pytest.raises(ValueError, match="multipliers_per_value must be >= 0"):
        fh.HindsightSettings(multipliers_per_value=(-0.01,))
    with pytest.raises(ValueError, match="--method: unknown planner 'best'"):
        planners.planner_settings("best", 2, 7)
    assert type(planners.planner_settings("hindsight-value", 3, 5)) is fh.HindsightSettings
    assert planners.planner_settings("expected-value", 3, 5) == fe.ExpectedSettings(scenarios=3, decision_every_days=5)
    assert isinstance(planners.planner(fo.TaskConstants.of_scenario(scenario), pool, CHEAP_EXPECTED), fe.FamilyExpectedPolicy)
    with pytest.raises(ValueError, match="programme_amounts must be >= 2"):
        fe.ExpectedSettings(programme_amounts=1)
    assert planners.planner_settings("mean-plan", 3, 5) == fm.MpcSettings(scenarios=3, decision_every_days=5)


def test_the_planner_summary_command_refuses_bad_input_and_foreign_problems(tmp_path, capsys):
    from experiments import planners_summary
    from test_leaderboard import planned_table, planner_run
    assert planners_summary.main(["--table", str(tmp_path / "missing.json"), "--runs", "x.json", "--out",
                                  str(tmp_path / "s.json")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("planners_summary: ") and err.count("\n") == 1 and "missing.json" in err
    table = planned_table()
    table["arguments"] = {"far_seasons": 2, "far_seed": 900_001}
    (tmp_path / "table.json").write_text(json.dumps(table))
    for name, task, set_name in (("far", "benton-quota", "far-benton"), ("capacity", "benton-capacity", None),
                                 ("sensing", "benton-sensing", None)):
        run = planner_run(task=task)
        run["set"] = set_name or run["set"]
        (tmp_path / f"{name}.json").write_text(json.dumps(run))

    def summarise(run: str) -> int:
        return planners_summary.main(["--table", str(tmp_path / "table.json"), "--runs", str(tmp_path / run),
                                      "--out", str(tmp_path / "summary.json")])
    assert summarise("far.json") == 2
    assert "planners_summary: --runs: set far-benton is not in the table" in capsys.readouterr().err
    assert summarise("capacity.json") == 2  # 4.5 mm a day: another planning problem
    assert "a run of benton-capacity, whose constants are not benton-quota's" in capsys.readouterr().err
    assert not (tmp_path / "summary.json").exists()
    # benton-sensing differs only in what the agents observe: its run is this set's, and the summary says so
    assert summarise("sensing.json") == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["sets"][0]["planned_on"] == "benton-sensing" and summary["task"] == "benton-quota"
    assert "heldout-real: planner 130" in capsys.readouterr().out
