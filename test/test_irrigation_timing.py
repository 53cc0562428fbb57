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


def test_main_prints_a_row_per_policy_and_names_bad_input(capsys):
    assert it.main(["--task", "benton-quota", "--set", "heldout-real", "--seasons", "1", "--period-days", "50"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[1].startswith("| policy | return | water | yield | days | d0-49 | d50-99 |")
    assert [line.split(" | ")[0] for line in out[3:]] == ["| oracle", "| rule"]
    for argv, message in ((["--set", "moon"], "no set 'moon' in benton-quota's protocol (sets: heldout-real"),
                          (["--set", "far-benton", "--agent", "x"], "--agent 'x': give NAME=RUN_DIRECTORY"),
                          (["--set", "far-benton", "--agent", "x=/nowhere"], "x: /nowhere/model.zip does not exist"),
                          (["--set", "far-benton", "--agent", f"rule={AGENT}"], "--agent rule: the name is taken"),
                          (["--set", "far-benton", "--seasons", "0"], "--seasons: 0 is not in 1..1000")):
        assert it.main(["--task", "benton-quota", *argv]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, err
