"""The SIMPLE crop model (Zhao et al. 2019) for N independent fields at once.

One call of :func:`step` advances every field by one day. Parameters, state and weather are numpy arrays
of shape ``(N,)`` (scalars broadcast), so a batch of seasons, cultivars or weather draws runs at array
speed; a single field is the ``N = 1`` case of the same code.

Reference semantics (see ``shared/spec/SIMPLE_MODEL.md``): day 0 is the sowing day; the thermal time and
biomass of day d exclude day d's own increments; fSolar(d) uses I50B(d-1) and the canopy water response
of day d-1; I50B grows by the larger of its heat and drought increments; CO2 sensitivity is per 100 ppm;
irrigation passes through runoff like rain.

State (:class:`CropState`, values at the start of day d)
-----------------------------------------------------------
=========================== ========= ===========================================================
Name                        Unit      Description
=========================== ========= ===========================================================
days_since_sowing           d         d (0 on the sowing day)
thermal_time_degc_d         degC d    TT(d): cumulative thermal time before day d
biomass_kg_ha               kg ha-1   Biomass(d): above-ground biomass before day d's growth
fsolar                      1         fSolar(d): fraction of radiation intercepted on day d
fsolar_previous             1         fSolar(d-1) (for the senescence rule)
i50b_degc_d                 degC d    I50B(d-1): the senescence parameter fSolar(d+1) will use
plant_available_water_mm    mm        W: plant-available water in the root zone
mature                      bool      the crop reached maturity (or harvest); it no longer grows
maturity_day                d         the maturity day (-1 until mature)
=========================== ========= ===========================================================

State, weather and fluxes are named tuples (immutable, and cheap to build on the one-field hot path);
parameters are a frozen dataclass.

After maturity the crop state is frozen (biomass, TT, fSolar stay at their maturity-day values) while the
soil water balance goes on, so water is conserved on every day of every field.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import NamedTuple

import numpy as np

from .parameters import Cultivar, Management, Soil, Species

# ARID's daily water uptake coefficient (Woli et al. 2012), d-1.
WATER_UPTAKE_COEFFICIENT = 0.096
# Senescence ends the season when fSolar falls to or below this fraction.
SENESCENCE_FSOLAR = 0.005
# Growth is g m-2 per MJ m-2; 1 g m-2 = 10 kg ha-1.
KG_HA_PER_G_M2 = 10.0


# --- Response functions (each usable on scalars or arrays) -------------------------------------------

def thermal_time_increment(tmean_degc, base_temperature_degc, xp=np):
    """dTT = max(Tmean - Tbase, 0), degC d."""
    return xp.maximum(tmean_degc - base_temperature_degc, 0.0)


def temperature_response(tmean_degc, base_temperature_degc, optimal_temperature_degc, xp=np):
    """f_temp: 0 below Tbase, linear to 1 at Topt, 1 above."""
    ramp = (tmean_degc - base_temperature_degc) / (optimal_temperature_degc - base_temperature_degc)
    return xp.clip(ramp, 0.0, 1.0)


def heat_response(tmax_degc, heat_stress_onset_degc, extreme_heat_degc, xp=np):
    """f_heat on TMAX: 1 up to Theat, linear to 0 at Textreme, 0 above."""
    ramp = 1.0 - (tmax_degc - heat_stress_onset_degc) / (extreme_heat_degc - heat_stress_onset_degc)
    return xp.clip(ramp, 0.0, 1.0)


def co2_response(co2_ppm, co2_sensitivity_per_100ppm):
    """f_CO2 = 1 + S_CO2 (CO2 - 350) / 100 on [350, 700) ppm; 1 below 350; 1 + 3.5 S_CO2 from 700 ppm on."""
    excess_per_100ppm = np.clip(np.asarray(co2_ppm, dtype=float) - 350.0, 0.0, 350.0) / 100.0
    return 1.0 + co2_sensitivity_per_100ppm * excess_per_100ppm


def water_response(arid, water_stress_sensitivity, xp=np):
    """f_water = max(0, 1 - S_water * ARID)."""
    return xp.maximum(1.0 - water_stress_sensitivity * arid, 0.0)


def canopy_water_response(f_water, xp=np):
    """fsw: 1 while f_water > 0.1, else 0.9 + f_water (severe drought shrinks the canopy)."""
    return xp.where(f_water > 0.1, 1.0, 0.9 + f_water)


def canopy_cover(thermal_time_degc_d, i50a_degc_d, thermal_time_to_maturity_degc_d, i50b_degc_d, fsolar_max,
                 xp=np):
    """min(growth curve, senescence curve) of radiation interception, before the water response."""
    grow = fsolar_max / (1.0 + xp.exp(-0.01 * (thermal_time_degc_d - i50a_degc_d)))
    senesce = fsolar_max / (1.0 + xp.exp(0.01 * (thermal_time_degc_d -
                                                 (thermal_time_to_maturity_degc_d - i50b_degc_d))))
    return xp.minimum(xp.minimum(grow, senesce), 1.0)


def runoff_retention_mm(runoff_curve_number):
    """SCS potential maximum retention S = 25400 / RCN - 254, mm."""
    return 25400.0 / runoff_curve_number - 254.0


class WaterFluxes(NamedTuple):
    """One day of the one-bucket water balance, mm (ARID dimensionless)."""

    runoff_mm: np.ndarray
    drainage_mm: np.ndarray
    transpiration_mm: np.ndarray
    plant_available_water_mm: np.ndarray  # at the end of the day
    arid: np.ndarray


def water_balance(plant_available_water_mm, water_input_mm, et0_mm, retention_mm,
                  available_water_capacity, deep_drainage_coefficient, root_zone_depth_mm, xp=np) -> WaterFluxes:
    """Woli et al. (2012) bucket: runoff (SCS), deep drainage above capacity, transpiration, ARID.

    ``water_input_mm`` is rain plus irrigation. Conserves water exactly:
    water_input = runoff + drainage + transpiration + (W_end - W_start).
    """
    excess = xp.maximum(water_input_mm - 0.2 * retention_mm, 0.0)
    runoff = excess * excess / (water_input_mm + 0.8 * retention_mm)
    after_infiltration = plant_available_water_mm + water_input_mm - runoff
    capacity_mm = available_water_capacity * root_zone_depth_mm
    drainage = deep_drainage_coefficient * xp.maximum(after_infiltration - capacity_mm, 0.0)
    after_drainage = after_infiltration - drainage
    transpiration = xp.minimum(WATER_UPTAKE_COEFFICIENT * after_drainage, et0_mm)
    arid = 1.0 - transpiration / et0_mm
    return WaterFluxes(runoff, drainage, transpiration, after_drainage - transpiration, arid)


# --- Parameters, weather, state ---------------------------------------------------------------------

@dataclass(frozen=True)
class FieldParameters:
    """What the daily step needs, for N fields: each attribute is a float or an array of shape (N,).

    Built by :func:`field_parameters` (one field) or :func:`stack_parameters` (a batch). Units as in
    :mod:`crop_sim_ros.model.parameters`; ``co2_factor`` is f_CO2 (fixed over a season),
    ``water_stress_sensitivity`` is 0 where water stress is switched off, ``harvest_day`` is inf where
    the crop is harvested at maturity, ``runoff_retention_mm`` is S of the SCS curve number.
    """

    base_temperature_degc: np.ndarray
    optimal_temperature_degc: np.ndarray
    radiation_use_efficiency: np.ndarray
    i50_max_heat_degc_d: np.ndarray
    i50_max_water_degc_d: np.ndarray
    heat_stress_onset_degc: np.ndarray
    extreme_heat_degc: np.ndarray
    co2_factor: np.ndarray
    water_stress_sensitivity: np.ndarray
    thermal_time_to_maturity_degc_d: np.ndarray
    harvest_index: np.ndarray
    i50a_degc_d: np.ndarray
    i50b_degc_d: np.ndarray
    fsolar_max: np.ndarray
    harvest_day: np.ndarray
    available_water_capacity: np.ndarray
    runoff_retention_mm: np.ndarray
    deep_drainage_coefficient: np.ndarray
    root_zone_depth_mm: np.ndarray
    initial_biomass_kg_ha: np.ndarray
    initial_thermal_time_degc_d: np.ndarray
    initial_fsolar: np.ndarray
    initial_paw_mm: np.ndarray

    @property
    def capacity_mm(self):
        """Plant-available water of a full root zone, mm."""
        return self.available_water_capacity * self.root_zone_depth_mm

    @property
    def n_fields(self) -> int:
        return int(np.broadcast(*(getattr(self, f.name) for f in fields(self))).size)


def field_parameters(species: Species, cultivar: Cultivar, soil: Soil,
                     management: Management = Management()) -> FieldParameters:
    """The step's parameters for one field, from SIMPLE's species, cultivar, soil and management."""
    if cultivar.species != species.name:
        raise ValueError(f"cultivar {cultivar.name!r} is a {cultivar.species}, not a {species.name}")
    capacity_mm = soil.capacity_mm
    initial_paw = capacity_mm if management.initial_paw_mm is None else management.initial_paw_mm
    if initial_paw > capacity_mm:
        raise ValueError(f"management: initial_paw_mm {initial_paw} exceeds the soil's capacity {capacity_mm} mm")
    values = dict(
        base_temperature_degc=species.base_temperature_degc,
        optimal_temperature_degc=species.optimal_temperature_degc,
        radiation_use_efficiency=species.radiation_use_efficiency,
        i50_max_heat_degc_d=species.i50_max_heat_degc_d,
        i50_max_water_degc_d=species.i50_max_water_degc_d,
        heat_stress_onset_degc=species.heat_stress_onset_degc,
        extreme_heat_degc=species.extreme_heat_degc,
        co2_factor=float(co2_response(management.co2_ppm, species.co2_sensitivity_per_100ppm)),
        water_stress_sensitivity=species.water_stress_sensitivity if management.water_stress else 0.0,
        thermal_time_to_maturity_degc_d=cultivar.thermal_time_to_maturity_degc_d,
        harvest_index=cultivar.harvest_index,
        i50a_degc_d=cultivar.i50a_degc_d,
        i50b_degc_d=cultivar.i50b_degc_d,
        fsolar_max=management.fsolar_max,
        harvest_day=np.inf if management.harvest_day is None else float(management.harvest_day),
        available_water_capacity=soil.available_water_capacity,
        runoff_retention_mm=runoff_retention_mm(soil.runoff_curve_number),
        deep_drainage_coefficient=soil.deep_drainage_coefficient,
        root_zone_depth_mm=soil.root_zone_depth_mm,
        initial_biomass_kg_ha=management.initial_biomass_kg_ha,
        initial_thermal_time_degc_d=management.initial_thermal_time_degc_d,
        initial_fsolar=management.initial_fsolar,
        initial_paw_mm=initial_paw,
    )
    return FieldParameters(**{k: np.array([float(v)]) for k, v in values.items()})


def stack_parameters(batch: list[FieldParameters]) -> FieldParameters:
    """One FieldParameters for all fields of ``batch`` (concatenated in order)."""
    if not batch:
        raise ValueError("stack_parameters needs at least one field")
    n = [p.n_fields for p in batch]
    return FieldParameters(**{
        f.name: np.concatenate([np.broadcast_to(getattr(p, f.name), (k,)) for p, k in zip(batch, n)])
        for f in fields(FieldParameters)})


def repeat_parameters(params: FieldParameters, n_fields: int) -> FieldParameters:
    """The same field ``n_fields`` times (a batch of k fields: the whole batch ``n_fields`` times, in order,
    as ``stack_parameters([params] * n_fields)`` gives, with one ``np.tile`` per parameter instead of one
    broadcast per field)."""
    if n_fields < 1:
        raise ValueError(f"repeat_parameters needs n_fields >= 1, got {n_fields}")
    k = params.n_fields
    return FieldParameters(**{f.name: np.tile(np.broadcast_to(getattr(params, f.name), (k,)), n_fields)
                              for f in fields(FieldParameters)})


class DailyWeather(NamedTuple):
    """One day's weather for N fields (floats or arrays of shape (N,)).

    tmax_degc, tmin_degc: degC; srad_mj_m2: MJ m-2 d-1; rain_mm: mm; et0_mm: reference ET, mm d-1
    (from :mod:`crop_sim_ros.model.et0`; must be > 0).
    """

    tmax_degc: np.ndarray
    tmin_degc: np.ndarray
    srad_mj_m2: np.ndarray
    rain_mm: np.ndarray
    et0_mm: np.ndarray


class CropState(NamedTuple):
    """State of N fields at the start of a day; see the module table for names and units."""

    days_since_sowing: np.ndarray
    thermal_time_degc_d: np.ndarray
    biomass_kg_ha: np.ndarray
    fsolar: np.ndarray
    fsolar_previous: np.ndarray
    i50b_degc_d: np.ndarray
    plant_available_water_mm: np.ndarray
    mature: np.ndarray
    maturity_day: np.ndarray

    def take(self, index) -> "CropState":
        """The state of the selected fields (an index array or boolean mask)."""
        return CropState(*(value[index] for value in self))


def harvestable_yield_kg_ha(params: FieldParameters, state: CropState):
    """Yield(d) = Biomass(d) * HI, kg ha-1 (the harvested yield once the field is mature)."""
    return state.biomass_kg_ha * params.harvest_index


class DailyFluxes(NamedTuple):
    """What happened on one day, per field.

    ============================= ========= =======================================================
    Name                          Unit      Description
    ============================= ========= =======================================================
    thermal_time_increment_degc_d degC d    dTT of the day (0 once mature)
    biomass_increment_kg_ha       kg ha-1   dBiomass of the day (0 on and after the maturity day)
    f_temp, f_heat, f_water       1         the day's growth responses
    arid                          1         Agricultural Reference Index for Drought
    et0_mm                        mm        reference evapotranspiration
    water_input_mm                mm        rain + irrigation
    runoff_mm, drainage_mm        mm        SCS runoff, deep drainage below the root zone
    transpiration_mm              mm        water taken up by the crop (ARID's T)
    matured                       bool      this day is the maturity (or harvest) day
    ============================= ========= =======================================================
    """

    thermal_time_increment_degc_d: np.ndarray
    biomass_increment_kg_ha: np.ndarray
    f_temp: np.ndarray
    f_heat: np.ndarray
    f_water: np.ndarray
    arid: np.ndarray
    et0_mm: np.ndarray
    water_input_mm: np.ndarray
    runoff_mm: np.ndarray
    drainage_mm: np.ndarray
    transpiration_mm: np.ndarray
    matured: np.ndarray


def initial_state(params: FieldParameters) -> CropState:
    """The sowing-day state of every field of ``params``."""
    n = params.n_fields

    def full(value) -> np.ndarray:
        return np.array(np.broadcast_to(value, (n,)), dtype=float)

    fsolar = full(params.initial_fsolar)
    return CropState(
        days_since_sowing=np.zeros(n, dtype=np.int64),
        thermal_time_degc_d=full(params.initial_thermal_time_degc_d),
        biomass_kg_ha=full(params.initial_biomass_kg_ha),
        fsolar=fsolar,
        fsolar_previous=fsolar.copy(),
        i50b_degc_d=full(params.i50b_degc_d),
        plant_available_water_mm=full(params.initial_paw_mm),
        mature=np.zeros(n, dtype=bool),
        maturity_day=np.full(n, -1, dtype=np.int64),
    )


def step(params: FieldParameters, state: CropState, weather: DailyWeather, irrigation_mm,
         xp=np) -> tuple[CropState, DailyFluxes]:
    """Advance every field by one day: returns the next day's state and this day's fluxes.

    ``irrigation_mm`` (float or array (N,)) is applied today with the rain. It must be finite and >= 0:
    this function does not check (it is the hot path); :func:`check_irrigation` does, and every face
    (environment, node, command line) calls it.

    ``xp`` is the array namespace: numpy for N fields, or :data:`SCALAR_MATH` for one field held as Python
    floats (:func:`scalar_parameters`, :func:`scalar_state`), which avoids numpy's per-call overhead and
    gives bit-identical results.
    """
    p = params
    tmean = 0.5 * (weather.tmax_degc + weather.tmin_degc)
    dtt = thermal_time_increment(tmean, p.base_temperature_degc, xp)
    f_temp = temperature_response(tmean, p.base_temperature_degc, p.optimal_temperature_degc, xp)
    f_heat = heat_response(weather.tmax_degc, p.heat_stress_onset_degc, p.extreme_heat_degc, xp)
    water_input = weather.rain_mm + irrigation_mm
    water = water_balance(state.plant_available_water_mm, water_input, weather.et0_mm, p.runoff_retention_mm,
                          p.available_water_capacity, p.deep_drainage_coefficient, p.root_zone_depth_mm, xp)
    f_water = water_response(water.arid, p.water_stress_sensitivity, xp)
    growth = (KG_HA_PER_G_M2 * p.radiation_use_efficiency * p.co2_factor * state.fsolar * weather.srad_mj_m2
              * f_temp * xp.minimum(f_heat, f_water))
    next_tt = state.thermal_time_degc_d + dtt

    # Maturity day d: the last day with TT <= Tsum, the day fSolar falls to <= 0.005, or the harvest day.
    senesced = ((state.days_since_sowing > 0) & (state.fsolar < state.fsolar_previous)
                & (state.fsolar <= SENESCENCE_FSOLAR))
    matures = xp.logical_not(state.mature) & ((next_tt > p.thermal_time_to_maturity_degc_d) | senesced
                                              | (state.days_since_sowing >= p.harvest_day))
    grows = xp.logical_not(state.mature | matures)

    # The larger of the drought and heat increments (not their sum); both lag one day.
    next_i50b = xp.maximum(xp.maximum(state.i50b_degc_d + p.i50_max_water_degc_d * (1.0 - f_water), 0.0),
                           xp.maximum(state.i50b_degc_d + p.i50_max_heat_degc_d * (1.0 - f_heat), 0.0))
    next_fsolar = (canopy_cover(next_tt, p.i50a_degc_d, p.thermal_time_to_maturity_degc_d, state.i50b_degc_d,
                                p.fsolar_max, xp)
                   * xp.minimum(canopy_water_response(f_water, xp), 1.0))

    growth = xp.where(grows, growth, 0.0)
    dtt = xp.where(grows, dtt, 0.0)
    next_state = CropState(
        days_since_sowing=state.days_since_sowing + 1,
        thermal_time_degc_d=state.thermal_time_degc_d + dtt,
        biomass_kg_ha=state.biomass_kg_ha + growth,
        fsolar=xp.where(grows, next_fsolar, state.fsolar),
        fsolar_previous=xp.where(grows, state.fsolar, state.fsolar_previous),
        i50b_degc_d=xp.where(grows, next_i50b, state.i50b_degc_d),
        plant_available_water_mm=water.plant_available_water_mm,
        mature=state.mature | matures,
        maturity_day=xp.where(matures, state.days_since_sowing, state.maturity_day),
    )
    fluxes = DailyFluxes(
        thermal_time_increment_degc_d=dtt,
        biomass_increment_kg_ha=growth,
        f_temp=f_temp, f_heat=f_heat, f_water=f_water, arid=water.arid, et0_mm=weather.et0_mm,
        water_input_mm=water_input, runoff_mm=water.runoff_mm, drainage_mm=water.drainage_mm,
        transpiration_mm=water.transpiration_mm, matured=matures,
    )
    return next_state, fluxes


class ScalarMath:
    """The few numpy functions :func:`step` uses, for one field held as Python floats and bools.

    ``exp`` goes through numpy so that the scalar and array paths agree to the bit (numpy's vectorised
    exp and libm's can differ in the last place).
    """

    @staticmethod
    def maximum(a, b):
        return a if a >= b else b

    @staticmethod
    def minimum(a, b):
        return a if a <= b else b

    @staticmethod
    def clip(x, low, high):
        return low if x < low else (high if x > high else x)

    @staticmethod
    def where(condition, if_true, if_false):
        return if_true if condition else if_false

    @staticmethod
    def logical_not(x):
        return not x

    @staticmethod
    def exp(x):
        return float(np.exp(x))


SCALAR_MATH = ScalarMath()


def scalar_parameters(params: FieldParameters, field: int = 0) -> FieldParameters:
    """One field of ``params`` as Python floats, for ``step(..., xp=SCALAR_MATH)``."""
    return FieldParameters(**{f.name: float(np.broadcast_to(getattr(params, f.name), (params.n_fields,))[field])
                              for f in fields(FieldParameters)})


def scalar_state(state: CropState, field: int = 0) -> CropState:
    """One field of ``state`` as Python scalars (int, float, bool), for ``step(..., xp=SCALAR_MATH)``."""
    return CropState(*(value[field].item() for value in state))


MAX_IRRIGATION_MM = 1000.0


def check_irrigation(irrigation_mm, limit_mm: float = MAX_IRRIGATION_MM) -> np.ndarray:
    """Irrigation as a float array, or ValueError naming what is wrong (NaN, infinite, negative, too large)."""
    amount = np.asarray(irrigation_mm, dtype=float)
    if not np.all(np.isfinite(amount)):
        raise ValueError(f"irrigation must be a finite number of mm, got {irrigation_mm!r}")
    if np.any(amount < 0):
        raise ValueError(f"irrigation must be >= 0 mm, got {irrigation_mm!r}")
    if np.any(amount > limit_mm):
        raise ValueError(f"irrigation must be <= {limit_mm} mm per day, got {irrigation_mm!r}")
    return amount
