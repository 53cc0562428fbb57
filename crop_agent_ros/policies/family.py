"""The rule family of the task family: a water-budget rule that reasons from SIMPLE's water terms.

:class:`WaterBudgetRule` reads only the family's extended observation (29 values, see
:mod:`crop_sim_ros.task.layout`) and what a farmer knows of the field before the season (:class:`FarmFacts`:
the soil's water capacity, the cultivar's thermal time to maturity). Each day it:

1. **Knows or estimates the soil water.** With a PAW reading it uses it; without one (a dropout, or no
   sensor at all) it keeps a checkbook, the irrigation scheduling method of extension services: yesterday's
   estimate + yesterday's rain + yesterday's applied irrigation - the crop's water use, which in SIMPLE's
   ARID bucket is min(ET0, 0.096 x PAW) mm, capped at the root zone's capacity.
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

from crop_sim_ros.task.layout import EXTENDED

from .base import BasePolicy

UPTAKE_PER_DAY = 0.096  # ARID's water uptake coefficient, d-1 (crop_sim_ros.model.simple)
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
        self._estimate_mm: np.ndarray | None = None

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self._estimate_mm = None

    def _soil_water_mm(self, obs: np.ndarray) -> np.ndarray:
        """The PAW reading where there is one, else the checkbook estimate carried from yesterday."""
        day = obs[:, _COL["days_since_sowing"]]
        observed = obs[:, _COL["paw_observed"]] > 0.5
        if self._estimate_mm is None or len(self._estimate_mm) != len(obs):
            self._estimate_mm = np.full(len(obs), self.facts.capacity_mm)
            self._yesterday = np.zeros((len(obs), 2))  # rain mm, ET0 mm
        previous = self._estimate_mm
        rain, et0 = self._yesterday[:, 0], self._yesterday[:, 1]
        water = previous + rain + obs[:, _COL["irrigation_yesterday_mm"]]
        water = water - np.minimum(et0, UPTAKE_PER_DAY * water)
        carried = np.clip(water, 0.0, self.facts.capacity_mm)
        # The sowing day starts full (SIMPLE's initial PAW is the capacity); a reading always wins.
        estimate = np.where(day < 0.5, self.facts.capacity_mm, carried)
        estimate = np.where(observed, obs[:, _COL["paw_mm"]], estimate)
        self._estimate_mm = estimate
        self._yesterday = np.stack([obs[:, _COL["rain_mm"]], obs[:, _COL["et0_mm"]]], axis=1)
        return estimate

    def _act_batch(self, obs):
        p = self.parameters
        paw = self._soil_water_mm(obs)
        et0 = obs[:, _COL["et0_mm"]]
        level = p["level_factor"] * et0 / UPTAKE_PER_DAY + p["margin_mm"]
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
