"""What a scenario's seasons are like for the crop: ``python -m crop_sim_ros.task.climate_summary NAME...``

For each scenario, over its first ``--seasons`` seasons (all of a smaller scenario), a Markdown row of means:

================================ ========= ==================================================================
Column                           Unit      Mean over the seasons of
================================ ========= ==================================================================
days to maturity, 0 / 10 mm/day  d         the day the crop matures, rainfed and irrigated 10 mm every day
yield, 0 / 10 mm/day             t ha-1    dry yield at maturity, likewise
ET0 to maturity                  mm d-1    the scenario's ET0 (FAO-56 Penman-Monteith unless it says other),
                                           sowing to maturity at 10 mm/day
vapour pressure, TMAX            hPa, degC the daily values over the same days
rain to maturity                 mm        the season's total over the same days
================================ ========= ==================================================================

Every season runs on the batched model (:func:`crop_sim_ros.model.simulate_season`), so a pool of 1,000
seasons takes about a second. Imports neither rclpy, gymnasium nor torch.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from ..model import harvestable_yield_kg_ha, repeat_parameters, simulate_season
from .scenario import get_scenario

COLUMNS = ("scenario", "seasons", "days to maturity, 0 / 10 mm/day", "yield t/ha, 0 / 10 mm/day",
           "ET0 to maturity, mm/d", "vapour pressure, hPa", "TMAX, degC", "rain to maturity, mm")


def summary(name: str, max_seasons: int = 200, data_dir=None) -> dict:
    """The means of the module docstring's table for scenario ``name`` (its first ``max_seasons`` seasons)."""
    scenario = get_scenario(name, data_dir)
    seasons = scenario.load_seasons()[:max_seasons]
    days = min(len(s) for s in seasons)
    weather = {column: np.stack([getattr(s, column)[:days] for s in seasons], axis=1)
               for column in ("tmax_degc", "tmin_degc", "srad_mj_m2", "rain_mm", "vap_hpa")}
    et0_mm = np.stack([s.et0_mm(scenario.et0_method)[:days] for s in seasons], axis=1)
    params = repeat_parameters(scenario.field_parameters(), len(seasons))
    result = {"scenario": name, "seasons": len(seasons)}
    for irrigation_mm in (0.0, 10.0):
        final = simulate_season(params, weather["tmax_degc"], weather["tmin_degc"], weather["srad_mj_m2"],
                                weather["rain_mm"], et0_mm, irrigation_mm).final_state
        if not np.all(final.mature):
            raise ValueError(f"{name}: {int(np.sum(~final.mature))} of {len(seasons)} seasons do not mature in "
                             f"{days} days at {irrigation_mm:g} mm/day")
        result[f"days_{irrigation_mm:g}mm"] = float(np.mean(final.maturity_day))
        result[f"yield_t_ha_{irrigation_mm:g}mm"] = float(np.mean(harvestable_yield_kg_ha(params, final))) / 1000.0
    # sowing to maturity at 10 mm/day: day d of season k counts while d < its maturity day
    to_maturity = np.arange(days)[:, None] < final.maturity_day[None, :]
    for key, values in (("et0_mm_d", et0_mm), ("vap_hpa", weather["vap_hpa"]), ("tmax_degc", weather["tmax_degc"])):
        result[key] = float(values[to_maturity].mean())
    result["rain_mm"] = float((weather["rain_mm"] * to_maturity).sum(axis=0).mean())
    return result


def markdown_row(row: dict) -> str:
    return (f"| `{row['scenario']}` | {row['seasons']:,} | {row['days_0mm']:.0f} / {row['days_10mm']:.0f} | "
            f"{row['yield_t_ha_0mm']:.2f} / {row['yield_t_ha_10mm']:.2f} | {row['et0_mm_d']:.2f} | "
            f"{row['vap_hpa']:.1f} | {row['tmax_degc']:.1f} | {row['rain_mm']:.0f} |")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m crop_sim_ros.task.climate_summary",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("scenarios", nargs="+", metavar="NAME", help="scenario names (crop-sim scenarios lists them)")
    parser.add_argument("--seasons", type=int, default=200, help="the first SEASONS seasons of each (default 200)")
    parser.add_argument("--data-dir", default=None, help="reference data directory (real seasons' files)")
    args = parser.parse_args(argv)
    if args.seasons < 1:
        parser.error(f"--seasons: {args.seasons} is not a positive count")
    print("| " + " | ".join(COLUMNS) + " |")
    print("|---|" + "---:|" * (len(COLUMNS) - 1))
    for name in args.scenarios:
        try:
            row = summary(name, args.seasons, args.data_dir)
        except (KeyError, ValueError, FileNotFoundError) as error:
            print(f"{name}: {error}", file=sys.stderr)
            return 2
        print(markdown_row(row), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
