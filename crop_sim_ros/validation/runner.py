"""Run the reference treatments through SIMPLE: one batched call of the model for all of them.

Each treatment's season starts on its sowing day (day 0) with its own weather (ET0 by Priestley-Taylor)
and runs until it matures (Tsum reached, canopy senesced, or the harvest date) or its weather file ends.
All treatments share one ``simulate_season`` call over the longest season: a field whose weather file
ends earlier is padded with neutral weather (no radiation, no rain) that only the days after its season
see, and every field's series is cut at its own maturity day.

Soils of the ``zhao2019`` source: the R distribution names soils by texture ("Loamy sand3"), Table 1b by
site. :data:`ZHAO2019_SOIL_OF_R_SOIL` maps each R soil name to the Table 1b site of the treatments that
use it. The numbers agree except for four sites, where the R set differs from the paper: rice Los Banos
(RZD 600 vs 400 mm), maize Gainesville (RZD 400 vs 1500 mm), sweetcorn Citra (RZD 1200 vs 1500 mm),
and the two tomato sites, whose R soils carry each other's Table 1b numbers.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import timedelta
from pathlib import Path

import numpy as np

from ..model.parameters import CropLibrary, Management, crop_library, normalize_name
from ..model.et0 import priestley_taylor
from ..model.season import simulate_season
from ..model.simple import field_parameters, stack_parameters
from ..weather.readers import read_dssat_wth
from ..weather.series import MODEL_VARIABLES, WeatherSeries
from .inputs import InputError, Treatment, read_irrigation, weather_file

ZHAO2019_SOIL_OF_R_SOIL = {
    "Loamy sand1": "Maricopa USA wheat FACE",
    "Clay loam1": "Lincoln New Zealand wheat",
    "Sand1": "Gainesville USA soybean",
    "Sandy loam1": "Ames USA soybean",
    "Clay loam2": "Wooster USA soybean",
    "Loamy sand2": "Los Banos Philippines rice",
    "Loamy sand3": "Gainesville USA maize",
    "Loamy sand4": "Canberra Australia potato",
    "Loamy sand5": "Huhhot China potato",
    "Loamy sand6": "WuMeng China potato",
    "Loamy sand7": "Benton USA potato",
    "Loamy sand8": "Maricopa USA cotton",
    "Sand2": "Gainesville USA green bean",
    "Clay1": "Citra USA sweetcorn",
    "Sandy loam2": "Gainesville USA tomato",
    "Clay loam3": "Bradenton USA tomato",
    "Sand3": "Gainesville USA peanut",
    "Sandy loam3": "Palmira Colombia cassava",
    "Loamy sand9": "Campo Grande Brazil banana",
    "Sand4": "Trzciana Poland carrot",
    "Sand5": "Gainesville USA dry bean",
}
_ZHAO2019_SOIL = {normalize_name(r): zhao for r, zhao in ZHAO2019_SOIL_OF_R_SOIL.items()}

# Series written per simulated day (names of the CSV columns), all (days,) arrays.
SERIES_COLUMNS = ("thermal_time_degc_d", "fsolar", "biomass_kg_ha", "yield_kg_ha", "paw_mm", "arid", "et0_mm")


@dataclass(frozen=True)
class TreatmentRun:
    """One treatment's simulated season, day 0 (sowing) to its maturity day (or the weather's end).

    ``series`` maps each of :data:`SERIES_COLUMNS` to a (days,) array: thermal time degC d, fSolar,
    biomass and yield kg ha-1, plant-available water mm, ARID, ET0 mm d-1. ``matured`` is False where
    the weather ended first.
    """

    treatment: Treatment
    cultivar: str
    dates: np.ndarray
    series: dict[str, np.ndarray]
    matured: bool

    @property
    def days(self) -> int:
        return len(self.dates)


def treatment_soil(library: CropLibrary, treatment: Treatment):
    """The treatment's soil in ``library``: by its R name, or (zhao2019) by its Table 1b site."""
    if library.source == "zhao2019":
        return library.soil(_ZHAO2019_SOIL.get(normalize_name(treatment.soil), treatment.soil))
    return library.soil(treatment.soil)


def _season_weather(treatment: Treatment, weather: WeatherSeries) -> tuple[WeatherSeries, int]:
    """The weather from sowing on (to the harvest day at most) and how many of its first days are
    complete (every model variable present): the season can run that far."""
    if treatment.harvest is not None and treatment.harvest < treatment.sowing:
        raise InputError(f"{treatment.name}: harvest {treatment.harvest} before sowing {treatment.sowing}")
    days = None if treatment.harvest is None else (treatment.harvest - treatment.sowing).days + 1
    available = len(weather) - int((np.datetime64(treatment.sowing, "D") - weather.dates[0]).astype(int))
    window = weather.window(treatment.sowing, None if days is None else min(days, available))
    missing = np.flatnonzero(~np.all([np.isfinite(getattr(window, v)) for v in MODEL_VARIABLES], axis=0))
    return window, int(missing[0]) if missing.size else len(window)


