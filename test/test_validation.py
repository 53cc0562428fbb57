"""The SIMPLE reference validation: reader, batched runner, RRMSE report and ``crop-sim validate``.

Measured RRMSE (%) on the shared input set (n in brackets), yield at harvest (see report.py):
======================= ============ ============ ============
source, treatments      biomass      yield        fSolar
======================= ============ ============ ============
zhao2019, switched on   41.3 (194)   41.5 (24)    29.6 (161)
zhao2019, --all         33.0 (476)   32.7 (50)    30.4 (458)
simple_r, switched on   29.8 (194)   21.1 (24)    38.8 (161)
simple_r, --all         25.2 (476)   17.2 (50)    39.9 (458)
paper Table 3           25.7         25.4         29.5
======================= ============ ============ ============
"""

import csv
import json
import shutil
from datetime import date
from pathlib import Path

import numpy as np
import pytest

from crop_agent_ros.cli import main
from crop_sim_ros.validation import (compare, read_observations, read_treatments, rrmse_percent, run_treatments,
                                     select_treatments)
from crop_sim_ros.validation.cli import CSV_COLUMNS
from crop_sim_ros.validation.inputs import read_irrigation

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
INPUTS = DATA / "simple_r_inputs"
needs_inputs = pytest.mark.usefixtures("shared_data")  # fails, never skips, without the data

# (source, --all) -> measured overall RRMSE % and n: biomass, yield, fSolar.
MEASURED = {
    ("zhao2019", False): {"biomass_kg_ha": (41.3, 194), "yield_kg_ha": (41.5, 24), "fsolar": (29.6, 161)},
    ("zhao2019", True): {"biomass_kg_ha": (33.0, 476), "yield_kg_ha": (32.7, 50), "fsolar": (30.4, 458)},
    ("simple_r", False): {"biomass_kg_ha": (29.8, 194), "yield_kg_ha": (21.1, 24), "fsolar": (38.8, 161)},
    ("simple_r", True): {"biomass_kg_ha": (25.2, 476), "yield_kg_ha": (17.2, 50), "fsolar": (39.9, 458)},
}
PAPER = {"biomass_kg_ha": 25.7, "yield_kg_ha": 25.4}
MARGIN_PERCENT = 0.5


def test_rrmse_by_hand():
    # errors 1 and 1 -> RMSE 1; mean observed 2 -> 50 %
    assert rrmse_percent([2.0, 4.0], [1.0, 3.0]) == pytest.approx(50.0)
    # errors 3 and -1 -> RMSE sqrt(5); mean observed 4 -> 100 sqrt(5) / 4 %
    assert rrmse_percent([5.0, 5.0], [2.0, 6.0]) == pytest.approx(100 * np.sqrt(5) / 4)
    assert np.isnan(rrmse_percent([], []))


@pytest.fixture(scope="module")
def shared():
    treatments = read_treatments(INPUTS)
    observations = read_observations(INPUTS)
    return treatments, observations, {(o.crop, o.experiment, o.treatment) for o in observations}


@needs_inputs
def test_switches_duplicates_and_loose_names(shared):
    treatments, _, _ = shared
    by_name = {t.name: t for t in treatments}
    # Listed twice in Simulation Management.csv, on (1) and off (0): runs.
    assert by_name["soybean/UFGA7801/1"].switched_on and by_name["maize/UFGA8201/1"].switched_on
    assert not by_name["soybean/IUAM/1"].switched_on
    assert not by_name["rice/IRMA9203/1"].water_stress and by_name["wheat/FACE92/1"].water_stress
    assert by_name["wheat/HSCE0701/1"].sowing == date(2008, 12, 1)
    irrigation = read_irrigation(INPUTS, treatments)
    # "wheat1,UFGA7801,1,78235,13" is soybean's; HSCE0701 applications on one day add up.
    assert irrigation[("soybean", "UFGA7801", 1)][date(1978, 8, 23)] == 13
    assert irrigation[("wheat", "HSCE0701", 7)][date(2007, 10, 10)] == pytest.approx(9.5 + 15.6)
    # Irrigation.csv names experiment OHWO by its weather file OHWO8801.
    assert ("soybean", "OHWO", 1) in irrigation


@needs_inputs
@pytest.mark.parametrize("source, run_all", sorted(MEASURED))
def test_rrmse_on_the_shared_inputs(shared, source, run_all):
    treatments, observations, observed = shared
    runs = run_treatments(INPUTS, select_treatments(treatments, observed, run_all), source, treatments)
    overall = compare(runs, observations).rrmse()["overall"]
    for variable, (measured, n) in MEASURED[(source, run_all)].items():
        assert overall[variable]["n"] == n
        assert overall[variable]["rrmse_percent"] <= measured + MARGIN_PERCENT
        if variable in PAPER and measured <= PAPER[variable]:
            assert overall[variable]["rrmse_percent"] <= PAPER[variable]


