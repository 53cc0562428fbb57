"""A paced water rule for the task family: spends a binding quota by the demand still ahead (issue 33, point 1).

:class:`PacedRule` reads only the family's 29-value observation (:mod:`crop_sim_ros.task.layout`), the published
SIMPLE parameters of the crop and soil (:mod:`crop_sim_ros.model.parameters`, as :class:`PacedFacts`) and the
soil-water sensor's published error (the scenario's ``noise.paw_mm``). Each day it:

1. **Estimates the soil water** with :class:`~crop_agent_ros.policies.family.SoilWaterFilter` at the sensor's
   published error (a noisy reading is weighed against the checkbook; a dropout day runs on the checkbook).
2. **Counts the stress it let happen** (SIMPLE's I50B): from yesterday's estimated water, rain, irrigation,
   ET0 and TMAX it adds ``senescence_weight`` x max(I50maxW (1 - f_water), I50maxH (1 - f_heat)) to its own
   estimate of I50B, so that stress brings the end of the canopy forward as it does in the model.
3. **Places a window of thermal time around the full canopy**: from I50A + ``start_offset_degc_d`` to
   Tsum - I50B(estimate) + ``stop_offset_degc_d``. The start moves later by ``narrow_degc_d`` x (1 - tightness)
   and the stop earlier by ``narrow_stop_degc_d`` x (1 - tightness), tightness = min(1, supply / demand over the wide window): a tight quota is spent where a mm buys most growth.
4. **Paces the quota by the demand still ahead**: demand = the net ET rate x the thermal time left in the
   window; supply = quota left + the estimated soil water; ratio = supply / demand. The rate (mm per degC d) is
   the larger of two estimates, each sum(ET0 - rain) / sum(dTT) (net ET at least a quarter of ET0) shrunk
   towards ``rate_prior_mm_per_degc_d`` as if ``prior_weight_degc_d`` degC d of it had been seen: over the
   season so far, and over recent days (each day weighed by exp(-(TT now - TT then) / ``memory_degc_d``)).
   Why the larger: a rate that rises through the season (a cool start, e.g. Maricopa sown in January: net ET
   about 0.2 mm per degC d in the first 300 degC d, 0.35-0.44 after; Benton 0.27-0.33 throughout) is what the
   demand ahead follows, and too low a rate spends a tight quota early; why a prior: in the first weeks the few
   days seen say little.
5. **Reserves water for the late canopy**: after the window (until maturity) the crop still grows in
   proportion to its canopy cover, and late stress brings harvest forward. The rule aims there at
   ``late_factor`` x the estimated canopy cover x ET0 / 0.096 (cover from SIMPLE's senescence curve at the
   estimated I50B, 1 / (1 + exp(0.01 (TT - (Tsum - I50B))))), and counts that water in the demand ahead
   (``late_factor`` x rate x the integral of the cover over the late thermal time still ahead), so that the
   quota is paced to leave it.
6. **Aims at a level**: in the window ``level_factor`` x min(1, ``pace`` x ratio) x ET0 / 0.096 + ``margin_mm``
   + min(1, ``pace`` x ratio) x the bank (SIMPLE's crop is unstressed while PAW >= ET0 / 0.096). The bank is
   water stored ahead of days the pump cannot keep up with: ``bank_days`` x max(0, recent ET0 -
   ``bank_threshold`` x the pump's capacity), recent ET0 the mean of the recent days (weighed as the recent
   rate of point 4). Storing costs nothing while it is used (SIMPLE's crop transpires at most ET0 however wet
   the soil); where ET0 nears a pivot's 8 mm/d (Maricopa's late season, 8-9 mm/d) the soil must carry the
   difference. The window's level is multiplied by 1 - ``rise_weight`` x (1 - the rising cover), the rising
   cover SIMPLE's 1 / (1 + exp(-0.01 (TT - I50A))): growth is intercepted radiation, so before the canopy
   closes a mm buys little growth, in any climate (the late reserve follows the senescing cover likewise).
   Before the window ``early_factor`` x ET0 / 0.096;
   after it the late level of point 5 (x min(1, ``pace`` x ratio)). On a heat day (f_heat < 1 from today's
   TMAX) growth is already limited to f_heat, and water
   stress down to f_water = f_heat costs neither growth nor canopy life: the level falls by ``heat_weight`` x
   that free share.
7. **Skips forecast rain**: nothing when tomorrow's forecast rain exceeds ``skip_rain_mm``; today's rain counts.

It irrigates the level minus the estimated water and today's rain, within the pump's capacity and the quota left.

Parameters (all may be (N,) arrays: N variants on N fields at once, the tuner's batched search):

===================== ========== ==================================================================
Name                  Unit       Description
===================== ========== ==================================================================
level_factor          1          share of the no-stress level ET0 / 0.096 aimed at in the window
margin_mm             mm         added to the level in the window
early_factor          1          share of the no-stress level kept before the window
start_offset_degc_d   degC d     window start after I50A (TT of half canopy)
stop_offset_degc_d    degC d     window stop after Tsum - I50B (TT of half senescence)
narrow_degc_d         degC d     how far the start moves later when the quota covers none of the demand
narrow_stop_degc_d    degC d     how far the stop moves earlier when the quota covers none of the demand
pace                  1          supply / demand ratio multiplier (large: the quota is not paced)
late_factor           1          share of the no-stress level x canopy cover kept after the window (0: none)
heat_weight           1          share of a heat day's free water stress taken (0: none, 1: all)
senescence_weight     1          weight of the estimated I50B increments (0: stress ignored)
skip_rain_mm          mm         no irrigation when tomorrow's forecast rain exceeds it
rate_prior_mm_per_    mm/degC d  net ET rate assumed before the season says otherwise (point 4)
degc_d
prior_weight_degc_d   degC d     the thermal time of evidence the prior counts as (0: no prior)
memory_degc_d         degC d     thermal time over which past days' weight in the recent rate falls by e
bank_days             d          days of the pump's shortfall stored in the soil (point 6; 0: none)
bank_threshold        1          share of the pump's capacity above which recent ET0 counts as shortfall
rise_weight           1          how far the window's level follows the rising canopy (point 6; 0: not at
                                 all, as in files tuned before it existed, which may leave it out)
===================== ========== ==================================================================

The tuned parameters of each task live in ``family_<task>-paced.json`` beside this module, written by
``crop-sim tune-rule --task TASK --rule paced-rule`` (:mod:`crop_agent_ros.policies.family_tuning`) from
generated training seasons only; the shipped benton-quota, benton-sensing, climates-quota and climates12-quota
files with ``--candidates 512 --rounds 10`` (the default 128 x 4 search stops well short of the best it finds),
all but climates-quota's with ``--space canopy`` (:data:`~crop_agent_ros.policies.family_tuning.PACED_SPACES`).
The rule is tuned on its task's training climates only: on a held-out climate (Maricopa for the Benton tasks) its
parameters are a transfer test.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

import numpy as np

from crop_sim_ros.model.simple import WATER_UPTAKE_COEFFICIENT, heat_response, water_response
from crop_sim_ros.task.layout import EXTENDED

from .base import BasePolicy
from .family import SoilWaterFilter

_COL = {name: EXTENDED.index(name) for name in EXTENDED.names}
# The smallest thermal time (degC d) the net-ET rate is estimated over (the first days say little).
MIN_RATE_TT_DEGC_D = 60.0


def _cover_integral(tt, senescence_tt):
    """An antiderivative in TT of SIMPLE's senescence cover 1 / (1 + exp(0.01 (TT - senescence_tt))) (degC d)."""
    z = 0.01 * (np.asarray(tt, dtype=float) - senescence_tt)
    return tt - 100.0 * np.logaddexp(0.0, z)