def _padded(values: np.ndarray, days: int) -> np.ndarray:
    return np.concatenate([values, np.zeros(days - len(values))])


def run_treatments(inputs_dir: str | Path, treatments: list[Treatment], source: str,
                   all_treatments: list[Treatment] | None = None,
                   irrigation_rows: str = "reference") -> list[TreatmentRun]:
    """Simulate ``treatments`` with parameter ``source`` (zhao2019 or simple_r) in one batched call.

    ``all_treatments`` (default ``treatments``) is what Irrigation.csv rows are matched against, the way
    ``irrigation_rows`` says (:func:`~crop_sim_ros.validation.inputs.read_irrigation`).
    Raises UnknownNameError for an unknown crop, cultivar or soil, WeatherError (file, line, column)
    for a missing or impossible weather value inside a simulated season, InputError for the rest.
    """
    if not treatments:
        raise InputError("no treatments to run")
    library = crop_library(source, inputs_dir)
    irrigation = read_irrigation(inputs_dir, all_treatments or treatments, irrigation_rows)
    weather_by_name: dict[str, WeatherSeries] = {}
    params, cultivars, windows, complete_days = [], [], [], []
    for t in treatments:
        species = library.species(t.crop)
        cultivar = library.cultivar(t.crop, t.cultivar)
        harvest_day = None if t.harvest is None else (t.harvest - t.sowing).days
        management = Management(co2_ppm=t.co2_ppm, fsolar_max=t.fsolar_max,
                                initial_biomass_kg_ha=t.initial_biomass_kg_ha,
                                initial_thermal_time_degc_d=t.initial_thermal_time_degc_d,
                                initial_fsolar=t.initial_fsolar, water_stress=t.water_stress,
                                harvest_day=harvest_day)
        params.append(field_parameters(species, cultivar, treatment_soil(library, t), management))
        cultivars.append(cultivar.name)
        key = t.weather.upper()
        if key not in weather_by_name:
            weather_by_name[key] = read_dssat_wth(weather_file(inputs_dir, t.weather))
        window, complete = _season_weather(t, weather_by_name[key])
        windows.append(window)
        complete_days.append(complete)

    days = max(complete_days)
    if days == 0:
        raise InputError("no treatment has weather on its sowing day")
    columns = {name: [] for name in (*MODEL_VARIABLES, "et0_mm", "irrigation_mm")}
    for t, window, complete in zip(treatments, windows, complete_days):
        season = window.window(t.sowing, complete)
        for name in MODEL_VARIABLES:
            columns[name].append(_padded(getattr(season, name), days))
        # Impossible values are checked on the season's own days below, once maturity is known.
        et0_mm = priestley_taylor(season.tmax_degc, season.tmin_degc, season.srad_mj_m2)
        columns["et0_mm"].append(np.concatenate([et0_mm, np.ones(days - complete)]))
        events = irrigation.get((t.crop, t.experiment, t.irrigation_treatment), {})
        columns["irrigation_mm"].append(np.array(
            [events.get(t.sowing + timedelta(days=d), 0.0) for d in range(days)]))
    arrays = {name: np.stack(values, axis=1) for name, values in columns.items()}
    result = simulate_season(stack_parameters(params), arrays["tmax_degc"], arrays["tmin_degc"],
                             arrays["srad_mj_m2"], arrays["rain_mm"], arrays["et0_mm"],
                             arrays["irrigation_mm"])

    runs = []
    for i, (t, window, complete) in enumerate(zip(treatments, windows, complete_days)):
        maturity_day = int(result.final_state.maturity_day[i])
        matured = 0 <= maturity_day < complete
        season_days = maturity_day + 1 if matured else complete
        if not matured and complete < len(window):
            window.window(t.sowing, complete + 1).require()  # names the missing value's file, line, column
        window.window(t.sowing, season_days).require()  # impossible values inside the season
        series = {
            "thermal_time_degc_d": result.thermal_time_degc_d, "fsolar": result.fsolar,
            "biomass_kg_ha": result.biomass_kg_ha, "yield_kg_ha": result.yield_kg_ha,
            "paw_mm": result.plant_available_water_mm, "arid": result.arid, "et0_mm": result.et0_mm,
        }
        runs.append(TreatmentRun(t, cultivars[i], window.dates[:season_days],
                                 {name: values[:season_days, i].copy() for name, values in series.items()},
                                 matured))
    return runs


def select_treatments(treatments: list[Treatment], observed_keys: set[tuple[str, str, int]],
                      run_all: bool) -> list[Treatment]:
    """The switched-on treatments, or with ``run_all`` every treatment that has observations."""
    if run_all:
        return [t for t in treatments if t.key in observed_keys]
    return [t for t in treatments if t.switched_on]

