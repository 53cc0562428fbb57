"""``crop-sim simulate`` on the embedded default: files written, numbers sensible, bad input refused."""

import json

import pytest

from crop_agent_ros.cli import main


def test_simulate_embedded_default(tmp_path, capsys):
    assert main(["simulate", "--irrigation-mm", "0,10", "--out", str(tmp_path)]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    dry, wet = summary["fields"]
    assert wet["yield_t_ha"] > 1.5 * dry["yield_t_ha"] > 0
    assert 5 < wet["yield_t_ha"] < 30
    assert wet["irrigation_mm"] == pytest.approx(10 * wet["days"])
    assert (tmp_path / "season.png").stat().st_size > 10_000
    lines = (tmp_path / "season.csv").read_text().splitlines()
    assert lines[0].startswith("irrigation_mm_per_day,date,days_after_sowing")
    assert "benton-generated" in capsys.readouterr().out


@pytest.mark.parametrize("rates", ["nan", "-1", "abc", "200"])
def test_simulate_refuses_bad_rates(tmp_path, capsys, rates):
    assert main(["simulate", "--irrigation-mm", rates, "--out", str(tmp_path / "out")]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("crop-sim simulate: --irrigation-mm: ") and repr(rates) in line
    assert not (tmp_path / "out").exists()