@dataclass(frozen=True)
class PacedFacts:
    """What the rule knows before the season: SIMPLE's published crop and soil parameters and the sensor's
    published error (sd, mm). Units as in :mod:`crop_sim_ros.model.parameters`."""

    capacity_mm: float
    tsum_degc_d: float
    i50a_degc_d: float
    i50b_degc_d: float
    i50_max_water_degc_d: float
    i50_max_heat_degc_d: float
    heat_stress_onset_degc: float
    extreme_heat_degc: float
    water_stress_sensitivity: float
    sensor_sd_mm: float

    def __post_init__(self) -> None:
        for item in fields(self):
            value = getattr(self, item.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
                raise ValueError(f"paced rule facts: {item.name} must be a finite number, got {value!r}")
            object.__setattr__(self, item.name, float(value))
        if self.capacity_mm <= 0 or self.tsum_degc_d <= 0 or self.sensor_sd_mm < 0:
            raise ValueError("paced rule facts: need capacity_mm > 0, tsum_degc_d > 0 and sensor_sd_mm >= 0")
        if self.extreme_heat_degc <= self.heat_stress_onset_degc:
            raise ValueError("paced rule facts: extreme_heat_degc must exceed heat_stress_onset_degc")

    @classmethod
    def of_scenario(cls, scenario) -> "PacedFacts":
        p = scenario.field_parameters()
        return cls(float(p.capacity_mm[0]), float(p.thermal_time_to_maturity_degc_d[0]), float(p.i50a_degc_d[0]),
                   float(p.i50b_degc_d[0]), float(p.i50_max_water_degc_d[0]), float(p.i50_max_heat_degc_d[0]),
                   float(p.heat_stress_onset_degc[0]), float(p.extreme_heat_degc[0]),
                   float(p.water_stress_sensitivity[0]), float(scenario.noise.paw_mm))

    @classmethod
    def from_record(cls, record: dict) -> "PacedFacts":
        if not isinstance(record, dict):
            raise ValueError(f"paced rule facts: expected a mapping, got {type(record).__name__}")
        names = {f.name for f in fields(cls)}
        if set(record) != names:
            raise ValueError(f"paced rule facts: expected fields {', '.join(sorted(names))}; got "
                             f"{', '.join(sorted(map(str, record)))}")
        return cls(**record)

    def record(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class PacedParameters:
    """The paced rule's parameters (see the module table); the defaults are a sensible untuned rule."""

    level_factor: float = 1.0
    margin_mm: float = 5.0
    early_factor: float = 0.5
    start_offset_degc_d: float = 0.0
    stop_offset_degc_d: float = 100.0
    narrow_degc_d: float = 200.0
    narrow_stop_degc_d: float = 200.0
    pace: float = 1.0
    late_factor: float = 0.0
    heat_weight: float = 1.0
    senescence_weight: float = 1.0
    skip_rain_mm: float = 10.0
    rate_prior_mm_per_degc_d: float = 0.3
    prior_weight_degc_d: float = 100.0
    memory_degc_d: float = 400.0
    bank_days: float = 0.0
    bank_threshold: float = 0.6
    rise_weight: float = 0.0

    @classmethod
    def names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls))

    @classmethod
    def later(cls) -> tuple[str, ...]:
        """Parameters added after files were tuned without them: a file may leave them out (their defaults
        reproduce the rule those files were tuned with)."""
        return ("rise_weight",)


