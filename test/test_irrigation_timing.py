"""When each policy irrigates, per period after sowing, on an evaluation set."""

from pathlib import Path

import numpy as np
import pytest

from crop_agent_ros.learning import irrigation_timing as it

AGENT = Path(__file__).resolve().parents[1] / "results/family/agents/benton-quota-es-s0"


def test_periods_add_up_to_the_water_and_follow_the_set_and_its_terms():
    rows = it.timings("benton-quota", "maricopa-late-generated", {"es": AGENT}, seasons=2, period_days=25)
    assert [r.policy for r in rows] == ["oracle", "rule", "es"]
    for r in rows:
        # every mm applied falls in one period; seasons end before day 125 here (late-sown, about 108 days)
        assert sum(r.irrigation_mm_by_period) == pytest.approx(r.water_mm, abs=1e-6)
        assert len(r.irrigation_mm_by_period) == len(r.paw_mm_by_period) <= 8 and r.days < 125
        assert np.all(np.array(r.paw_mm_by_period)[np.isfinite(r.paw_mm_by_period)] >= 0)
    oracle, rule, _ = rows
    assert oracle.return_usd_ha > rule.return_usd_ha
    # the same seasons and terms as crop-sim evaluate's set: both spend about the same (binding) quota
    assert oracle.water_mm == pytest.approx(rule.water_mm, abs=10.0)


def test_the_seasons_are_the_first_of_the_protocols_set_with_its_terms():
    # a generated pool's first seasons depend on its size: the protocol's 50-season set, not a 2-season pool
    from crop_sim_ros.task.scenario import get_scenario
    from crop_agent_ros.learning.evaluate_task import evaluation_sets, set_terms
    from crop_agent_ros.policies import family_tuning
    from crop_agent_ros.policies.rollout import run_episodes
    sets = evaluation_sets(get_scenario("benton-quota"), 50)
    position = [s.name for s in sets].index("maricopa-late-generated")
    protocol = sets[position]
    terms = {name: values[:2] for name, values in set_terms(protocol, 4049 + position).items()}
    rule = run_episodes(family_tuning.tuned_rule("benton-quota"), protocol.scenario, protocol.seasons[:2], seed=0,
                        terms=terms)
    timed = it.timings("benton-quota", "maricopa-late-generated", {}, seasons=2, period_days=50)[1]
    assert timed.policy == "rule" and timed.return_usd_ha == rule.episode_return.mean()
    assert timed.water_mm == rule.water_mm.mean()
    small_pool = it.timings("benton-quota", "maricopa-late-generated", {}, seasons=2, period_days=50, far_seasons=2)
    assert small_pool[1].return_usd_ha != timed.return_usd_ha


def test_main_prints_a_row_per_policy_and_names_bad_input(capsys):
    assert it.main(["--task", "benton-quota", "--set", "heldout-real", "--seasons", "1", "--period-days", "50"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[1].startswith("| policy | return | water | yield | days | d0-49 | d50-99 |")
    assert [line.split(" | ")[0] for line in out[3:]] == ["| oracle", "| rule"]
    for argv, message in ((["--set", "moon"], "no set 'moon' in benton-quota's protocol (sets: heldout-real"),
                          (["--set", "far-benton", "--agent", "x"], "--agent 'x': give NAME=RUN_DIRECTORY"),
                          (["--set", "far-benton", "--agent", "x=/nowhere"], "x: /nowhere/model.zip does not exist"),
                          (["--set", "far-benton", "--agent", f"rule={AGENT}"], "--agent rule: the name is taken"),
                          (["--set", "far-benton", "--seasons", "0"], "--seasons: 0 is not in 1..1000"),
                          (["--set", "far-benton", "--far-seasons", "0"], "--far-seasons: 0 is not in 1..10000")):
        assert it.main(["--task", "benton-quota", *argv]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, err
