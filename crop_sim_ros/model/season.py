"""Run whole seasons: N fields over D days, with the daily series recorded."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .simple import (CropState, DailyWeather, FieldParameters, check_irrigation, harvestable_yield_kg_ha,
                     initial_state, step)


@dataclass(frozen=True)
class SeasonResult:
    """Daily series of a season, arrays of shape (D, N): row d is the state at the start of day d
    (for the state series) or the fluxes of day d. ``final_state`` is the state after the last day.

    Units: thermal_time_degc_d degC d; biomass_kg_ha, yield_kg_ha kg ha-1; fsolar 1;
    plant_available_water_mm, et0_mm, irrigation_mm, rain_mm, runoff_mm, drainage_mm, transpiration_mm mm;
    arid 1.
    """

    thermal_time_degc_d: np.ndarray
    fsolar: np.ndarray
    biomass_kg_ha: np.ndarray
    yield_kg_ha: np.ndarray
    plant_available_water_mm: np.ndarray
    arid: np.ndarray
    et0_mm: np.ndarray
    irrigation_mm: np.ndarray
    rain_mm: np.ndarray
    runoff_mm: np.ndarray
    drainage_mm: np.ndarray
    transpiration_mm: np.ndarray
    final_state: CropState
    harvest_index: np.ndarray

    @property
    def harvested_yield_kg_ha(self) -> np.ndarray:
        """Yield on the maturity day of each field (NaN where the field did not mature)."""
        return np.where(self.final_state.mature, self.final_state.biomass_kg_ha * self.harvest_index, np.nan)


def simulate_season(params: FieldParameters, tmax_degc, tmin_degc, srad_mj_m2, rain_mm, et0_mm,
                    irrigation_mm=0.0) -> SeasonResult:
    """Run N fields over D days. Weather and irrigation arrays are (D,) (shared) or (D, N)."""
    n = params.n_fields
    weather = [np.broadcast_to(np.asarray(a, dtype=float).reshape(len(a), -1), (len(a), n))
               for a in (tmax_degc, tmin_degc, srad_mj_m2, rain_mm, et0_mm)]
    days = len(weather[0])
    irrigation = np.broadcast_to(check_irrigation(irrigation_mm).reshape(
        (days, -1) if np.ndim(irrigation_mm) else (1, 1)), (days, n))
    names = ("thermal_time_degc_d", "fsolar", "biomass_kg_ha", "yield_kg_ha", "plant_available_water_mm",
             "arid", "runoff_mm", "drainage_mm", "transpiration_mm")
    series = {name: np.empty((days, n)) for name in names}
    state = initial_state(params)
    for d in range(days):
        series["thermal_time_degc_d"][d] = state.thermal_time_degc_d
        series["fsolar"][d] = state.fsolar
        series["biomass_kg_ha"][d] = state.biomass_kg_ha
        series["yield_kg_ha"][d] = harvestable_yield_kg_ha(params, state)
        series["plant_available_water_mm"][d] = state.plant_available_water_mm
        day = DailyWeather(weather[0][d], weather[1][d], weather[2][d], weather[3][d], weather[4][d])
        state, fluxes = step(params, state, day, irrigation[d])
        series["arid"][d] = fluxes.arid
        series["runoff_mm"][d] = fluxes.runoff_mm
        series["drainage_mm"][d] = fluxes.drainage_mm
        series["transpiration_mm"][d] = fluxes.transpiration_mm
    return SeasonResult(**series, et0_mm=np.array(weather[4]), irrigation_mm=np.array(irrigation),
                        rain_mm=np.array(weather[3]), final_state=state,
                        harvest_index=np.broadcast_to(params.harvest_index, (n,)))