class PacedRule(BasePolicy):
    """The paced rule (see the module docstring). ``parameters``: a :class:`PacedParameters`, or a mapping of
    its fields to values or (N,) arrays (missing fields take the defaults)."""

    observation_sizes = (EXTENDED.size,)

    def __init__(self, facts: PacedFacts, parameters: PacedParameters | dict | None = None,
                 name: str = "paced-rule"):
        values = asdict(parameters) if isinstance(parameters, PacedParameters) else dict(parameters or {})
        unknown = set(values) - set(PacedParameters.names())
        if unknown:
            raise ValueError(f"unknown paced rule parameters {sorted(map(str, unknown))}; known: "
                             f"{', '.join(PacedParameters.names())}")
        defaults = PacedParameters()
        self.parameters = {}
        for key in PacedParameters.names():
            value = np.asarray(values.get(key, getattr(defaults, key)), dtype=float)
            if value.ndim > 1 or np.isnan(value).any():
                raise ValueError(f"paced rule parameter {key}: expected a number or an (N,) array, got {value!r}")
            self.parameters[key] = value
        self.facts = facts
        self.name = name
        self.soil_water = SoilWaterFilter(facts.capacity_mm, facts.sensor_sd_mm)
        self.reset()

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self.soil_water.reset()
        self._memory = None  # per field: I50B estimate, fading sums of ET0, rain and dTT, yesterday's values

    def _start(self, n: int) -> dict:
        # The sums of ET0, rain, dTT and days: row 0 over the season so far, row 1 fading (recent days).
        return {"i50b": np.full(n, self.facts.i50b_degc_d), "et0_sum": np.zeros((2, n)), "rain_sum": np.zeros((2, n)),
                "paw": np.full(n, self.facts.capacity_mm), "rain": np.zeros(n), "et0": np.ones(n),
                "tmax": np.zeros(n), "tt_sum": np.zeros((2, n)), "tt": np.zeros(n),
                "day_sum": np.zeros((2, n))}

    def _remember(self, obs: np.ndarray) -> dict:
        """Update the per-field memory with yesterday's outcome (from today's observation) and return it."""
        n = len(obs)
        fresh = obs[:, _COL["days_since_sowing"]] < 0.5
        if self._memory is None or len(self._memory["i50b"]) != n:
            self._memory = self._start(n)
        m = self._memory
        start = self._start(n)
        f = self.facts
        # Yesterday's water stress and heat, as SIMPLE counts them in I50B (one day late).
        water = np.clip(m["paw"] + m["rain"] + obs[:, _COL["irrigation_yesterday_mm"]], 0.0, f.capacity_mm)
        et0 = np.maximum(m["et0"], 1e-6)
        arid = 1.0 - np.minimum(WATER_UPTAKE_COEFFICIENT * water, et0) / et0
        f_water = water_response(arid, f.water_stress_sensitivity)
        f_heat = heat_response(m["tmax"], f.heat_stress_onset_degc, f.extreme_heat_degc)
        step = np.maximum(f.i50_max_water_degc_d * (1.0 - f_water), f.i50_max_heat_degc_d * (1.0 - f_heat))
        m["i50b"] = m["i50b"] + self.parameters["senescence_weight"] * step
        # Row 1 fades with thermal time (``memory_degc_d``: how far back the recent rate looks).
        tt = obs[:, _COL["thermal_time_degc_d"]]
        fade = np.stack([np.ones(n), np.exp(-np.maximum(tt - m["tt"], 0.0) / self.parameters["memory_degc_d"])])
        m["et0_sum"] = fade * m["et0_sum"] + m["et0"]
        m["rain_sum"] = fade * m["rain_sum"] + m["rain"]
        m["tt_sum"] = fade * m["tt_sum"] + (tt - m["tt"])
        m["day_sum"] = fade * m["day_sum"] + 1.0
        m["tt"] = tt
        for key in m:
            m[key] = np.where(fresh, start[key], m[key])
        return m

    def net_et_rate(self, memory: dict) -> np.ndarray:
        """(N,) net ET per unit of thermal time (mm per degC d; module docstring, point 4) from the sums of
        :meth:`_remember`: the larger of the season's and the recent rate, each shrunk towards the prior."""
        p = self.parameters
        net = np.maximum(memory["et0_sum"] - memory["rain_sum"], 0.25 * memory["et0_sum"])
        weight = p["prior_weight_degc_d"]
        rates = (net + p["rate_prior_mm_per_degc_d"] * weight) / np.maximum(memory["tt_sum"] + weight, MIN_RATE_TT_DEGC_D)
        return rates.max(axis=0)

    def _act_batch(self, obs):
        p, f = self.parameters, self.facts
        m = self._remember(obs)
        paw = self.soil_water.update(obs)
        et0 = obs[:, _COL["et0_mm"]]
        rain = obs[:, _COL["rain_mm"]]
        tt = obs[:, _COL["thermal_time_degc_d"]]
        quota = obs[:, _COL["quota_remaining_mm"]]
        rate = self.net_et_rate(m)
        supply = quota + paw

        def demand(first, last):
            return rate * np.maximum(last - np.maximum(tt, first), 0.0)

        start = f.i50a_degc_d + p["start_offset_degc_d"]
        stop = f.tsum_degc_d - m["i50b"] + p["stop_offset_degc_d"]
        wide = demand(start, stop)
        tightness = np.clip(np.where(wide > 0, supply / np.maximum(wide, 1e-9), 1.0), 0.0, 1.0)
        start = start + p["narrow_degc_d"] * (1.0 - tightness)
        stop = stop - p["narrow_stop_degc_d"] * (1.0 - tightness)
        # The late canopy: cover after the window, and its demand ahead (integral of the cover over TT).
        senescence_tt = f.tsum_degc_d - m["i50b"]
        late_from = np.maximum(tt, stop)
        late_ahead = rate * np.maximum(_cover_integral(f.tsum_degc_d, senescence_tt)
                                       - _cover_integral(late_from, senescence_tt), 0.0)
        ahead = demand(start, stop) + p["late_factor"] * np.where(late_from < f.tsum_degc_d, late_ahead, 0.0)
        ratio = np.where(ahead > 0, supply / np.maximum(ahead, 1e-9), np.inf)
        share = np.minimum(1.0, p["pace"] * ratio)
        # A heat day: growth is limited to f_heat already; f_water down to f_heat is free (I50B takes the max).
        f_heat = heat_response(obs[:, _COL["tmax_degc"]], f.heat_stress_onset_degc, f.extreme_heat_degc)
        free = np.clip((1.0 - f_heat) / f.water_stress_sensitivity, 0.0, 1.0)  # ARID that costs nothing today
        heat_share = 1.0 - p["heat_weight"] * free
        unstressed = et0 / WATER_UPTAKE_COEFFICIENT
        in_window = (tt >= start) & (tt <= stop)
        cover = 1.0 / (1.0 + np.exp(np.clip(0.01 * (tt - senescence_tt), -50.0, 50.0)))
        # The rising canopy (SIMPLE's f_Solar before senescence): growth, hence a mm's worth, follows it.
        rising = 1.0 / (1.0 + np.exp(np.clip(-0.01 * (tt - f.i50a_degc_d), -50.0, 50.0)))
        rise_share = 1.0 - p["rise_weight"] * (1.0 - rising)
        late = np.where(tt < f.tsum_degc_d, p["late_factor"] * share * cover * heat_share * unstressed, 0.0)
        # The bank: days of the recent ET0 the pump cannot keep up with (point 6).
        et0_recent = m["et0_sum"][1] / np.maximum(m["day_sum"][1], 1.0)
        shortfall = np.maximum(et0_recent - p["bank_threshold"] * obs[:, _COL["capacity_mm_per_day"]], 0.0)
        bank = p["bank_days"] * shortfall
        window_level = rise_share * (p["level_factor"] * share * heat_share * unstressed + p["margin_mm"] + share * bank)
        level = np.where(in_window, window_level,
                         np.where(tt < start, p["early_factor"] * heat_share * unstressed, late))
        amount = np.maximum(np.minimum(level, f.capacity_mm) - paw - rain, 0.0)
        amount = np.where(obs[:, _COL["forecast_rain_mm"]] > p["skip_rain_mm"], 0.0, amount)
        amount = np.minimum(np.minimum(amount, obs[:, _COL["capacity_mm_per_day"]]), quota)
        m["paw"], m["rain"], m["et0"], m["tmax"] = paw, rain, et0, obs[:, _COL["tmax_degc"]]
        return amount

    def describe(self):
        return {"name": self.name, **{k: (v.tolist() if v.ndim else float(v)) for k, v in self.parameters.items()}}
