"""``crop-sim validate``: run the SIMPLE reference treatments and report RRMSE against the observations.

    crop-sim validate --inputs ../shared/data/simple_r_inputs --out sim.csv --summary-json summary.json \
        [--params zhao2019|simple_r] [--all] [--irrigation-rows reference|attributed]

Prints per crop and overall n and RRMSE (%) of biomass, yield and fSolar beside Zhao et al. (2019)
Table 3, writes the JSON summary and the daily simulated series (one CSV row per treatment and day).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from ..output import write_csv_atomic, write_json_atomic
from ..model.parameters import PARAMETER_SOURCES, UnknownNameError
from ..weather.series import WeatherError
from .inputs import IRRIGATION_ROWS, InputError, read_observations, read_treatments
from .report import OVERALL, PAPER_TABLE3_RRMSE_PERCENT, VARIABLES, compare
from .runner import SERIES_COLUMNS, TreatmentRun, run_treatments, select_treatments

CSV_COLUMNS = ("experiment", "treatment", "crop", "cultivar", "date", "days_after_planting", *SERIES_COLUMNS)
_LABELS = {"biomass_kg_ha": "biomass", "yield_kg_ha": "yield", "fsolar": "fSolar"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--inputs", required=True, type=Path,
                        help="the SIMPLE input set (folders Input, Observation, Weather)")
    parser.add_argument("--out", required=True, type=Path, help="CSV of the daily simulated series")
    parser.add_argument("--summary-json", required=True, type=Path, help="JSON summary of the RRMSE")
    parser.add_argument("--params", choices=PARAMETER_SOURCES, default="zhao2019",
                        help="parameter source: the paper's Tables 1a/1b or the R distribution's tables")
    parser.add_argument("--all", action="store_true",
                        help="run every treatment with observations, not only those switched on")
    parser.add_argument("--irrigation-rows", choices=IRRIGATION_ROWS, default=IRRIGATION_ROWS[0],
                        help="reference: Irrigation.csv rows irrigate the treatments of their species and "
                             "experiment, as the reference R code reads them; attributed: also give the "
                             "'wheat1,UFGA7801' row to soybean UFGA7801 and the 'soybean,OHWO8801' rows to "
                             "experiment OHWO (see validation/inputs.py)")


def write_series_csv(path: Path, runs: list[TreatmentRun]) -> None:
    """One row per treatment and simulated day, columns :data:`CSV_COLUMNS`."""
    write_csv_atomic(path, CSV_COLUMNS, (
        [run.treatment.experiment, run.treatment.number, run.treatment.crop, run.cultivar, str(when), day,
         *(f"{float(run.series[name][day]):.6g}" for name in SERIES_COLUMNS)]
        for run in runs for day, when in enumerate(run.dates)))


def _format(entry: dict) -> str:
    value = entry["rrmse_percent"]
    return f"{entry['n']:>5} {'-' if math.isnan(value) else f'{value:.1f}':>9}"


def format_table(rrmse: dict) -> str:
    """The RRMSE table: a row per crop and the overall row with the paper's Table 3 beside it."""
    header = "crop         " + "".join(f"{'n':>5} {_LABELS[v] + ' %':>9}" for v in VARIABLES)
    lines = [header]
    for crop in [c for c in rrmse if c != OVERALL] + [OVERALL]:
        lines.append(f"{crop:<12} " + "".join(_format(rrmse[crop][v]) for v in VARIABLES))
    lines.append(f"{'paper Tab. 3':<12} " + "".join(f"{'':>5} {PAPER_TABLE3_RRMSE_PERCENT[v]:>9.1f}"
                                                     for v in VARIABLES))
    return "\n".join(lines)


def _json_number(value: float):
    return None if math.isnan(value) else round(value, 3)


def run(args: argparse.Namespace) -> int:
    try:
        if not args.inputs.is_dir():
            raise InputError(f"inputs directory not found: {args.inputs}")
        treatments = read_treatments(args.inputs)
        observations = read_observations(args.inputs)
        observed = {(o.crop, o.experiment, o.treatment) for o in observations}
        selected = select_treatments(treatments, observed, args.all)
        runs = run_treatments(args.inputs, selected, args.params, treatments, args.irrigation_rows)
    except (InputError, UnknownNameError, WeatherError, FileNotFoundError) as error:
        print(f"crop-sim validate: {error}", file=sys.stderr)
        return 2
    comparison = compare(runs, observations)
    rrmse = comparison.rrmse()
    print(f"SIMPLE validation, parameters {args.params}, {len(runs)} treatments "
          f"({'all with observations' if args.all else 'switched on'}), Irrigation.csv rows read as "
          f"{args.irrigation_rows}; RRMSE = 100 RMSE / mean(observed)")
    print(format_table(rrmse))
    if comparison.date_mismatches:
        print(f"{len(comparison.date_mismatches)} observations whose Date disagrees with sowing + DAP "
              "(matched by Date); see the JSON summary")
    write_series_csv(args.out, runs)
    summary = {
        "parameter_source": args.params,
        "run_all_observed": args.all,
        "irrigation_rows": args.irrigation_rows,
        "treatments": [t.treatment.name for t in runs],
        "not_matured": [t.treatment.name for t in runs if not t.matured],
        "rrmse": {crop: {_LABELS[v]: {"rrmse_percent": _json_number(e["rrmse_percent"]), "n": e["n"]}
                         for v, e in table.items()} for crop, table in rrmse.items()},
        "paper_table3_rrmse_percent": {_LABELS[v]: value for v, value in PAPER_TABLE3_RRMSE_PERCENT.items()},
        "unmatched_observations": [o.source for o in comparison.unmatched],
        "skipped_observations": len(comparison.skipped),
        "date_mismatches": comparison.date_mismatches,
    }
    write_json_atomic(args.summary_json, summary, indent=2)
    print(f"wrote {args.out} and {args.summary_json}")
    return 0
