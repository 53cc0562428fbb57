"""The rule family of the task family: a water-budget rule that reasons from SIMPLE's water terms.

:class:`WaterBudgetRule` reads only the family's extended observation (29 values, see
:mod:`crop_sim_ros.task.layout`) and what a farmer knows of the field before the season (:class:`FarmFacts`:
the soil's water capacity, the cultivar's thermal time to maturity). Each day it:

1. **Knows or estimates the soil water** (:class:`SoilWaterFilter` with no sensor error: the rule's
   checkbook). With a PAW reading it uses it; without one (a dropout, or no sensor at all) it keeps a
   checkbook, the irrigation scheduling method of extension services: yesterday's estimate + yesterday's rain
   + yesterday's applied irrigation - the crop's water use, which in SIMPLE's ARID bucket is
   min(ET0, 0.096 x PAW) mm, capped at the root zone's capacity.
2. **Aims at the no-stress level.** SIMPLE's crop transpires min(ET0, 0.096 PAW): it is unstressed while
   PAW >= ET0 / 0.096. The rule refills to ``level_factor x ET0 / 0.096 + margin_mm`` (today's published
   ET0), counting today's rain.
3. **Skips when rain is forecast** above ``skip_rain_mm``.
4. **Irrigates only in the window of thermal time that pays**: from ``start_tt_fraction`` to
   ``stop_tt_fraction`` of the cultivar's TT to maturity. SIMPLE's growth is proportional to the radiation the
   canopy intercepts: stress costs little while the canopy is small (early: the full root zone carries the
   crop) and once it senesces (late), so scarce water is worth most in between.
5. **Budgets a quota**: it spends at most ``pace x remaining / max(days left, 1)`` today, so that an
   allocation lasts the nominal season (``pace`` inf: no budgeting).
6. **Weighs money**: it irrigates only when the yield the water protects is worth more than it costs, a
   test it makes by ``value_ratio``: no irrigation when water cost per mm > ``value_ratio`` x tuber price per t
   (both observed).

All parameters may be arrays of shape (N,) to run N variants of the rule on N fields at once (the tuner's
batched search). The tuned parameters of each task live in ``family_<task>.json`` beside this module,
written by :mod:`crop_agent_ros.policies.family_tuning` from generated training seasons only.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from crop_sim_ros.model.simple import WATER_UPTAKE_COEFFICIENT  # ARID's water uptake coefficient, d-1
from crop_sim_ros.task.layout import EXTENDED

from .base import BasePolicy

_COL = {name: EXTENDED.index(name) for name in EXTENDED.names}


@dataclass(frozen=True)
class FarmFacts:
    """What a farmer knows of the field before the season: the root zone's water capacity (mm) and the
    cultivar's thermal time to maturity (degC d)."""

    capacity_mm: float
    tsum_degc_d: float

    @classmethod
    def of_scenario(cls, scenario) -> "FarmFacts":
        params = scenario.field_parameters()
        return cls(float(params.capacity_mm[0]), float(params.thermal_time_to_maturity_degc_d[0]))


@dataclass(frozen=True)
class RuleParameters:
    """The water-budget rule's parameters (see the module docstring); units in the names."""

    level_factor: float = 1.0
    margin_mm: float = 5.0
    skip_rain_mm: float = 10.0
    start_tt_fraction: float = 0.0
    stop_tt_fraction: float = 1.5
    pace: float = np.inf
    value_ratio: float = np.inf

    @classmethod
    def names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls))