@needs_inputs
def test_simple_r_with_all_reaches_the_papers_biomass_and_yield(shared):
    treatments, observations, observed = shared
    runs = run_treatments(INPUTS, select_treatments(treatments, observed, True), "simple_r", treatments)
    overall = compare(runs, observations).rrmse()["overall"]
    assert overall["biomass_kg_ha"]["rrmse_percent"] <= PAPER["biomass_kg_ha"]
    assert overall["yield_kg_ha"]["rrmse_percent"] <= PAPER["yield_kg_ha"]


@needs_inputs
def test_cli_writes_the_documented_csv_and_summary(tmp_path, capsys):
    out, summary = tmp_path / "sim.csv", tmp_path / "summary.json"
    assert main(["validate", "--inputs", str(INPUTS), "--out", str(out), "--summary-json", str(summary),
                 "--params", "simple_r"]) == 0
    printed = capsys.readouterr().out
    assert "overall" in printed and "25.7" in printed and "29.5" in printed
    with out.open() as handle:
        rows = list(csv.DictReader(handle))
    assert tuple(rows[0]) == CSV_COLUMNS
    result = json.loads(summary.read_text())
    assert result["parameter_source"] == "simple_r"
    assert set(result["rrmse"]["overall"]) == {"biomass", "yield", "fSolar"}
    by_treatment = {}
    for row in rows:
        by_treatment.setdefault((row["crop"], row["experiment"], row["treatment"]), []).append(row)
    assert [f"{c}/{e}/{t}" for c, e, t in by_treatment] == result["treatments"]
    treatments = read_treatments(INPUTS)
    runs = run_treatments(INPUTS, [t for t in treatments if t.switched_on], "simple_r", treatments)
    for run in runs:  # one row per simulated day, sowing to maturity
        days = by_treatment[run.treatment.key[0], run.treatment.experiment, str(run.treatment.number)]
        assert [int(r["days_after_planting"]) for r in days] == list(range(run.days))
        assert days[0]["date"] == str(run.treatment.sowing)
        assert np.diff(np.array([r["date"] for r in days], dtype="datetime64[D]")).astype(int).tolist() == \
            [1] * (run.days - 1)


def copy_inputs(tmp_path) -> Path:
    inputs = tmp_path / "inputs"
    shutil.copytree(INPUTS, inputs)
    return inputs


def validate(inputs: Path, tmp_path) -> int:
    return main(["validate", "--inputs", str(inputs), "--out", str(tmp_path / "s.csv"),
                 "--summary-json", str(tmp_path / "s.json")])


def test_missing_inputs_directory_is_a_clear_error(tmp_path, capsys):
    assert validate(tmp_path / "nowhere", tmp_path) == 2
    assert "inputs directory not found" in capsys.readouterr().err


@needs_inputs
def test_missing_input_file_is_a_clear_error(tmp_path, capsys):
    inputs = copy_inputs(tmp_path)
    (inputs / "Input" / "Irrigation.csv").unlink()
    assert validate(inputs, tmp_path) == 2
    assert "Irrigation.csv" in capsys.readouterr().err


@needs_inputs
def test_unknown_cultivar_names_the_known_ones(tmp_path, capsys):
    inputs = copy_inputs(tmp_path)
    path = inputs / "Input" / "Treatment.csv"
    path.write_text(path.read_text().replace("Yecora Rojo", "Yecora Verde", 1))
    assert validate(inputs, tmp_path) == 2
    err = capsys.readouterr().err
    assert "unknown cultivar 'Yecora Verde'" in err and "known cultivars" in err


@needs_inputs
def test_missing_weather_inside_a_season_names_file_line_and_column(tmp_path, capsys):
    inputs = copy_inputs(tmp_path)
    path = inputs / "Weather" / "UFGA8201.WTH"
    lines = path.read_text().splitlines(keepends=True)
    number = next(i for i, line in enumerate(lines) if line.startswith("82100"))
    lines[number] = lines[number][:5] + "   -99" + lines[number][11:]
    path.write_text("".join(lines))
    assert validate(inputs, tmp_path) == 2
    assert f"UFGA8201.WTH, line {number + 1}, column srad_mj_m2: missing value" in capsys.readouterr().err
