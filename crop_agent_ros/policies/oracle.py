"""The hindsight oracle: the best irrigation schedule of one season, found knowing its true weather.

It is not a farmer: it reads the season's true daily weather (and hence every future rain) and the exact
soil water, and plans the whole schedule before the season starts. Observation noise does not change the
true dynamics, so the oracle's return is the season's best achievable return up to the search's
optimality gap: the upper bound every policy's regret is measured against.

How the schedule is found (all candidate schedules of a round are N fields of one batched
:func:`crop_sim_ros.model.simulate_season` call, scored with the task's reward
``sum C_I * a_d + Y`` over the days up to and including the maturity day):

1. Parametric family "exact just-in-time refill": each day, knowing the true PAW W and today's rain and
   ET0, irrigate the least amount that brings the water left after infiltration and drainage to
   ``k * ET0 / 0.096`` mm (the level at which transpiration meets ET0, i.e. no water stress), at least
   ``floor_mm``, only on days ``< stop_day``. Grid over k, floor and stop day; constant schedules and
   zero are candidates too.
2. Local refinement of the daily amounts: from the best schedule, every day's amount is moved by +-step,
   and step mm are shifted from any day to any other day at most 5 days away (about 2 D + 10 D
   candidates in one batched call); the best improving +-step move of each day is kept when the
   combination still improves, else the single best move of any kind; repeated until no move improves,
   then the step is halved (16 mm -> 1/8 mm).

Optimality gap, reported in ``OracleResult``: ``last_gain`` is the return gained by the last productive
refinement round, and at the end no single-day move of +-1/8 mm and no 1/8 mm shift between days within
5 days improves the return (a local optimum of this neighbourhood). Measured on the five held-out
seasons (benton-2000, paterson-1992..1995): the refinement gained 0.003-0.013 t/ha over the best family
schedule (adding the shift moves alone gained up to 0.0016 of it); a further, larger refinement from the
result (shifts between days up to 20 days apart, +-step on every irrigated day of 5-, 10- and 20-day
blocks, steps 4 -> 1/8 mm) found no improvement at all (gain 0 on every season). The search is local, so
this is evidence, not proof, of optimality. A rigorous upper bound on the true optimum is the season's potential
yield (no water stress, no water cost): ``bound_gap = potential - return >= optimum - return``. A tighter
one holds for every schedule without water stress (the crop then transpires ET0 each day, so by the water
balance its irrigation up to maturity is at least ``sum ET0 - PAW0 - sum rain + ET0_last (1/0.096 - 1)``,
the last term being the water an unstressed crop must still hold after its last day), the
``stress_free_water_floor_mm``): such a schedule returns at most ``potential + C_I * floor``, and
``stress_free_gap`` = that bound - the oracle's return (<= 0 means no stress-free schedule beats it).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .base import ACTION_HIGH_MM, DAYS_SINCE_SOWING, BasePolicy, SeasonContext

UPTAKE = 0.096  # ARID's daily water uptake coefficient (crop_sim_ros.model.simple.WATER_UPTAKE_COEFFICIENT)


def _model():
    from crop_sim_ros import model
    return model


def schedule_returns(context: SeasonContext, schedules: np.ndarray) -> tuple[np.ndarray, object]:
    """Return of each column of ``schedules`` (D, N) mm on the season's true dynamics, and the run.

    Return = C_I * (irrigation on days 0..maturity day) + yield t/ha at maturity (0 if the season ends
    unmatured: the env truncates without a harvest reward in that case; see ``context.extra``).
    """
    m = _model()
    schedules = np.asarray(schedules, dtype=float)
    days, n = schedules.shape
    params = m.repeat_parameters(context.params, n) if context.params.n_fields != n else context.params
    run = m.simulate_season(params, context.tmax_degc[:days], context.tmin_degc[:days], context.srad_mj_m2[:days],
                            context.rain_mm[:days], context.et0_mm[:days], schedules)
    state = run.final_state
    last_day = np.where(state.mature, state.maturity_day, days - 1)
    counted = np.arange(days)[:, None] <= last_day[None, :]
    water = (schedules * counted).sum(axis=0)
    yield_t_ha = np.where(state.mature, state.biomass_kg_ha * run.harvest_index / 1000.0,
                          context.extra.get("unmatured_yield_factor", 0.0)
                          * state.biomass_kg_ha * run.harvest_index / 1000.0)
    return context.water_cost_per_mm * water + yield_t_ha, run


def potential_yield_t_ha(context: SeasonContext, with_maturity_day: bool = False):
    """Yield of the season with water stress switched off (the normalizer and an upper bound); with
    ``with_maturity_day`` also the maturity day of that unstressed crop (-1 if it does not mature)."""
    from dataclasses import replace
    m = _model()
    p = replace(context.params, water_stress_sensitivity=np.zeros_like(context.params.water_stress_sensitivity))
    run = m.simulate_season(p, context.tmax_degc, context.tmin_degc, context.srad_mj_m2, context.rain_mm,
                            context.et0_mm, 0.0)
    potential = float(np.nan_to_num(run.harvested_yield_kg_ha[0]) / 1000.0)
    return (potential, int(run.final_state.maturity_day[0])) if with_maturity_day else potential


def _infiltrated(p_mm, retention_mm):
    """Water kept after SCS runoff from an input of ``p_mm``."""
    excess = np.maximum(p_mm - 0.2 * retention_mm, 0.0)
    return p_mm - excess * excess / (p_mm + 0.8 * retention_mm)


def _input_for(level_mm, capacity_mm, ddc, retention_mm):
    """The water W1 (after infiltration, before drainage) that leaves ``level_mm`` after deep drainage:
    above capacity, drainage takes ``ddc`` of the excess (``retention_mm`` unused: runoff is handled by
    the caller's bisection on the irrigation amount)."""
    above = np.maximum(level_mm - capacity_mm, 0.0)
    return np.where(level_mm > capacity_mm, capacity_mm + above / (1.0 - ddc), level_mm)


def refill_family(context: SeasonContext, k, floor_mm, stop_day) -> np.ndarray:
    """Schedules (D, N) of the exact just-in-time refill family (see the module docstring)."""
    m = _model()
    k, floor_mm, stop_day = np.broadcast_arrays(np.asarray(k, float), np.asarray(floor_mm, float),
                                                np.asarray(stop_day, float))
    n = k.size
    params = m.repeat_parameters(context.params, n)
    state = m.initial_state(params)
    days = len(context.rain_mm)
    out = np.zeros((days, n))
    cap = params.capacity_mm
    s = params.runoff_retention_mm
    for d in range(days):
        rain, et0 = context.rain_mm[d], context.et0_mm[d]
        level = np.maximum(k * et0 / UPTAKE, floor_mm)
        w1_needed = _input_for(level, cap, params.deep_drainage_coefficient, s)
        need = w1_needed - state.plant_available_water_mm  # infiltrated water wanted today
        have = _infiltrated(np.full(n, rain), s)
        lo = np.zeros(n)
        hi = np.full(n, ACTION_HIGH_MM)
        want = need > have + 1e-9
        for _ in range(40):  # bisection on the irrigation amount (infiltration is increasing in P)
            mid = 0.5 * (lo + hi)
            ok = _infiltrated(rain + mid, s) >= need
            hi = np.where(ok, mid, hi)
            lo = np.where(ok, lo, mid)
        amount = np.where(want & (d < stop_day) & ~state.mature, hi, 0.0)
        out[d] = amount
        weather = m.DailyWeather(context.tmax_degc[d], context.tmin_degc[d], context.srad_mj_m2[d], rain, et0)
        state, _ = m.step(params, state, weather, amount)
    return out


@dataclass
class OracleResult:
    schedule_mm: np.ndarray
    return_value: float
    family_return: float
    family_parameters: dict
    potential_yield_t_ha: float
    bound_gap: float
    last_gain: float
    stress_free_water_floor_mm: float
    stress_free_gap: float
    refinement_gain: float
    rounds: int
    evaluations: int
    yield_t_ha: float
    water_mm: float
    history: list = field(default_factory=list)


def find_best_schedule(context: SeasonContext, finest_step_mm: float = 1 / 8, first_step_mm: float = 16.0,
                       max_rounds_per_step: int = 60, shift_window_days: int = 5) -> OracleResult:
    """Search the season's best schedule (see the module docstring for the method)."""
    days = len(context.rain_mm)
    evaluations = 0
    # 1. parametric family
    ks = np.array([0.8, 0.9, 0.95, 1.0, 1.02, 1.05, 1.1, 1.2])
    floors = np.array([0.0, 40.0, 60.0, 80.0])
    stops = np.array([days, days - 10, days - 20, days - 30])
    kk, ff, ss = [a.ravel() for a in np.meshgrid(ks, floors, stops, indexing="ij")]
    family = refill_family(context, kk, ff, ss)
    constants = np.array([0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 15.0])
    candidates = np.concatenate([family, np.broadcast_to(constants, (days, constants.size))], axis=1)
    returns, _ = schedule_returns(context, candidates)
    evaluations += candidates.shape[1]
    best_i = int(np.argmax(returns))
    best = candidates[:, best_i].copy()
    best_return = float(returns[best_i])
    family_return = best_return
    family_params = ({"k": float(kk[best_i]), "floor_mm": float(ff[best_i]), "stop_day": int(ss[best_i])}
                     if best_i < kk.size else {"constant_mm": float(constants[best_i - kk.size])})
    # 2. coordinate refinement
    _, run = schedule_returns(context, best[:, None])
    state = run.final_state
    active_days = int(state.maturity_day[0]) + 1 if state.mature[0] else days
    step_mm = first_step_mm
    rounds = 0
    last_gain = 0.0
    history = [best_return]
    eye = np.eye(active_days)
    offsets = [o for o in range(-shift_window_days, shift_window_days + 1) if o]
    pairs = np.array([(i, i + o) for i in range(active_days) for o in offsets if 0 <= i + o < active_days])
    while step_mm >= finest_step_mm - 1e-12:
        for _ in range(max_rounds_per_step):
            plus = np.clip(best[:active_days, None] + step_mm * eye, 0.0, ACTION_HIGH_MM)
            minus = np.clip(best[:active_days, None] - step_mm * eye, 0.0, ACTION_HIGH_MM)
            # shift moves: step mm from day i to day j (|i - j| <= window), where day i has that much
            movable = pairs[best[pairs[:, 0]] >= step_mm - 1e-12]
            shift = np.repeat(best[:active_days, None], len(movable), axis=1)
            columns = np.arange(len(movable))
            shift[movable[:, 0], columns] -= step_mm
            shift[movable[:, 1], columns] = np.minimum(shift[movable[:, 1], columns] + step_mm, ACTION_HIGH_MM)
            moves = np.concatenate([plus, minus, shift], axis=1)
            full = np.zeros((days, moves.shape[1]))
            full[:active_days] = moves
            r, _ = schedule_returns(context, full)
            evaluations += moves.shape[1]
            gains = r - best_return
            rounds += 1
            if gains.max() <= 1e-12:
                break
            # combine every day's best improving +-step move; else take the single best move of any kind
            per_day = np.stack([gains[:active_days], gains[active_days:2 * active_days]])
            choice = np.argmax(per_day, axis=0)
            improving = per_day.max(axis=0) > 1e-12
            new, new_return = None, best_return
            if improving.sum() > 1:
                combined = best.copy()
                delta = np.where(choice == 0, step_mm, -step_mm)
                combined[:active_days] = np.where(improving, np.clip(best[:active_days] + delta, 0, ACTION_HIGH_MM),
                                                  best[:active_days])
                rc, _ = schedule_returns(context, combined[:, None])
                evaluations += 1
                if rc[0] > best_return + gains.max():
                    new, new_return = combined, float(rc[0])
            if new is None:
                j = int(np.argmax(gains))
                new, new_return = full[:, j].copy(), float(r[j])
            last_gain = new_return - best_return
            best, best_return = new, new_return
            history.append(best_return)
        step_mm /= 2.0
    # final certificate at the finest step
    potential, maturity_day = potential_yield_t_ha(context, with_maturity_day=True)
    last = maturity_day if maturity_day >= 0 else days - 1
    # unstressed on the maturity day: W2 >= ET0/0.096 there, so W_end = W2 - ET0 >= ET0 (1/0.096 - 1)
    water_floor = max(0.0, float(np.sum(context.et0_mm[:last + 1]) - context.params.initial_paw_mm[0]
                                 - np.sum(context.rain_mm[:last + 1])
                                 + context.et0_mm[last] * (1.0 / UPTAKE - 1.0)))
    stress_free_bound = potential + context.water_cost_per_mm * water_floor
    _, run = schedule_returns(context, best[:, None])
    state = run.final_state
    yield_t_ha = float(state.biomass_kg_ha[0] * run.harvest_index[0] / 1000.0) if state.mature[0] else 0.0
    end = int(state.maturity_day[0]) + 1 if state.mature[0] else days
    best[end:] = 0.0
    return OracleResult(schedule_mm=best, return_value=best_return, family_return=family_return,
                        family_parameters=family_params, potential_yield_t_ha=potential,
                        bound_gap=potential - best_return, last_gain=last_gain,
                        stress_free_water_floor_mm=water_floor, stress_free_gap=stress_free_bound - best_return,
                        refinement_gain=best_return - family_return, rounds=rounds, evaluations=evaluations,
                        yield_t_ha=yield_t_ha, water_mm=float(best.sum()), history=history)


class OraclePolicy(BasePolicy):
    """Plays the planned best schedule of each field's season (given to :meth:`begin_season`: one
    :class:`SeasonContext`, or a list with one per row of the observation batch), by days since sowing."""

    name = "oracle"

    def __init__(self, **search_options):
        self.search_options = search_options
        self.results: list[OracleResult] = []
        self._cache: dict = {}

    def plan(self, context: SeasonContext) -> OracleResult:
        """The best schedule of ``context`` (searched once per season, then cached)."""
        key = (context.name, len(context.rain_mm), float(np.sum(context.rain_mm)), float(np.sum(context.et0_mm)),
               context.water_cost_per_mm)
        if key not in self._cache:
            self._cache[key] = find_best_schedule(context, **self.search_options)
        return self._cache[key]

    def begin_season(self, context) -> None:
        contexts = list(context) if isinstance(context, (list, tuple)) else [context]
        self.results = [self.plan(c) for c in contexts]

    @property
    def result(self) -> OracleResult | None:
        return self.results[0] if self.results else None

    def _act_batch(self, obs):
        if not self.results:
            raise RuntimeError("the oracle needs begin_season(context) with the season's true weather first")
        if len(self.results) not in (1, len(obs)):
            raise ValueError(f"oracle: {len(self.results)} planned seasons for {len(obs)} observations")
        out = np.empty(len(obs))
        for i in range(len(obs)):
            schedule = self.results[i if len(self.results) > 1 else 0].schedule_mm
            day = int(np.clip(np.rint(obs[i, DAYS_SINCE_SOWING]), 0, len(schedule) - 1))
            out[i] = schedule[day]
        return out

    def describe(self):
        return {"name": self.name, **({} if not self.results else {
            "return": [r.return_value for r in self.results], "bound_gap": [r.bound_gap for r in self.results],
            "last_gain": [r.last_gain for r in self.results]})}
