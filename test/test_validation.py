"""The SIMPLE reference validation: reader, batched runner, RRMSE report and ``crop-sim validate``.

Measured RRMSE (%) on the shared input set (n in brackets), yield at harvest (see report.py), Irrigation.csv
read as the reference implementation reads it (the default):
======================= ============ ============ ============
source, treatments      biomass      yield        fSolar
======================= ============ ============ ============
zhao2019, switched on   41.2 (194)   41.6 (24)    30.1 (161)
zhao2019, --all         33.0 (476)   32.7 (50)    30.6 (458)
simple_r, switched on   29.7 (194)   21.2 (24)    39.1 (161)
simple_r, --all         25.2 (476)   17.2 (50)    40.0 (458)
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
from crop_sim_ros.validation.inputs import InputError, read_irrigation

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
INPUTS = DATA / "simple_r_inputs"
needs_inputs = pytest.mark.usefixtures("shared_data")  # fails, never skips, without the data

# (source, --all) -> measured overall RRMSE % (as the summary JSON rounds it) and n: biomass, yield, fSolar.
MEASURED = {
    ("zhao2019", False): {"biomass_kg_ha": (41.216, 194), "yield_kg_ha": (41.550, 24), "fsolar": (30.081, 161)},
    ("zhao2019", True): {"biomass_kg_ha": (32.999, 476), "yield_kg_ha": (32.714, 50), "fsolar": (30.588, 458)},
    ("simple_r", False): {"biomass_kg_ha": (29.727, 194), "yield_kg_ha": (21.165, 24), "fsolar": (39.116, 161)},
    ("simple_r", True): {"biomass_kg_ha": (25.183, 476), "yield_kg_ha": (17.222, 50), "fsolar": (39.981, 458)},
}
PAPER = {"biomass_kg_ha": 25.7, "yield_kg_ha": 25.4}
# The figures above are rounded to 0.001; another machine's summation order moves them by ~1e-12.
MEASURED_TOLERANCE_PERCENT = 0.002
# Soybean UFGA7801 treatment 1 (irrigated, Bragg): final biomass of the reference R implementation, kg/ha.
REFERENCE_UFGA7801_1_FINAL_BIOMASS_KG_HA = 8231.6


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
    # HSCE0701 applications on one day add up.
    assert irrigation[("wheat", "HSCE0701", 7)][date(2007, 10, 10)] == pytest.approx(9.5 + 15.6)
    # As the reference reads the rows: "wheat1,UFGA7801,1,78235,13" names no wheat experiment, and
    # "soybean,OHWO8801,..." no soybean experiment: both are dropped.
    assert date(1978, 8, 23) not in irrigation[("soybean", "UFGA7801", 1)]
    assert sum(irrigation[("soybean", "UFGA7801", 1)].values()) == 193  # its 20 soybean rows (label: "190mm")
    assert not any(experiment in ("OHWO", "OHWO8801") for _, experiment, _ in irrigation)
    # Our reading, on request: "wheat1" is soybean's, and OHWO8801 is experiment OHWO's weather file.
    attributed = read_irrigation(INPUTS, treatments, "attributed")
    assert attributed[("soybean", "UFGA7801", 1)][date(1978, 8, 23)] == 13
    assert sum(attributed[("soybean", "OHWO", 1)].values()) == pytest.approx(595)
    assert {k: v for k, v in attributed.items() if k[1] not in ("UFGA7801", "OHWO")} == \
        {k: v for k, v in irrigation.items() if k[1] != "UFGA7801"}
    with pytest.raises(InputError, match="irrigation_rows must be one of reference, attributed"):
        read_irrigation(INPUTS, treatments, "loose")


def _final_biomass_kg_ha(csv_path: Path, experiment: str, treatment: int) -> tuple[float, int]:
    """The last simulated day's biomass (kg/ha) and days after planting of one treatment in a series CSV."""
    with csv_path.open() as handle:
        rows = [r for r in csv.DictReader(handle) if (r["experiment"], r["treatment"]) == (experiment, str(treatment))]
    return float(rows[-1]["biomass_kg_ha"]), int(rows[-1]["days_after_planting"])


@needs_inputs
def test_validate_reads_irrigation_as_the_reference_implementation(tmp_path, capsys):
    """``crop-sim validate --params simple_r --all`` matches the reference R code on soybean UFGA7801/1 (the
    treatment the two readings disagree on in growth); ``--irrigation-rows attributed`` adds 13 mm to it."""
    outputs = {}
    for rows in ("reference", "attributed"):
        out, summary = tmp_path / f"{rows}.csv", tmp_path / f"{rows}.json"
        extra = [] if rows == "reference" else ["--irrigation-rows", rows]
        assert main(["validate", "--inputs", str(INPUTS), "--out", str(out), "--summary-json", str(summary),
                     "--params", "simple_r", "--all", *extra]) == 0
        assert json.loads(summary.read_text())["irrigation_rows"] == rows
        outputs[rows] = _final_biomass_kg_ha(out, "UFGA7801", 1)
    capsys.readouterr()
    biomass, maturity_dap = outputs["reference"]
    assert biomass == pytest.approx(REFERENCE_UFGA7801_1_FINAL_BIOMASS_KG_HA, rel=1e-4)
    attributed_biomass, attributed_maturity_dap = outputs["attributed"]
    assert attributed_biomass / REFERENCE_UFGA7801_1_FINAL_BIOMASS_KG_HA - 1 == pytest.approx(0.0576, abs=0.0005)
    assert attributed_maturity_dap == maturity_dap + 2


@needs_inputs
def test_ohwo_irrigation_rows_change_soil_water_not_growth(shared):
    """The 595 mm of the 'soybean,OHWO8801' rows (given to OHWO/1 only by the attributed reading) raise its
    plant-available water by up to ~320 mm but leave growth unchanged (no water stress either way)."""
    treatments, _, _ = shared
    (ohwo,) = [t for t in treatments if t.name == "soybean/OHWO/1"]
    reference, attributed = (run_treatments(INPUTS, [ohwo], "simple_r", treatments, rows)[0]
                             for rows in ("reference", "attributed"))
    np.testing.assert_array_equal(attributed.series["biomass_kg_ha"], reference.series["biomass_kg_ha"])
    extra_paw_mm = attributed.series["paw_mm"] - reference.series["paw_mm"]
    assert extra_paw_mm.min() >= 0 and 300 < extra_paw_mm.max() < 340


@needs_inputs
@pytest.mark.parametrize("source, run_all", sorted(MEASURED))
def test_rrmse_on_the_shared_inputs(shared, source, run_all):
    treatments, observations, observed = shared
    runs = run_treatments(INPUTS, select_treatments(treatments, observed, run_all), source, treatments)
    overall = compare(runs, observations).rrmse()["overall"]
    for variable, (measured, n) in MEASURED[(source, run_all)].items():
        assert overall[variable]["n"] == n
        assert overall[variable]["rrmse_percent"] == pytest.approx(measured, abs=MEASURED_TOLERANCE_PERCENT), variable


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
