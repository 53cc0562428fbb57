"""A dynamic programme over one field's soil water and senescence: a rigorous upper bound on the task family's
return (:func:`upper_bound`) and global plans (:func:`plan`), for :mod:`crop_agent_ros.policies.family_oracle`.

What water changes in SIMPLE (``crop_sim_ros.model.simple``), given the season's weather:

- the soil water W (mm) and, through it, the day's transpiration T = min(0.096 W2, ET0) (W2: after runoff
  and drainage), ARID = 1 - T / ET0 and f_water = max(1 - S_water ARID, 0);
- the day's growth, ``10 RUE f_CO2 fSolar SRAD f_temp min(f_heat, f_water)`` kg/ha;
- the senescence parameter I50B, which grows each day by max(I50maxW (1 - f_water), I50maxH (1 - f_heat)),
  and fSolar(d+1) = canopy(TT(d+1), I50B(d)) x canopy water response(f_water(d)).

Thermal time, and hence the last day the crop can grow (the day before TT passes the cultivar's TT to
maturity), do not depend on water. The state that matters on day d is therefore two numbers: W(d) and
I50B(d-1). Yesterday's transpiration is a function of W(d) alone (W(d) = W2 - min(0.096 W2, ET0) is
increasing in W2), so I50B(d) = I50B(d-1) + max(I50maxW (1 - f_water(d-1)), I50maxH (1 - f_heat(d-1)))
follows from the state, and so does fSolar(d). The programme stores I50B(d-1) as its excess ("offset", degC
d) over the no-water-stress value; its value function V_d(W, offset) is the best return still to come. A
quota is priced by a Lagrange multiplier lambda (reward units per mm) added to the water's cost.

**Plans** (:func:`plan`): W on a grid of ``water_step_mm``, offsets on a grid of ``offset_step_degc_d``,
linear interpolation between grid points; each day's choices are no water, each grid level of tomorrow's W
reachable within the capacity, and the capacity. Then a forward pass on the true model: each day the amount
(on a fine grid within the capacity and the quota left) that maximises today's reward + the interpolated
value of tomorrow's state. One plan per multiplier of a sweep; the oracle starts its local search from the
best. Global (no start schedule, no rule), but approximate (the grid, and a quota priced rather than held).

**Upper bound** (:func:`upper_bound`). The true value function is nondecreasing in W and nonincreasing in
the offset (more water: more transpiration, less senescence; a larger offset: a smaller canopy). The bound's
programme rounds tomorrow's W up to its grid, credits each choice with the growth of the most water it stands
for and charges it the irrigation of the least (the previous grid level's) and the event cost of any water,
counts growth to the TT maturity day (maturity by senescence only ends growth earlier), and holds the offset
at 0 (water stress never advances senescence: rounding a daily increment of at most I50maxW S_water = 12 degC d
down to any practical grid loses it anyway). By induction its value at a grid state is at least the true
best return from any state with less water, hence from the true initial state; and for every lambda >= 0,
``value(cost per mm + lambda) + lambda x quota`` >= every feasible schedule's return. The bound reported is
the least over the multipliers tried. Its slack: the grid (about (cost + lambda) x water_step_mm / 2 per day
of partial irrigation), the senescence it ignores (large under a binding quota, where the best schedules
stress the crop), and the Lagrangian duality gap. Without a quota it is tight to a fraction of a per cent.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from crop_sim_ros import model
from crop_sim_ros.model import simple

KG_PER_T = 1000.0


def water_input_for(infiltrated_mm, retention_mm):
    """The water input P (mm) whose infiltration after SCS runoff, P - (P - 0.2 S)^2 / (P + 0.8 S) above
    0.2 S, is ``infiltrated_mm`` (inf when it exceeds the curve's limit 1.2 S): solving the quadratic."""
    a, b = 0.2 * retention_mm, 0.8 * retention_mm
    f = np.maximum(infiltrated_mm, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        above = np.where(f < 1.2 * retention_mm, (a * a + b * f) / (1.2 * retention_mm - f), np.inf)
    return np.where(f <= a, f, above)


@dataclass
class BoundResult:
    """``bound``: reward units; no feasible schedule of the field returns more. ``multiplier``: the quota's
    Lagrange multiplier it was found at (reward units per mm); ``evaluations``: dynamic programmes run."""

    bound: float
    multiplier: float
    evaluations: int
    water_step_mm: float


class SeasonProgramme:
    """The dynamic programme of one :class:`~crop_agent_ros.policies.family_oracle.FieldProblem` (see the
    module docstring)."""

    def __init__(self, problem, water_step_mm: float = 0.5, offset_step_degc_d: float = 20.0,
                 offset_max_degc_d: float = 1200.0):
        context = problem.context
        p = {f.name: float(np.broadcast_to(getattr(context.params, f.name), (1,))[0])
             for f in fields(model.FieldParameters)}
        self.p = p
        self.problem = problem
        tmax, tmin, srad, rain, et0 = (np.asarray(a, dtype=float) for a in (
            context.tmax_degc, context.tmin_degc, context.srad_mj_m2, context.rain_mm, context.et0_mm))
        self.rain, self.et0 = rain, et0
        n = len(rain)
        tmean = 0.5 * (tmax + tmin)
        dtt = simple.thermal_time_increment(tmean, p["base_temperature_degc"])
        next_tt = p["initial_thermal_time_degc_d"] + np.cumsum(dtt)
        self.tt = np.concatenate([[p["initial_thermal_time_degc_d"]], next_tt[:-1]])  # TT at the start of day d
        matures = (next_tt > p["thermal_time_to_maturity_degc_d"]) | (np.arange(n) >= p["harvest_day"])
        self.last_growth_day = int(np.argmax(matures)) - 1 if matures.any() else n - 1
        f_temp = simple.temperature_response(tmean, p["base_temperature_degc"], p["optimal_temperature_degc"])
        self.f_heat = simple.heat_response(tmax, p["heat_stress_onset_degc"], p["extreme_heat_degc"])
        # growth, kg/ha, per unit of fSolar x min(f_heat, f_water)
        self.growth_scale = (simple.KG_HA_PER_G_M2 * p["radiation_use_efficiency"] * p["co2_factor"] * srad
                             * f_temp)
        self.heat_increment = np.maximum(p["i50_max_heat_degc_d"] * (1.0 - self.f_heat), 0.0)
        # I50B(d-1) without water stress (offset 0), for d >= 1
        self.base_i50b = p["i50b_degc_d"] + np.concatenate([[0.0, 0.0], np.cumsum(self.heat_increment)[:-1]])
        self.capacity_soil = p["available_water_capacity"] * p["root_zone_depth_mm"]
        self.ddc = p["deep_drainage_coefficient"]
        self.retention = p["runoff_retention_mm"]
        self.cap = float(problem.capacity_mm_per_day)
        self.value_per_kg = problem.yield_value_per_t * p["harvest_index"] / KG_PER_T
        if not 0.0 < self.ddc < 1.0:
            raise ValueError(f"family DP: the soil's deep drainage coefficient must be in (0, 1) (the water grid is "
                             f"bounded by drainage), got {self.ddc}")
        top = max(p["initial_paw_mm"], self.capacity_soil
                  + (1.0 - self.ddc) / self.ddc * (float(rain.max()) + self.cap))
        self.water_step = float(water_step_mm)
        self.water = np.arange(0.0, top + self.water_step, self.water_step)
        self.offset_step = float(offset_step_degc_d)
        self.offsets = np.arange(0.0, offset_max_degc_d + self.offset_step / 2, self.offset_step)

    # --- the water balance and its inverse (crop_sim_ros.model.simple.water_balance) ---------------------
    def _forward(self, water_mm, irrigation_mm, d):
        """(tomorrow's W, today's T) from W and today's irrigation (arrays broadcast)."""
        flux = simple.water_balance(water_mm, self.rain[d] + irrigation_mm, self.et0[d], self.retention,
                                    self.p["available_water_capacity"], self.ddc, self.p["root_zone_depth_mm"])
        return flux.plant_available_water_mm, flux.transpiration_mm

    def _inverse(self, water_mm, target_mm, d):
        """(irrigation, T) that bring W to ``target_mm`` tomorrow (targets at or above the no-water one)."""
        u = simple.WATER_UPTAKE_COEFFICIENT
        et0 = self.et0[d]
        after_drainage = np.where(target_mm * u / (1.0 - u) <= et0, target_mm / (1.0 - u), target_mm + et0)
        before = np.where(after_drainage <= self.capacity_soil, after_drainage,
                          self.capacity_soil + (after_drainage - self.capacity_soil) / (1.0 - self.ddc))
        water_input = water_input_for(before - water_mm, self.retention)
        return np.maximum(water_input - self.rain[d], 0.0), np.minimum(u * after_drainage, et0)

    def _f_water(self, transpiration_mm, d):
        return np.maximum(1.0 - self.p["water_stress_sensitivity"] * (1.0 - transpiration_mm / self.et0[d]), 0.0)

    # --- one day ------------------------------------------------------------------------------------------
    def _choices(self, water_mm: np.ndarray, d: int, rounding: bool):
        """Each state's choices (n, K): tomorrow's W, the growth factor min(f_heat, f_water), the irrigation
        charged (mm; rounding: the least of the choice's interval), whether it is a day with water, and
        which are valid. Choices: no water, each grid level of tomorrow's W between, the capacity."""
        n = len(water_mm)
        none_w, none_t = self._forward(water_mm, 0.0, d)
        columns_w, columns_t = [none_w[:, None]], [none_t[:, None]]
        charged, wet, valid = [np.zeros((n, 1))], [np.zeros((n, 1), dtype=bool)], [np.ones((n, 1), dtype=bool)]
        if self.cap > 0.0:
            full_w, full_t = self._forward(water_mm, self.cap, d)
            h = self.water_step
            first = np.floor(none_w / h + 1e-9).astype(np.int64) + 1
            last = np.minimum(np.ceil(full_w / h - 1e-9).astype(np.int64) - 1, len(self.water) - 1)
            count = np.maximum(last - first + 1, 0)
            width = int(count.max())
            inside = np.arange(width)[None, :] < count[:, None]
            target = self.water[np.minimum(first[:, None] + np.arange(width)[None, :], len(self.water) - 1)]
            target_i, target_t = self._inverse(water_mm[:, None], target, d)
            target_i = np.where(inside, np.minimum(target_i, self.cap), 0.0)
            if rounding:  # charge the previous level's irrigation: the least any amount of the interval costs
                target_charged = np.concatenate([np.zeros((n, 1)), target_i[:, :-1]], axis=1)
                full_charged = np.where(count > 0, target_i[np.arange(n), np.maximum(count - 1, 0)], 0.0)
            else:
                target_charged, full_charged = target_i, np.full(n, self.cap)
            columns_w += [target, full_w[:, None]]
            columns_t += [target_t, full_t[:, None]]
            charged += [target_charged, full_charged[:, None]]
            wet += [np.ones((n, width), dtype=bool), np.ones((n, 1), dtype=bool)]
            valid += [inside, np.ones((n, 1), dtype=bool)]
        next_w, transpiration, charged, wet, valid = (np.concatenate(c, axis=1) for c in
                                                     (columns_w, columns_t, charged, wet, valid))
        factor = np.minimum(self.f_heat[d], self._f_water(transpiration, d))
        return next_w, factor, charged, wet, valid

    def _lookup(self, tables: np.ndarray, water_mm: np.ndarray, offset: np.ndarray, rounding: bool) -> np.ndarray:
        """tables (M, nW, nO) at W (n, K) and offsets (n, J): (M, n, K, J); rounding: W up, offset down (the
        bound), else bilinear interpolation (offsets beyond the grid: its last)."""
        count, nw, no = tables.shape
        flat = tables.reshape(count, nw * no)  # np.take on the flat table: the fastest gather
        w = np.clip(water_mm / self.water_step, 0.0, nw - 1)
        o = np.clip(offset / self.offset_step, 0.0, no - 1)
        if rounding:
            wi = np.minimum(np.ceil(w - 1e-9).astype(np.int64), nw - 1)
            oi = np.floor(o + 1e-9).astype(np.int64)
            return np.take(flat, wi[:, :, None] * no + oi[:, None, :], axis=1)
        w0 = np.minimum(np.floor(w).astype(np.int64), nw - 2)
        o0 = np.minimum(np.floor(o).astype(np.int64), no - 2)
        fw = (w - w0)[None, :, :, None]
        fo = (o - o0)[None, :, None, :]
        corner = w0[:, :, None] * no + o0[:, None, :]
        low = np.take(flat, corner, axis=1) * (1 - fo) + np.take(flat, corner + 1, axis=1) * fo
        high = np.take(flat, corner + no, axis=1) * (1 - fo) + np.take(flat, corner + no + 1, axis=1) * fo
        return low * (1 - fw) + high * fw

    def _lookup_shifted(self, tables: np.ndarray, water_mm: np.ndarray, shift_degc_d: np.ndarray,
                        rounding: bool) -> np.ndarray:
        """tables (M, nW, nO) at W (n, K) and the offsets ``offsets + shift_degc_d`` (shift (n,) >= 0): (M, n, K,
        nO), as :meth:`_lookup`. A state's next offsets are its grid offsets shifted by one amount
        (:meth:`_state_terms`); when every shift is below the offset step (a day's senescence is at most I50maxW,
        30 degC d for potato) the bilinear interpolation in the offset is between neighbouring columns of whole
        table rows, not a gather per element: what makes the backward pass cheap. Rounding (the bound), or a
        shift of a step or more: :meth:`_lookup` itself."""
        part = shift_degc_d / self.offset_step
        if rounding or part.max() >= 1.0:
            return self._lookup(tables, water_mm, self.offsets[None, :] + shift_degc_d[:, None], rounding)
        count, nw, no = tables.shape
        padded = np.concatenate([tables, tables[:, :, -1:]], axis=2)  # beyond the last offset: the last
        w = np.clip(water_mm / self.water_step, 0.0, nw - 1)
        w0 = np.minimum(np.floor(w).astype(np.int64), nw - 2)
        low = padded[:, w0]
        rows = low + (padded[:, w0 + 1] - low) * (w - w0)[None, :, :, None]  # (M, n, K, nO + 1): interpolated in W
        return rows[..., :-1] + (rows[..., 1:] - rows[..., :-1]) * part[None, :, None, None]

    def _state_terms(self, d: int):
        """For the grid states of day d >= 1: fSolar (nW, nO) and the shift (nW,) of tomorrow's offset over
        today's (degC d): tomorrow's offsets are ``offsets + shift``."""
        p = self.p
        u = simple.WATER_UPTAKE_COEFFICIENT
        yesterday_t = np.minimum(self.et0[d - 1], self.water * u / (1.0 - u))
        f_water = self._f_water(yesterday_t, d - 1)
        response = np.minimum(simple.canopy_water_response(f_water), 1.0)
        cover = simple.canopy_cover(self.tt[d], p["i50a_degc_d"], p["thermal_time_to_maturity_degc_d"],
                                    self.base_i50b[d] + self.offsets, p["fsolar_max"])
        extra = np.maximum(p["i50_max_water_degc_d"] * (1.0 - f_water) - self.heat_increment[d - 1], 0.0)
        return response[:, None] * cover[None, :], extra

    def _day_terms(self, d: int, rounding: bool, kept: dict | None) -> tuple:
        """:meth:`_state_terms` and :meth:`_choices` of the grid states of day d, from ``kept`` if it holds them
        (they do not depend on the price), else computed and stored there."""
        if kept is None:
            return self._state_terms(d) + self._choices(self.water, d, rounding)
        if (d, rounding) not in kept:
            kept[d, rounding] = self._state_terms(d) + self._choices(self.water, d, rounding)
        return kept[d, rounding]

    def value_tables(self, prices_per_mm, rounding: bool, first_day: int = 0,
                     day_terms: dict | None = None) -> tuple[np.ndarray | None, list]:
        """For M prices per mm of irrigation: the return still to come from the initial state (M,) (without
        the initial biomass's value), and the value tables (M, nW, nO) of days 1..last growth day + 1.
        ``first_day`` > 0: only the tables of days first_day..last growth day + 1 (the others None), and no
        initial value (None): what a decision in mid-season needs. ``day_terms``: a dict that keeps each day's
        price-independent terms across calls on this programme at other prices (a caller's, to drop with it:
        megabytes on fine grids)."""
        prices = np.atleast_1d(np.asarray(prices_per_mm, dtype=float))
        event = self.problem.event_cost
        last = self.last_growth_day
        tables: list = [None] * max(last + 2, first_day + 1)
        if last < 0:
            return np.zeros(len(prices)), tables
        tables[last + 1] = np.zeros((len(prices), len(self.water), len(self.offsets)))
        for d in range(last, max(first_day, 1) - 1, -1):
            fsolar, shift, next_w, factor, charged, wet, valid = self._day_terms(d, rounding, day_terms)
            gain = self.value_per_kg * self.growth_scale[d] * fsolar[:, None, :] * factor[:, :, None]
            charge = np.where(valid[None], prices[:, None, None] * charged[None] + event * wet[None], np.inf)
            later = self._lookup_shifted(tables[d + 1], next_w, shift, rounding)
            tables[d] = ((gain[None] - charge[..., None]) + later).max(axis=2)
        if first_day > 0:
            return None, tables
        w0 = np.array([self.p["initial_paw_mm"]])
        next_w, factor, charged, wet, valid = self._choices(w0, 0, rounding)
        gain = self.value_per_kg * self.growth_scale[0] * self.p["initial_fsolar"] * factor
        charge = prices[:, None, None] * charged[None] + event * wet[None]
        later = self._lookup(tables[1], next_w, np.zeros((1, 1)), rounding)[..., 0]
        return np.where(valid[None], gain[None] - charge + later, -np.inf).max(axis=(1, 2)), tables

    def bounds_at(self, multipliers, day_terms: dict | None = None) -> np.ndarray:
        """The upper bound at each of the quota's multipliers (reward units per mm); ``day_terms`` as
        :meth:`value_tables`'."""
        multipliers = np.atleast_1d(np.asarray(multipliers, dtype=float))
        values, _ = self.value_tables(self.problem.water_cost_per_mm + multipliers, rounding=True, day_terms=day_terms)
        quota = self.problem.quota_mm
        return (self.value_per_kg * self.p["initial_biomass_kg_ha"] + values
                + (multipliers * quota if np.isfinite(quota) else 0.0))


def upper_bound(problem, water_step_mm: float = 0.25, multipliers_per_round: int = 8, rounds: int = 2) -> BoundResult:
    """A rigorous upper bound on the return of every feasible schedule of ``problem`` (module docstring), with
    the senescence offset held at 0; the least over multipliers on a geometric grid, then on a finer grid
    around the best (every one is a bound)."""
    programme = SeasonProgramme(problem, water_step_mm, offset_max_degc_d=0.0)
    if not np.isfinite(problem.quota_mm):
        return BoundResult(float(programme.bounds_at(0.0)[0]), 0.0, 1, water_step_mm)
    grid = np.concatenate([[0.0], problem.yield_value_per_t * np.geomspace(1e-4, 0.05, multipliers_per_round - 1)])
    tried, values, day_terms = [], [], {}
    for round_ in range(rounds):
        tried.append(grid)
        values.append(programme.bounds_at(grid, day_terms))
        best = int(np.argmin(values[-1]))
        low, high = grid[max(best - 1, 0)], grid[min(best + 1, len(grid) - 1)]
        grid = np.linspace(low, high, multipliers_per_round + 2)[1:-1]
    tried, values = np.concatenate(tried), np.concatenate(values)
    best = int(np.argmin(values))
    return BoundResult(float(values[best]), float(tried[best]), len(tried), water_step_mm)


def _forward_plans(programme: SeasonProgramme, tables: list, prices: np.ndarray, amounts: int = 33,
                   first_day: int = 0, state=None, quota_left_mm: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """For each price: the schedule that each day maximises today's reward + the interpolated value of
    tomorrow's state, on the true model, within the capacity and the quota left; from ``state`` (one field's
    :class:`CropState` at the start of ``first_day``; default: sowing) with ``quota_left_mm`` (default: the
    quota). Returns the schedules (D, M) (0 before ``first_day``) and their returns to go (M,) at the
    problem's own water cost (reward units: the growth's value from ``first_day`` less water and events)."""
    problem = programme.problem
    context = problem.context
    count = len(prices)
    schedules = np.zeros((problem.days, count))
    params = model.repeat_parameters(context.params, count * amounts)
    start = model.initial_state(context.params) if state is None else state
    state = model.CropState(*(np.repeat(np.asarray(a), count) for a in start))
    quota_left = problem.quota_mm if quota_left_mm is None else float(quota_left_mm)
    left = np.full(count, quota_left - 1e-6 if np.isfinite(quota_left) else np.inf)
    returns = np.zeros(count)
    rows = np.arange(count)
    fraction = np.linspace(0.0, 1.0, amounts)
    for d in range(first_day, min(programme.last_growth_day + 1, problem.days)):
        if state.mature.all():
            break
        top = np.where(state.mature, 0.0, np.minimum(programme.cap, np.maximum(left, 0.0)))
        choices = (top[:, None] * fraction[None, :]).ravel()
        batch = model.CropState(*(np.repeat(a, amounts) for a in state))
        after, _ = model.step(params, batch, context.weather_on(d), choices)
        growth = programme.value_per_kg * (after.biomass_kg_ha - batch.biomass_kg_ha)
        events = problem.event_cost * (choices > 0.0)
        reward = (growth - np.repeat(prices, amounts) * choices - events).reshape(count, amounts)
        offset = (state.i50b_degc_d - programme.base_i50b[d + 1])[:, None]
        water = after.plant_available_water_mm.reshape(count, amounts)
        later = programme._lookup(tables[d + 1], water, offset, False)[rows, rows, :, 0]  # price k's table at its own states
        best = np.argmax(reward + later, axis=1)
        pick = rows * amounts + best
        schedules[d] = choices[pick]
        returns += (growth - problem.water_cost_per_mm * choices - events)[pick]
        left -= choices[pick]
        state = model.CropState(*(a[pick] for a in after))
    return schedules, returns


def plan(problem, multipliers=None, water_step_mm: float = 2.0, offset_step_degc_d: float = 40.0,
         offset_max_degc_d: float = 1200.0) -> np.ndarray:
    """Plans of ``problem`` (module docstring), one per quota multiplier (reward units per mm; default: a
    sweep, or 0 without a quota): feasible schedules (D, M)."""
    programme = SeasonProgramme(problem, water_step_mm, offset_step_degc_d, offset_max_degc_d)
    if multipliers is None:
        multipliers = ([0.0] if not np.isfinite(problem.quota_mm)
                       else problem.yield_value_per_t * np.array(PLAN_MULTIPLIERS_PER_VALUE))
    prices = problem.water_cost_per_mm + np.asarray(multipliers, dtype=float)
    _, tables = programme.value_tables(prices, rounding=False)
    return _forward_plans(programme, tables, prices)[0]


# The plan's quota multipliers, as fractions of the yield value per t (reward units per mm per reward unit per t).
PLAN_MULTIPLIERS_PER_VALUE = (0.0, 0.01, 0.015, 0.02, 0.03)
