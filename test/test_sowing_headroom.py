"""The sowing-date headroom probe: the oracle and the tuned rule on a climate sown on other dates."""

from datetime import date

import pytest

from crop_agent_ros.learning import sowing_headroom as sh


def test_headroom_is_the_rule_regret_share_of_the_oracle_and_the_sowing_date_moves_the_season():
    january, march = (sh.sowing_headroom("benton-quota", "maricopa-generated", day, seasons=2, noise_seeds=1)
                      for day in (date(2001, 1, 15), date(2001, 3, 15)))
    for h in (january, march):
        assert h.oracle_usd_ha > h.rule_usd_ha > 0  # the oracle knows the season; the rule does not
        assert h.headroom_pct == pytest.approx(100 * (h.oracle_usd_ha - h.rule_usd_ha) / h.oracle_usd_ha)
    # the same weather seed sown six weeks later grows into the desert's spring heat: a smaller crop
    assert march.oracle_usd_ha < january.oracle_usd_ha
    again = sh.sowing_headroom("benton-quota", "maricopa-generated", date(2001, 1, 15), seasons=2, noise_seeds=1)
    assert again == january  # the same seeds, the same figures


def test_main_prints_one_row_per_date_and_refuses_bad_input(capsys):
    assert sh.main(["--task", "benton-quota", "--sowing-dates", "2001-02-28", "--seasons", "1",
                    "--noise-seeds", "1"]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| February 28 |")]
    assert len(rows) == 1 and rows[0].count("|") == 6 and "%" in rows[0]
    for argv, message in ((["--sowing-dates", "2001-02-30"], "--sowing-dates: day is out of range"),
                          (["--sowing-dates", "2001-02-28", "--seasons", "0"], "--seasons: 0 is not in 1..1000"),
                          (["--sowing-dates", "2001-02-28", "--scenario", "maricopa-real"],
                           "not on generated weather"),
                          (["--sowing-dates", "2001-02-28", "--scenario", "atlantis"], "unknown scenario 'atlantis'")):
        assert sh.main(["--task", "benton-quota", *argv]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, err
