"""What each field's season still holds: its weather from today on, known only in hindsight.

A learner may use these values to *judge* its decisions while it trains, never to make them: an asymmetric
critic (Pinto et al. 2018, "Asymmetric Actor Critic for Image-Based Robot Learning") whose value of a day is
conditioned on the weather the season will bring can tell what the agent's choices cost from what the weather
did, which a critic that sees only the observation cannot (``crop-sim train --task T --critic-hindsight``).
Nothing here is an observation: no policy, rule or evaluation reads it.

Values (one row per field, for its season from day ``d`` (today) on; mm, MJ m-2 and degC as named):

============================== =========== ============================================================
Name                           Unit        Value
============================== =========== ============================================================
potential_yield_t_ha           t ha-1      the season's yield with no water stress (SeasonTable)
rain_next_{7,21,63}_d_mm       mm          rain of days d .. d + n - 1 (days past the weather: none)
et0_next_{7,21,63}_d_mm        mm          reference evapotranspiration of the same days
srad_next_{7,21,63}_d_mj_m2    MJ m-2      solar radiation of the same days
mean_tmax_next_21_d_degc       degC        mean TMAX of days d .. d + 20 still in the weather (the last
                                           day's if none)
============================== =========== ============================================================
"""

from __future__ import annotations

import numpy as np

from .core import SeasonTable

WINDOWS_D = (7, 21, 63)
TMAX_WINDOW_D = 21
# SeasonTable.model_weather rows (the DailyWeather fields in order: TMAX, TMIN, SRAD, rain, ET0)
_TMAX, _SRAD, _RAIN, _ET0 = 0, 2, 3, 4
HINDSIGHT_NAMES = ("potential_yield_t_ha",
                   *(f"{variable}_next_{n}_d_{unit}" for variable, unit in (("rain", "mm"), ("et0", "mm"),
                                                                             ("srad", "mj_m2"))
                     for n in WINDOWS_D),
                   f"mean_tmax_next_{TMAX_WINDOW_D}_d_degc")


class SeasonHindsight:
    """The :data:`HINDSIGHT_NAMES` values of any (season, day) of a :class:`SeasonTable`, from running sums
    over each season's days of weather (padding excluded) made once."""

    def __init__(self, table: SeasonTable):
        weather = table.model_weather[:, :, :-2]  # (5, M, D): the padding's two days are not weather
        in_weather = np.arange(weather.shape[2])[None, :] < table.n_days[:, None]
        used = np.where(in_weather[None], weather, 0.0)
        # running[v, m, d] = sum of variable v over days 0 .. d - 1 of season m
        self._running = np.concatenate([np.zeros(used.shape[:2] + (1,)), np.cumsum(used, axis=2)], axis=2)
        self._n_days = np.asarray(table.n_days, dtype=np.int64)
        self._potential = np.asarray(table.potential_yield_t_ha, dtype=float)
        self._last_tmax = table.model_weather[_TMAX, np.arange(len(self._n_days)), self._n_days - 1]

    def _window(self, variable: int, season: np.ndarray, day: np.ndarray, days: int) -> np.ndarray:
        """Sum of ``variable`` over days ``day`` .. ``day + days - 1`` of each season that are in its weather;
        also how many such days there are."""
        start = np.minimum(day, self._n_days[season])
        end = np.minimum(day + days, self._n_days[season])
        running = self._running[variable]
        return running[season, end] - running[season, start], end - start

    def values(self, season, day) -> np.ndarray:
        """(N, len(HINDSIGHT_NAMES)) float64 for fields in seasons ``season`` (N,) on days ``day`` (N,)."""
        season = np.asarray(season, dtype=np.int64).reshape(-1)
        day = np.asarray(day, dtype=np.int64).reshape(-1)
        columns = [self._potential[season]]
        for variable in (_RAIN, _ET0, _SRAD):
            columns += [self._window(variable, season, day, n)[0] for n in WINDOWS_D]
        tmax_sum, tmax_days = self._window(_TMAX, season, day, TMAX_WINDOW_D)
        columns.append(np.where(tmax_days > 0, tmax_sum / np.maximum(tmax_days, 1), self._last_tmax[season]))
        return np.stack(columns, axis=1)
