"""``crop-sim simulate``: grow one season of a scenario under fixed daily irrigation rates and summarise it.

All rates run as one batched model call (one field per rate, at most MAX_FIELDS). Writes the daily series
(CSV), a summary (JSON) and a plot (PNG) of biomass, canopy cover, plant-available water, rain and irrigation.

A mistake in the input (an unknown scenario, a broken weather file, a missing data directory, an output
path that is a file, ...) is one line on stderr and exit status 2 (:mod:`crop_sim_ros.usage`).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

from .model import repeat_parameters, simulate_season
from .output import output_directory, save_figure_atomic, write_csv_atomic, write_json_atomic
from .task.scenario import Scenario, get_scenario, load_scenario, scenario_names
from .usage import UsageError, user_input

KG_PER_T = 1000.0
MAX_FIELDS = 1000  # irrigation rates of one run (one field each)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--task", default="benton-generated",
                        help=f"task name or scenario YAML path (default benton-generated; built in: {', '.join(scenario_names())})")
    parser.add_argument("--season", type=int, default=0, help="which season of the scenario (default 0)")
    parser.add_argument("--irrigation-mm", default="0,5,10",
                        help="comma-separated constant daily irrigation rates, mm/day, one field each (default 0,5,10)")
    parser.add_argument("--data-dir", default=None, help="data directory for file scenarios (default ../shared/data)")
    parser.add_argument("--out", default="out/simulate", help="output directory (default out/simulate)")
    parser.add_argument("--no-plot", action="store_true", help="skip the PNG")


def _rates(text: str) -> np.ndarray:
    try:
        rates = np.array([float(v) for v in text.split(",") if v.strip()])
    except ValueError:
        raise UsageError(f"--irrigation-mm: {text!r} is not a comma-separated list of numbers") from None
    if rates.size == 0 or not np.all(np.isfinite(rates)) or np.any(rates < 0) or np.any(rates > 100):
        raise UsageError(f"--irrigation-mm: every rate must be a number in [0, 100] mm/day, got {text!r}")
    if rates.size > MAX_FIELDS:
        raise UsageError(f"--irrigation-mm: {rates.size} rates; at most {MAX_FIELDS} (one field each)")
    return rates


def is_scenario_path(name_or_path: str) -> bool:
    """Whether a command's or a node's scenario names a YAML file (it ends in .yaml or .yml, or has a directory
    in it) rather than a built-in scenario."""
    name = name_or_path.strip()
    return name.endswith((".yaml", ".yml")) or os.sep in name


def find_scenario(name_or_path: str, data_dir: str | Path | None = None) -> Scenario:
    """A built-in scenario by name, or a scenario YAML file (a path: it ends in .yaml or .yml, or has a
    directory in it), its weather files and crop names checked. Raises UnknownNameError, ValueError or OSError
    (a missing file) naming what is wrong."""
    name = name_or_path.strip()
    if not is_scenario_path(name):
        return get_scenario(name, data_dir)
    scenario = load_scenario(Path(name).expanduser(), data_dir)
    for season in scenario.weather.seasons:
        scenario.season_path(season)
    scenario.field_parameters()
    return scenario


def run(args: argparse.Namespace) -> int:
    rates = _rates(args.irrigation_mm)
    if args.data_dir is not None and not Path(args.data_dir).is_dir():
        raise UsageError(f"--data-dir: {args.data_dir} is not a directory")
    with user_input("--task"):
        scenario = find_scenario(args.task, args.data_dir)
    if scenario.limits.quota_mm is not None or scenario.limits.capacity_mm_per_day is not None:
        raise UsageError(f"--task {scenario.name}: its water is limited (a quota or a pivot's capacity), which "
                         f"simulate's constant rates ignore; run it with `crop-sim evaluate --task {scenario.name}` "
                         f"or `crop-sim farm --task {scenario.name}`")
    with user_input("--task"):
        seasons = scenario.load_seasons()
    if not 0 <= args.season < len(seasons):
        raise UsageError(f"--season: scenario {scenario.name!r} has seasons 0..{len(seasons) - 1}")
    out = output_directory(args.out)
    weather = seasons[args.season]
    et0 = weather.et0_mm(scenario.et0_method)
    params = repeat_parameters(scenario.field_parameters(), rates.size)
    days = len(weather)
    result = simulate_season(params, weather.tmax_degc, weather.tmin_degc, weather.srad_mj_m2, weather.rain_mm,
                             et0, np.broadcast_to(rates, (days, rates.size)))
    final = result.final_state
    # Water and yield up to the maturity day (or the whole series for a field that did not mature).
    end = np.where(final.mature, final.maturity_day + 1, days)
    summary = {"scenario": scenario.name, "season": args.season, "weather_source": weather.source,
               "weather_filled": list(weather.filled), "sowing_date": str(weather.start),
               "et0_method": scenario.et0_method, "fields": []}
    print(f"{scenario.name} season {args.season}: {weather.source}, sown {weather.start}, "
          f"{scenario.crop} {scenario.cultivar}, ET0 {scenario.et0_method}")
    print(f"{'irrigation':>12} {'matured':>11} {'yield t/ha':>10} {'biomass t/ha':>12} {'irrig. mm':>9} "
          f"{'rain mm':>8} {'runoff mm':>9} {'drain mm':>8} {'transp. mm':>10} {'mean ARID':>9}")
    for i, rate in enumerate(rates):
        season = slice(0, int(end[i]))
        row = {
            "irrigation_mm_per_day": float(rate),
            "matured": bool(final.mature[i]),
            "maturity_date": str(weather.dates[final.maturity_day[i]]) if final.mature[i] else None,
            "days": int(end[i]),
            "yield_t_ha": float(final.biomass_kg_ha[i] * params.harvest_index[i] / KG_PER_T),
            "biomass_t_ha": float(final.biomass_kg_ha[i] / KG_PER_T),
            "irrigation_mm": float(result.irrigation_mm[season, i].sum()),
            "rain_mm": float(result.rain_mm[season, i].sum()),
            "runoff_mm": float(result.runoff_mm[season, i].sum()),
            "drainage_mm": float(result.drainage_mm[season, i].sum()),
            "transpiration_mm": float(result.transpiration_mm[season, i].sum()),
            "mean_arid": float(result.arid[season, i].mean()),
        }
        summary["fields"].append(row)
        matured = row["maturity_date"] or "no"
        print(f"{rate:>7.1f} mm/d {matured:>11} {row['yield_t_ha']:>10.2f} {row['biomass_t_ha']:>12.2f} "
              f"{row['irrigation_mm']:>9.0f} {row['rain_mm']:>8.0f} {row['runoff_mm']:>9.1f} "
              f"{row['drainage_mm']:>8.0f} {row['transpiration_mm']:>10.0f} {row['mean_arid']:>9.3f}")
    write_json_atomic(out / "summary.json", summary, indent=2)
    write_csv_atomic(out / "season.csv",
                     ["irrigation_mm_per_day", "date", "days_after_sowing", "thermal_time_degc_d", "fsolar",
                      "biomass_kg_ha", "yield_kg_ha", "paw_mm", "arid", "et0_mm", "rain_mm", "irrigation_mm"],
                     ([rate, weather.dates[d], d, result.thermal_time_degc_d[d, i], result.fsolar[d, i],
                       result.biomass_kg_ha[d, i], result.yield_kg_ha[d, i], result.plant_available_water_mm[d, i],
                       result.arid[d, i], et0[d], result.rain_mm[d, i], result.irrigation_mm[d, i]]
                      for i, rate in enumerate(rates) for d in range(days)))
    written = [out / "summary.json", out / "season.csv"]
    if not args.no_plot:
        written.append(_plot(out / "season.png", weather, result, rates, scenario.name))
    print("wrote " + ", ".join(str(p) for p in written))
    return 0


def _plot(path: Path, weather, result, rates: np.ndarray, title: str) -> Path:
    import matplotlib  # only for the picture

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    days = np.arange(len(weather))
    figure, axes = plt.subplots(4, 1, figsize=(9, 10), sharex=True)
    for i, rate in enumerate(rates):
        label = f"{rate:g} mm/day"
        axes[0].plot(days, result.biomass_kg_ha[:, i] / KG_PER_T, label=label)
        axes[1].plot(days, result.fsolar[:, i], label=label)
        axes[2].plot(days, result.plant_available_water_mm[:, i], label=label)
    axes[3].bar(days, weather.rain_mm, color="tab:blue", label="rain")
    axes[0].set_ylabel("biomass, t/ha")
    axes[1].set_ylabel("fSolar (canopy)")
    axes[2].set_ylabel("PAW, mm")
    axes[3].set_ylabel("rain, mm/day")
    axes[3].set_xlabel(f"days after sowing ({weather.start})")
    axes[0].legend(title="irrigation")
    axes[0].set_title(f"SIMPLE, {title}: {weather.source}")
    figure.tight_layout()
    save_figure_atomic(figure, path, dpi=90)
    plt.close(figure)
    return path
