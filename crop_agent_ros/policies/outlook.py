"""The climate outlook a family agent may read (a research feature: an agent whose model.json names an
``outlook``, trained by an earlier version's ``--outlook``): how the water left compares with the demand the
site's climate normally brings over the next two months, and whether that demand is rising.

A farm's controller knows its site's climate (its normals: weather networks and FAO-56 scheduling publish
them); the observation does not carry it. The planner the students imitate knows it (its continuations are
seasons of the field's own climate), and on a climate no training season comes from (Maricopa, AZ) a planner
given another climate's statistics does worse than the rule (README, `climates3-quota`). Two numbers carry
the part of that knowledge a quota decision needs, in units that mean the same in every climate:

===================== ====== ===============================================================================
Name                  Unit   Value (field sown on day of year s, on day t of its season, Q mm of quota left)
===================== ====== ===============================================================================
water_vs_demand       1      ln(max(Q, 1) / E60), E60 the normal ET0 of days s+t .. s+t+59 (mm)
demand_trend          1      2 ln(E60 / (60 x the mean normal ET0 of days s+t-14 .. s+t-1))
===================== ====== ===============================================================================

Normals: each climate's mean daily ET0 (FAO-56 Penman-Monteith, mm) by day of the year over
:data:`NORMAL_YEARS` years drawn by its weather generator with seed :data:`NORMALS_SEED` (no training,
validation, evaluation or continuation pool uses it). A climate is a fitted generator, as fitted or with its
temperature, humidity or rain delta-changed (``benton``, ``benton+4C``, ``benton+6C+8DPDx0.3R``: the name its
seasons' source carries; :func:`crop_sim_ros.weather.generator.climate_parameters`). A generated season's
climate is read from its source; a real season's (held-out Benton, Maricopa) is its site's generator, as its
scenario names it (``weather.climate``; for Maricopa's three real seasons, a generator whose fit includes those
years: that set's outlook is not independent of it; the 50 generated Maricopa seasons are).
"""

from __future__ import annotations

import datetime
import functools
import re

import numpy as np

from crop_sim_ros.task.layout import EXTENDED

NORMALS_SEED = 31_337
NORMAL_YEARS = 60
AHEAD_DAYS = 60
BEHIND_DAYS = 14
FEATURES = ("water_vs_demand", "demand_trend")
_DAY = EXTENDED.index("days_since_sowing")
_QUOTA = EXTENDED.index("quota_remaining_mm")


def normal_et0_mm(climate: str) -> np.ndarray:
    """(365,) mean daily ET0 (mm) by day of the year (0 = January 1) of ``climate`` (``<generator>``, warmed, dried
    and its rain scaled as in ``benton+6C+8DPDx0.3R``); ValueError naming the fitted generators for an unknown one.
    A rain factor leaves them as they are (the same wet days, so the same temperatures, radiation, humidity and
    wind), so a climate's normals are computed once for every rain factor: a spread pool names thousands of
    climates."""
    from crop_sim_ros.weather.generator import WeatherError, climate_parameters
    try:
        params = climate_parameters(climate)
    except WeatherError as error:
        raise ValueError(f"climate outlook: {error}") from None
    return _normal_et0_mm(re.sub(r"x[0-9.]+R$", "", params.name))


@functools.lru_cache(maxsize=None)
def _normal_et0_mm(climate: str) -> np.ndarray:
    """:func:`normal_et0_mm` of a climate without a rain factor."""
    from crop_sim_ros.weather.generator import climate_parameters, generate_seasons
    years = generate_seasons(climate_parameters(climate), datetime.date(2001, 1, 1), 730, NORMAL_YEARS, NORMALS_SEED)
    et0 = np.stack([series.et0_mm("penman_monteith") for series in years])
    normals = et0.reshape(NORMAL_YEARS, 2, 365).mean(axis=(0, 1))
    normals.setflags(write=False)
    return normals


def climate_of_source(source: str) -> str | None:
    """The climate of a generated season (its source names the generator's parameters), else None."""
    from crop_sim_ros.weather.generator import generator_of_source
    return generator_of_source(source)


def season_climate(source: str, fallback: str | None, season: str) -> str:
    """The climate of a season whose weather came from ``source``: the generator that made it, else
    ``fallback`` (the site's climate of a real season); ValueError naming ``season`` if neither."""
    climate = climate_of_source(source) or fallback
    if climate is None:
        raise ValueError(f"climate outlook: season {season} ({source}) was not generated and no site climate was "
                         "given for it")
    return climate


def scenario_climate(scenario) -> str:
    """The climate of a generated-weather scenario (its generator, delta-changed as it says)."""
    return scenario.weather.generated_climate


