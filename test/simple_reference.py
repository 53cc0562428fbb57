"""A second, independent formulation of SIMPLE for the tests to compare the model, the task and the
environments with.

Written from ``shared/spec/SIMPLE_MODEL.md`` alone: plain Python floats, one field, one day at a time, the
equations spelled out as the spec states them, and the parameters typed from the spec (Russet Burbank
potato on the Benton County soil). It imports nothing from crop_sim_ros, so an error there cannot hide
in an expected value computed here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

# Zhao et al. (2019) Table 1a/1b as quoted in SIMPLE_MODEL.md: Russet Burbank potato, Benton County soil.
RUSSET_BURBANK_ON_BENTON = {
    "tbase": 4.0, "topt": 22.0, "rue": 1.30, "i50max_heat": 50.0, "i50max_water": 30.0, "theat": 34.0,
    "textreme": 45.0, "s_co2": 0.10, "s_water": 0.4,                        # species
    "tsum": 2300.0, "hi": 0.90, "i50a": 500.0, "i50b": 400.0,               # cultivar
    "awc": 0.10, "rcn": 64.0, "ddc": 0.8, "rzd": 1200.0,                    # soil
}


def bucket_day(paw_mm: float, water_input_mm: float, et0_mm: float, awc: float, rcn: float, ddc: float,
               rzd: float) -> tuple[float, float, float, float, float]:
    """One day of the Woli et al. (2012) bucket as the spec writes it:
    (runoff mm, drainage mm, transpiration mm, PAW at the day's end mm, ARID)."""
    s = 25400.0 / rcn - 254.0
    p = water_input_mm
    runoff = (p - 0.2 * s) ** 2 / (p + 0.8 * s) if p > 0.2 * s else 0.0
    w1 = paw_mm + p - runoff
    drainage = rzd * ddc * (w1 / rzd - awc) if w1 / rzd > awc else 0.0
    w2 = w1 - drainage
    transpiration = min(0.096 * w2, et0_mm)
    return runoff, drainage, transpiration, w2 - transpiration, 1.0 - transpiration / et0_mm


@dataclass
class ReferenceSeason:
    """State lists hold the value at the start of each day 0..D-1 (and index D: after the last day); flux
    lists hold each day's value. ``maturity_day`` is None if the crop never matured; ``yield_kg_ha`` is the
    yield at maturity (kg/ha), None then."""

    thermal_time_degc_d: list = field(default_factory=list)
    biomass_kg_ha: list = field(default_factory=list)
    fsolar: list = field(default_factory=list)
    paw_mm: list = field(default_factory=list)
    runoff_mm: list = field(default_factory=list)
    drainage_mm: list = field(default_factory=list)
    transpiration_mm: list = field(default_factory=list)
    arid: list = field(default_factory=list)
    maturity_day: int | None = None
    yield_kg_ha: float | None = None


def reference_season(tmax, tmin, srad, rain, et0, irrigation, co2_ppm: float = 369.0, water_stress: bool = True,
                     harvest_day: int | None = None, fsolar_max: float = 0.95, initial_paw_mm: float | None = None,
                     **overrides) -> ReferenceSeason:
    """Grow one field over the given days (sequences of floats; units as in the spec) by the spec's daily
    equations 1-11 and its water balance. ``overrides`` replace entries of RUSSET_BURBANK_ON_BENTON."""
    p = {**RUSSET_BURBANK_ON_BENTON, **overrides}
    if co2_ppm < 350:
        f_co2 = 1.0
    elif co2_ppm < 700:
        f_co2 = 1.0 + p["s_co2"] * (co2_ppm - 350.0) / 100.0
    else:
        f_co2 = 1.0 + p["s_co2"] * 3.5
    s_water = p["s_water"] if water_stress else 0.0
    tt, biomass, fsolar, fsolar_before, i50b = 0.0, 1.0, 0.001, None, p["i50b"]
    paw = p["awc"] * p["rzd"] if initial_paw_mm is None else initial_paw_mm
    out = ReferenceSeason()
    for d in range(len(tmax)):
        out.thermal_time_degc_d.append(tt)
        out.biomass_kg_ha.append(biomass)
        out.fsolar.append(fsolar)
        out.paw_mm.append(paw)
        tmean = (tmax[d] + tmin[d]) / 2.0
        dtt = max(tmean - p["tbase"], 0.0)
        if tmean < p["tbase"]:
            f_temp = 0.0
        elif tmean < p["topt"]:
            f_temp = (tmean - p["tbase"]) / (p["topt"] - p["tbase"])
        else:
            f_temp = 1.0
        if tmax[d] <= p["theat"]:
            f_heat = 1.0
        elif tmax[d] > p["textreme"]:
            f_heat = 0.0
        else:
            f_heat = 1.0 - (tmax[d] - p["theat"]) / (p["textreme"] - p["theat"])
        runoff, drainage, transpiration, paw, arid = bucket_day(
            paw, rain[d] + irrigation[d], et0[d], p["awc"], p["rcn"], p["ddc"], p["rzd"])
        out.runoff_mm.append(runoff)
        out.drainage_mm.append(drainage)
        out.transpiration_mm.append(transpiration)
        out.arid.append(arid)
        f_water = max(0.0, 1.0 - s_water * arid)
        if out.maturity_day is None:
            # 11. the last day with TT <= Tsum; the day fSolar falls to <= 0.005; the harvest day.
            senesced = d > 0 and fsolar < fsolar_before and fsolar <= 0.005
            if tt + dtt > p["tsum"] or senesced or (harvest_day is not None and d >= harvest_day):
                out.maturity_day = d
                out.yield_kg_ha = biomass * p["hi"]
        if out.maturity_day is None:  # the crop grows; from maturity on it stays as it is
            growth = 10.0 * p["rue"] * fsolar * srad[d] * f_co2 * f_temp * min(f_heat, f_water)
            canopy_water = 1.0 if f_water > 0.1 else 0.9 + f_water
            tt += dtt
            biomass += growth
            grow = min(1.0, fsolar_max / (1.0 + math.exp(-0.01 * (tt - p["i50a"]))))
            senesce = min(1.0, fsolar_max / (1.0 + math.exp(0.01 * (tt - (p["tsum"] - i50b)))))
            fsolar_before, fsolar = fsolar, min(grow, senesce) * min(canopy_water, 1.0)
            i50b = max(max(0.0, i50b + p["i50max_water"] * (1.0 - f_water)),
                       max(0.0, i50b + p["i50max_heat"] * (1.0 - f_heat)))
    out.thermal_time_degc_d.append(tt)
    out.biomass_kg_ha.append(biomass)
    out.fsolar.append(fsolar)
    out.paw_mm.append(paw)
    return out


def reference_of_table_season(table, weather_names, k: int, irrigation_mm: float, **keywords) -> ReferenceSeason:
    """Season ``k`` of a task's season table (duck-typed: its ``weather`` laid out by ``weather_names``,
    ``et0_mm`` and ``n_days``) grown by :func:`reference_season` with constant irrigation, mm/day."""
    n = int(table.n_days[k])
    weather = [table.weather[k, :n, list(weather_names).index(name)].tolist()
               for name in ("tmax_degc", "tmin_degc", "srad_mj_m2", "rain_mm")]
    return reference_season(*weather, table.et0_mm[k, :n].tolist(), [irrigation_mm] * n, **keywords)
