"""Reference evapotranspiration ET0, mm d-1, for whole series at once (numpy arrays over days).

- :func:`priestley_taylor`: the DSSAT form SIMPLE was validated with (albedo 0.23); needs TMAX, TMIN, SRAD.
- :func:`penman_monteith`: FAO-56 Penman-Monteith (grass reference, Cn 900, Cd 0.34) through the
  ``refet`` library (ASCE standardized daily form, with FAO-56's simple clear-sky radiation Rso =
  (0.75 + 2e-5 z) Ra); needs vapour pressure, wind at 2 m, latitude, elevation and day of year.
"""

from __future__ import annotations

import numpy as np

ALBEDO = 0.23
# ET0 never reaches zero: ARID divides by it.
MINIMUM_ET0_MM = 1e-4
HPA_PER_KPA = 10.0


def priestley_taylor(tmax_degc, tmin_degc, srad_mj_m2, albedo: float = ALBEDO):
    """DSSAT Priestley-Taylor potential ET, mm d-1 (the form of SIMPLE's reference code)."""
    tmax = np.asarray(tmax_degc, dtype=float)
    daytime_temperature = 0.6 * tmax + 0.4 * np.asarray(tmin_degc, dtype=float)
    equilibrium = (np.asarray(srad_mj_m2, dtype=float) * 23.923 * (2.04e-4 - 1.83e-4 * albedo)
                   * (daytime_temperature + 29.0))
    coefficient = np.where(tmax > 35.0, (tmax - 35.0) * 0.05 + 1.1,
                           np.where(tmax < 5.0, 0.01 * np.exp(0.18 * (tmax + 20.0)), 1.1))
    return np.maximum(equilibrium * coefficient, MINIMUM_ET0_MM)


def penman_monteith(tmax_degc, tmin_degc, srad_mj_m2, vap_hpa, wind_m_s, day_of_year,
                    latitude_deg: float, elevation_m: float, wind_height_m: float = 2.0):
    """FAO-56 Penman-Monteith grass reference ET0, mm d-1 (through ``refet``).

    vap_hpa: actual vapour pressure, hPa; wind_m_s: wind speed at ``wind_height_m`` (default 2 m), m s-1.
    """
    import refet  # numpy-only; imported here so the Priestley-Taylor path needs nothing more

    et0 = refet.Daily(
        tmin=np.asarray(tmin_degc, dtype=float), tmax=np.asarray(tmax_degc, dtype=float),
        rs=np.asarray(srad_mj_m2, dtype=float), uz=np.asarray(wind_m_s, dtype=float), zw=wind_height_m,
        elev=elevation_m, lat=latitude_deg, doy=np.asarray(day_of_year, dtype=float),
        ea=np.asarray(vap_hpa, dtype=float) / HPA_PER_KPA, method="asce", rso_type="simple",
    ).eto()
    return np.maximum(np.asarray(et0, dtype=float), MINIMUM_ET0_MM)


def saturation_vapour_pressure_hpa(temperature_degc):
    """FAO-56 eq. 11, in hPa: e0(T) = 6.108 exp(17.27 T / (T + 237.3))."""
    t = np.asarray(temperature_degc, dtype=float)
    return 6.108 * np.exp(17.27 * t / (t + 237.3))


ET0_METHODS = ("priestley_taylor", "penman_monteith")