def pool_climates(task) -> list[tuple[str, int]]:
    """(climate, sowing day of year) of every season of ``task``'s training pool, in pool order (each generated
    part's ``n_seasons`` in turn; a spread part's seasons each their own, as their sources name them)."""
    from crop_sim_ros.task.core import scenario_table
    from crop_sim_ros.task.scenario import generated_parts
    pool = []
    for part in generated_parts(task):
        if part.weather.spread is None:
            pool += [(scenario_climate(part), day_of_year(part.sowing_date))] * part.weather.n_seasons
        else:
            table = scenario_table(part)
            pool += [(climate_of_source(source), day_of_year(str(sown)))
                     for source, sown in zip(table.sources, table.sowing_dates)]
    return pool


def day_of_year(day: datetime.date | str) -> int:
    """0-based day of the year (a leap year's December 31 folds onto day 364)."""
    date = day if isinstance(day, datetime.date) else datetime.date.fromisoformat(str(day))
    return min(date.timetuple().tm_yday - 1, 364)


def _by_climate(climates, sowing_days, obs: np.ndarray):
    """(observations as an (N, 29) float array, and for each climate among the fields: the fields' mask, the
    climate's normals, and those fields' day of the year today)."""
    obs = np.atleast_2d(np.asarray(obs, dtype=float))
    today = np.asarray(sowing_days, dtype=int) + obs[:, _DAY].astype(int)
    climates = np.asarray(climates, dtype=object)
    return obs, [(climates == climate, normal_et0_mm(str(climate)), today[climates == climate])
                 for climate in np.unique(climates)]


def features(climates, sowing_days, obs: np.ndarray) -> np.ndarray:
    """(N, 2) :data:`FEATURES` of N fields: their climates and sowing days of the year, today's observations
    (days since sowing, quota left)."""
    obs, groups = _by_climate(climates, sowing_days, obs)
    quota = np.maximum(obs[:, _QUOTA], 1.0)
    out = np.empty((len(obs), 2))
    for mine, normals, days in groups:
        ahead = normals[(days[:, None] + np.arange(AHEAD_DAYS)) % 365].sum(axis=1)
        behind = normals[(days[:, None] - BEHIND_DAYS + np.arange(BEHIND_DAYS)) % 365].mean(axis=1)
        out[mine, 0] = np.log(quota[mine] / ahead)
        out[mine, 1] = 2.0 * np.log(ahead / (AHEAD_DAYS * behind))
    return out.astype(np.float32)


class ClimateOutlook:
    """Each field's climate and sowing day for the season it is in, and its :func:`features`. Fields are set by
    :meth:`set_fields` (the training environment, from its seasons) or :meth:`begin_season` (a policy run, from
    the seasons' contexts; a season whose weather no generator made takes ``fallback``, its site's climate)."""

    size = len(FEATURES)

    def __init__(self):
        self.climates: list[str] | None = None
        self.sowing_days: np.ndarray | None = None

    def record(self) -> dict:
        return {"features": list(FEATURES), "normals_seed": NORMALS_SEED, "normal_years": NORMAL_YEARS}

    def set_fields(self, climates, sowing_days) -> None:
        for climate in set(climates):
            normal_et0_mm(climate)  # an unknown climate is refused here, before any step
        self.climates, self.sowing_days = list(climates), np.asarray(sowing_days, dtype=int)

    def begin_season(self, contexts, fallback: str | None = None) -> None:
        self.set_fields([season_climate(str(c.extra.get("source", "")), fallback, c.name) for c in contexts],
                        [day_of_year(c.extra["sowing_date"]) for c in contexts])

    def _checked(self, obs: np.ndarray) -> np.ndarray:
        """``obs`` as (N, 29), or ValueError if this outlook was not told the climates of N fields."""
        obs = np.atleast_2d(obs)
        if self.climates is None or len(self.climates) != len(obs):
            told = "was not" if self.climates is None else f"was told {len(self.climates)} fields, not {len(obs)}"
            raise ValueError("climate outlook: this agent reads its fields' climate; it is told it before the "
                             f"season (a policy run's begin_season, or the training environment), and {told}")
        return obs

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """The fields' :func:`features` today."""
        return features(self.climates, self.sowing_days, self._checked(obs))


class ReadsOutlook:
    """A policy that may read a :class:`ClimateOutlook` (``self.outlook``, None: it does not): told its fields'
    climates before each season. ``site_climate`` is the climate of seasons no generator made (the evaluation
    sets it from a real set's scenario; the agent node from its ``climate`` parameter or the reset's)."""

    outlook: ClimateOutlook | None = None
    site_climate: str | None = None

    def begin_season(self, contexts) -> None:
        if self.outlook is not None:
            self.outlook.begin_season(contexts, self.site_climate)

    def begin_field_season(self, weather_source: str, sowing_date: datetime.date | str) -> None:
        """One field's season (a simulator's reset: its weather source and sowing date)."""
        if self.outlook is not None:
            self.outlook.set_fields([season_climate(weather_source, self.site_climate, str(sowing_date))],
                                    [day_of_year(sowing_date)])