class SoilWaterFilter:
    """An estimate of the plant-available water (mm) of N fields from their daily observations: the checkbook
    (yesterday's estimate + yesterday's rain + yesterday's irrigation - min(yesterday's ET0, 0.096 x water),
    within 0..capacity mm) corrected by each PAW reading, a scalar Kalman filter.

    ``sensor_sd_mm``: the sensor's error (standard deviation, mm). 0 takes a reading as the truth (the rule's
    checkbook: the reading wins, the checkbook carries only dropout days); above 0 a reading corrects the
    checkbook by the gain K = P / (P + sensor_sd_mm^2), where P (mm^2) is the checkbook's error variance,
    0 on the sowing day (SIMPLE starts at the capacity) and growing by ``process_sd_mm``^2 a day (what the
    checkbook misses: runoff, drainage above capacity, the readings' own error). ``update(obs)`` takes each
    day's (N, 29) observations once, in order; a field whose day is 0 starts a new season."""

    # What the checkbook misses in a day: its one-step error against benton-quota's readings (1 mm sensor)
    # over the 100 seasons of the expected-value planner's benton-quota-expected-000-099.npz is 1.4 mm (sd),
    # that reading error included.
    PROCESS_SD_MM = 1.0

    def __init__(self, capacity_mm: float, sensor_sd_mm: float = 0.0, process_sd_mm: float = PROCESS_SD_MM):
        if not (np.isfinite(capacity_mm) and capacity_mm > 0):
            raise ValueError(f"soil water filter: capacity_mm must be > 0, got {capacity_mm}")
        if not (np.isfinite(sensor_sd_mm) and sensor_sd_mm >= 0 and np.isfinite(process_sd_mm) and process_sd_mm > 0):
            raise ValueError(f"soil water filter: need sensor_sd_mm >= 0 and process_sd_mm > 0, got "
                             f"{sensor_sd_mm} and {process_sd_mm}")
        self.capacity_mm = float(capacity_mm)
        self.sensor_sd_mm = float(sensor_sd_mm)
        self.process_sd_mm = float(process_sd_mm)
        self.reset()

    def reset(self) -> None:
        self._estimate_mm: np.ndarray | None = None  # (N,) mm, yesterday's estimate
        self._variance_mm2: np.ndarray | None = None  # (N,) mm^2, its error variance
        self._yesterday: np.ndarray | None = None  # (N, 2): yesterday's rain mm and ET0 mm

    def record(self) -> dict:
        return {"capacity_mm": self.capacity_mm, "sensor_sd_mm": self.sensor_sd_mm,
                "process_sd_mm": self.process_sd_mm}

    def update(self, obs: np.ndarray) -> np.ndarray:
        """Today's estimates (N,) mm, from today's observations (N, 29)."""
        obs = np.atleast_2d(np.asarray(obs, dtype=float))
        day = obs[:, _COL["days_since_sowing"]]
        observed = obs[:, _COL["paw_observed"]] > 0.5
        if self._estimate_mm is None or len(self._estimate_mm) != len(obs):
            self._estimate_mm = np.full(len(obs), self.capacity_mm)
            self._variance_mm2 = np.zeros(len(obs))
            self._yesterday = np.zeros((len(obs), 2))
        rain, et0 = self._yesterday[:, 0], self._yesterday[:, 1]
        water = self._estimate_mm + rain + obs[:, _COL["irrigation_yesterday_mm"]]
        water = water - np.minimum(et0, WATER_UPTAKE_COEFFICIENT * water)
        carried = np.clip(water, 0.0, self.capacity_mm)
        # The sowing day starts full and known (SIMPLE's initial PAW is the capacity).
        fresh = day < 0.5
        estimate = np.where(fresh, self.capacity_mm, carried)
        variance = np.where(fresh, 0.0, self._variance_mm2 + self.process_sd_mm ** 2)
        reading = obs[:, _COL["paw_mm"]]
        if self.sensor_sd_mm == 0.0:
            estimate = np.where(observed, reading, estimate)
            variance = np.where(observed, 0.0, variance)
        else:
            gain = np.where(observed, variance / (variance + self.sensor_sd_mm ** 2), 0.0)
            estimate = estimate + gain * (np.where(observed, reading, estimate) - estimate)
            variance = (1.0 - gain) * variance
        self._estimate_mm, self._variance_mm2 = estimate, variance
        self._yesterday = np.stack([obs[:, _COL["rain_mm"]], obs[:, _COL["et0_mm"]]], axis=1)
        return estimate


class WaterBudgetRule(BasePolicy):
    """The family's rule (see the module docstring). ``parameters``: a :class:`RuleParameters`, or a mapping
    of its fields to values or (N,) arrays."""

    observation_sizes = (EXTENDED.size,)

    def __init__(self, facts: FarmFacts, parameters: RuleParameters | dict | None = None, name: str = "budget-rule"):
        values = parameters.__dict__ if isinstance(parameters, RuleParameters) else dict(parameters or {})
        unknown = set(values) - set(RuleParameters.names())
        if unknown:
            raise ValueError(f"unknown rule parameters {sorted(unknown)}; known: {', '.join(RuleParameters.names())}")
        defaults = RuleParameters()
        self.parameters = {k: np.asarray(values.get(k, getattr(defaults, k)), dtype=float)
                           for k in RuleParameters.names()}
        self.facts = facts
        self.name = name
        self.soil_water = SoilWaterFilter(facts.capacity_mm)

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self.soil_water.reset()

    def _act_batch(self, obs):
        p = self.parameters
        paw = self.soil_water.update(obs)
        et0 = obs[:, _COL["et0_mm"]]
        level = p["level_factor"] * et0 / WATER_UPTAKE_COEFFICIENT + p["margin_mm"]
        amount = np.maximum(level - paw - obs[:, _COL["rain_mm"]], 0.0)
        amount = np.where(obs[:, _COL["forecast_rain_mm"]] > p["skip_rain_mm"], 0.0, amount)
        progress = obs[:, _COL["thermal_time_degc_d"]] / self.facts.tsum_degc_d
        outside = (progress < p["start_tt_fraction"]) | (progress > p["stop_tt_fraction"])
        amount = np.where(outside, 0.0, amount)
        left = obs[:, _COL["quota_remaining_mm"]]
        days_left = np.maximum(obs[:, _COL["season_days_left"]], 1.0)
        budget = np.where(np.isinf(p["pace"]), np.inf, np.where(np.isinf(p["pace"]), 0.0, p["pace"]) * left / days_left)
        amount = np.minimum(amount, budget)
        too_dear = obs[:, _COL["water_cost_usd_per_mm"]] > p["value_ratio"] * obs[:, _COL["tuber_price_usd_per_t"]]
        amount = np.where(too_dear, 0.0, amount)
        return np.minimum(amount, obs[:, _COL["capacity_mm_per_day"]])

    def describe(self):
        return {"name": self.name, **{k: (v.tolist() if v.ndim else float(v)) for k, v in self.parameters.items()}}
