"""The hindsight oracle: the best irrigation schedule of one season, found knowing its true weather.

It is not a farmer: it reads the season's true daily weather (and hence every future rain) and the exact
soil water, and plans the whole schedule before the season starts. Observation noise does not change the
true dynamics, so the oracle's return is the season's best achievable return up to the search's
optimality gap: the upper bound every policy's regret is measured against.

How the schedule is found (all candidate schedules of a round are N fields of one batched model run,
scored with the task's reward ``sum C_I * a_d + Y`` over the days up to and including the maturity day;
the searches of several seasons run side by side, see :func:`find_best_schedules`; :func:`_evaluate`
skips the days a candidate shares with the schedule it was made from and the days after every candidate
matured, with the same results, bit for bit, as whole-season runs, :func:`schedule_returns`):

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

from dataclasses import dataclass, field, fields, replace

import numpy as np

from crop_sim_ros.model.simple import WATER_UPTAKE_COEFFICIENT  # ARID's water uptake coefficient, d-1

from .base import ACTION_HIGH_MM, DAYS_SINCE_SOWING, BasePolicy, SeasonContext


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


def refill_families(contexts: list[SeasonContext], k, floor_mm, stop_day_of) -> list[np.ndarray]:
    """Schedules (D, N) of the exact just-in-time refill family (see the module docstring) of every
    context, all seasons in one batched model call per day: ``k``, ``floor_mm`` (N,) and the stop days
    ``stop_day_of(days)`` of a season of ``days`` days. Seasons shorter than the longest run on with their
    last day's weather; those days are cut off the returned schedules."""
    m = _model()
    k, floor_mm = np.broadcast_arrays(np.asarray(k, float), np.asarray(floor_mm, float))
    n = k.size
    lengths = [len(c.rain_mm) for c in contexts]
    stop_day = np.concatenate([np.broadcast_to(np.asarray(stop_day_of(days), float), (n,)) for days in lengths])
    slot = np.repeat(np.arange(len(contexts)), n)
    k, floor_mm = np.tile(k.ravel(), len(contexts)), np.tile(floor_mm.ravel(), len(contexts))
    params = _column_parameters(contexts, slot)
    weather = _weather_by_day(contexts)
    state = m.initial_state(params)
    out = np.zeros((max(lengths), slot.size))
    cap = params.capacity_mm
    s = params.runoff_retention_mm
    for d in range(out.shape[0]):
        day = m.DailyWeather(*weather[d][:, slot])
        rain, et0 = day.rain_mm, day.et0_mm
        level = np.maximum(k * et0 / WATER_UPTAKE_COEFFICIENT, floor_mm)
        w1_needed = _input_for(level, cap, params.deep_drainage_coefficient, s)
        need = w1_needed - state.plant_available_water_mm  # infiltrated water wanted today
        have = _infiltrated(rain, s)
        lo = np.zeros(slot.size)
        hi = np.full(slot.size, ACTION_HIGH_MM)
        want = need > have + 1e-9
        for _ in range(40):  # bisection on the irrigation amount (infiltration is increasing in P)
            mid = 0.5 * (lo + hi)
            ok = _infiltrated(rain + mid, s) >= need
            hi = np.where(ok, mid, hi)
            lo = np.where(ok, lo, mid)
        amount = np.where(want & (d < stop_day) & ~state.mature, hi, 0.0)
        out[d] = amount
        state, _ = m.step(params, state, day, amount)
    return [out[:days, i * n:(i + 1) * n] for i, days in enumerate(lengths)]


def _column_parameters(contexts: list[SeasonContext], slot: np.ndarray):
    """FieldParameters with column j holding the (one-field) parameters of ``contexts[slot[j]]``."""
    m = _model()
    for c in contexts:
        if c.params.n_fields != 1:
            raise ValueError(f"oracle: season {c.name!r} has parameters for {c.params.n_fields} fields, not one")
    return m.FieldParameters(**{f.name: np.concatenate([np.broadcast_to(getattr(c.params, f.name), (1,))
                                                        for c in contexts])[slot]
                                for f in fields(m.FieldParameters)})


def _weather_by_day(contexts: list[SeasonContext]) -> np.ndarray:
    """(D_max, 5, S) model weather (DailyWeather order) of the S contexts, each season padded with its
    last day up to the longest: ``weather[d][:, slots]`` is day d of every column's season."""
    days = max(len(c.rain_mm) for c in contexts)
    series = [[c.tmax_degc, c.tmin_degc, c.srad_mj_m2, c.rain_mm, c.et0_mm] for c in contexts]
    table = np.empty((days, 5, len(contexts)))
    for s, values in enumerate(series):
        for v, a in enumerate(values):
            a = np.asarray(a, dtype=float)
            table[:len(a), v, s] = a
            table[len(a):, v, s] = a[-1]
    return table


@dataclass
class _Trajectory:
    """One field's crop state at the start of days 0..len-1 of ``schedule_mm`` (``fields``: one array per
    CropState field), and its final (mature, maturity day, biomass kg/ha): the run that recorded it
    stopped early only once the field was mature."""

    schedule_mm: np.ndarray
    fields: list
    final: tuple


@dataclass
class _Request:
    """Columns of ``schedules_mm`` (D, n) to score on ``context``. Without ``base``, column 0 is simulated
    from the sowing day and every other column from the first day it differs from column 0, starting
    from column 0's state that day (``record``: keep column 0's trajectory for later requests). With
    ``base``, every column starts from the base trajectory on the first day it differs from its schedule."""

    context: SeasonContext
    schedules_mm: np.ndarray
    base: _Trajectory | None = None
    record: bool = False


@dataclass
class _Evaluation:
    """Return (as :func:`schedule_returns`) and final crop state of each column of a request."""

    returns: np.ndarray
    mature: np.ndarray
    maturity_day: np.ndarray
    biomass_kg_ha: np.ndarray
    trajectory: _Trajectory | None = None


JOIN_BLOCK_DAYS = 8  # columns join the batch on days that are multiples of this
AFTER_BASE_MATURED = -2  # the joining day of a column that leaves its base only after the base matured


def _evaluate(requests: list[_Request]) -> list[_Evaluation]:
    """Score the columns of every request in one batched run; the same returns as
    :func:`schedule_returns` (bit for bit: every column goes through the same daily steps), for less work.

    The candidates of a search round differ from one schedule on a few days: before its first different
    day a column's trajectory is the base's, so it joins the run only on that day (columns sorted by
    joining day: the fields stepped are a prefix of the batch). The run stops when every column is
    mature (its return no longer changes), and a column's final state is taken after its own season's
    last day. Several seasons run in one batch, one model call per day for all of them.
    """
    m = _model()
    # the schedules come from the search, which keeps every amount in [0, ACTION_HIGH_MM]: not checked again
    checked = [np.asarray(request.schedules_mm, dtype=float) for request in requests]
    joins = []  # per column of each request: the first day it is stepped; -1: identical to column 0
    for request, schedules in zip(requests, checked):
        days = schedules.shape[0]
        if days > len(request.context.rain_mm):
            raise ValueError(f"oracle: {days}-day schedules for the {len(request.context.rain_mm)}-day season "
                             f"{request.context.name!r}")
        base = schedules[:, 0] if request.base is None else request.base.schedule_mm[:days]
        differs = schedules != base[:, None]
        join = np.where(differs.any(axis=0), differs.argmax(axis=0), -1)
        if request.base is None:
            join[0] = 0
        else:
            join[join < 0] = 0  # the base schedule itself: from the sowing day
            # leaving the base after its recorded days, when it was mature: the base's crop, own water
            join[join >= len(request.base.fields[0])] = AFTER_BASE_MATURED
        # Joining early is exact (the days before the first difference are the base's days); joining
        # in blocks of days saves the per-day cost of growing the batch.
        joins.append(np.where(join > 0, join - join % JOIN_BLOCK_DAYS, join))
    counts = np.array([s.shape[1] for s in checked])
    offsets = np.concatenate([[0], np.cumsum(counts)])
    join_all = np.concatenate(joins)
    simulated = np.flatnonzero(join_all >= 0)
    order = simulated[np.argsort(join_all[simulated], kind="stable")]  # the batch: columns by joining day
    total = order.size
    position_of = np.full(join_all.size, -1)
    position_of[order] = np.arange(total)
    from_base = np.array([request.base is None for request in requests])
    first = np.where(from_base, position_of[offsets[:-1]], -1)  # column 0's place in the batch
    copies = np.flatnonzero(join_all == -1)
    position_of[copies] = first[np.searchsorted(offsets, copies, side="right") - 1]
    join = join_all[order]
    slot = np.repeat(np.arange(len(requests)), counts)[order]  # request of each column
    # A joining column takes its state from its request's column 0 in the batch, or (a request with a
    # base trajectory) from the trajectory on its joining day: those states are stacked after the batch.
    source = first[slot]
    outside = np.flatnonzero(source < 0)
    source[outside] = total + np.arange(outside.size)
    outside_states = [np.array([requests[slot[p]].base.fields[i][join[p]] for p in outside])
                      for i in range(len(m.CropState._fields))] if outside.size else None
    end_day = np.array([s.shape[0] - 1 for s in checked])[slot]
    contexts = [request.context for request in requests]
    weather = _weather_by_day(contexts)
    days = weather.shape[0]
    irrigation = np.concatenate([np.pad(s, ((0, days - s.shape[0]), (0, 0))) for s in checked], axis=1)[:, order]
    params, per_column = _batch_parameters(contexts, slot)
    joined = np.searchsorted(join, np.arange(days), side="right").tolist()  # columns stepped on day d
    joined_from_outside = set(join[outside].tolist())
    recorded = [r for r, request in enumerate(requests) if request.record and request.base is None]
    record_at = first[recorded]
    history = []
    ends = {int(day): np.flatnonzero(end_day == day) for day in np.unique(end_day)}
    last_join = int(join[-1])
    final = {name: np.empty(total, dtype=dtype) for name, dtype in
             (("mature", bool), ("maturity_day", np.int64), ("biomass_kg_ha", float))}
    stepped = joined[0]
    state = m.initial_state(_column_parameters(contexts, slot[:stepped]))
    day_params = _prefix(params, per_column, stepped)
    weather_until = 0
    for d in range(days):
        k = joined[d]
        if k > stepped:  # columns that leave their base's trajectory today, from its state today
            weather_until = d  # gather the weather again, for the grown batch
            arriving = source[stepped:k]
            if d in joined_from_outside:
                state = m.CropState(*(np.concatenate((a, np.concatenate((a, np.zeros(total - a.size, a.dtype), o))
                                                      [arriving])) for a, o in zip(state, outside_states)))
            else:
                state = m.CropState(*(np.concatenate((a, a[arriving])) for a in state))
            stepped = k
            day_params = _prefix(params, per_column, k)
        if d >= weather_until:  # the batch's weather, gathered for up to JOIN_BLOCK_DAYS days at once
            weather_from, weather_until = d, min(d + JOIN_BLOCK_DAYS, days)
            batch_weather = weather[weather_from:weather_until][:, :, slot[:k]]
        if recorded:
            history.append([a[record_at] for a in state])
        state, _ = m.step(day_params, state, m.DailyWeather(*batch_weather[d - weather_from]), irrigation[d, :k])
        if d in ends:
            for name in final:
                final[name][ends[d]] = getattr(state, name)[ends[d]]
        if d >= last_join and np.all(state.mature | (end_day <= d)):
            still = np.flatnonzero(end_day > d)  # all mature: their final states no longer change
            for name in final:
                final[name][still] = getattr(state, name)[still]
            break
    recorded_fields = [np.stack([day[i] for day in history]) for i in range(len(state))] if recorded else []
    out = []
    for r, (request, schedules) in enumerate(zip(requests, checked)):
        days, n = schedules.shape
        at = position_of[offsets[r]:offsets[r + 1]]
        mature, maturity_day, biomass = (final[name][at] for name in ("mature", "maturity_day", "biomass_kg_ha"))
        late = joins[r] == AFTER_BASE_MATURED
        if late.any():
            if not request.base.final[0]:
                raise ValueError("oracle: a column leaves its base after the base's recorded days")
            mature[late], maturity_day[late], biomass[late] = request.base.final
        harvest_index = np.broadcast_to(request.context.params.harvest_index, (n,))
        last_day = np.where(mature, maturity_day, days - 1)
        counted = np.arange(days)[:, None] <= last_day[None, :]
        water = (schedules * counted).sum(axis=0)
        yield_t_ha = np.where(mature, biomass * harvest_index / 1000.0,
                              request.context.extra.get("unmatured_yield_factor", 0.0)
                              * biomass * harvest_index / 1000.0)
        trajectory = None
        if r in recorded:
            j = recorded.index(r)
            trajectory = _Trajectory(schedules[:, 0].copy(), [by_day[:, j] for by_day in recorded_fields],
                                     (mature[0], maturity_day[0], biomass[0]))
        out.append(_Evaluation(request.context.water_cost_per_mm * water + yield_t_ha, mature, maturity_day,
                               biomass, trajectory))
    return out


def _batch_parameters(contexts: list[SeasonContext], slot: np.ndarray):
    """FieldParameters of a batch whose column j is a field of ``contexts[slot[j]]``: a parameter the
    seasons share stays one value (broadcast by the step; the same arithmetic), the others are per
    column (their names are returned too)."""
    m = _model()
    first = contexts[0].params
    per_column = [f.name for f in fields(m.FieldParameters)
                  if not all(np.array_equal(getattr(c.params, f.name), getattr(first, f.name)) for c in contexts[1:])]
    if not per_column:
        return first, per_column
    by_column = _column_parameters(contexts, slot)
    return replace(first, **{name: getattr(by_column, name) for name in per_column}), per_column


def _prefix(params, per_column: list[str], k: int):
    """The parameters of the first ``k`` columns of a batch."""
    return replace(params, **{name: getattr(params, name)[:k] for name in per_column}) if per_column else params


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
    return find_best_schedules([context], finest_step_mm=finest_step_mm, first_step_mm=first_step_mm,
                               max_rounds_per_step=max_rounds_per_step, shift_window_days=shift_window_days)[0]


def find_best_schedules(contexts: list[SeasonContext], **search_options) -> list[OracleResult]:
    """:func:`find_best_schedule` of every context, the searches run side by side: each round's candidates
    of all seasons are scored in one batched run (the same results as searching one season at a time)."""
    contexts = list(contexts)
    if not contexts:
        return []
    ks, floors = np.meshgrid(FAMILY_K, FAMILY_FLOOR_MM, FAMILY_STOP_DAYS_BEFORE_END, indexing="ij")[:2]
    families = refill_families(contexts, ks.ravel(), floors.ravel(), _family_stop_days)
    searches = [_search(context, family, **search_options) for context, family in zip(contexts, families)]
    waiting = {i: next(search) for i, search in enumerate(searches)}
    results: list[OracleResult | None] = [None] * len(contexts)
    while waiting:
        pending = list(waiting)
        for i, evaluation in zip(pending, _evaluate([waiting[i] for i in pending])):
            try:
                waiting[i] = searches[i].send(evaluation)
            except StopIteration as finished:
                results[i] = finished.value
                del waiting[i]
    return results


# The parametric family's grid: k, floor (mm) and stop day (days before the end of the season's weather).
FAMILY_K = np.array([0.8, 0.9, 0.95, 1.0, 1.02, 1.05, 1.1, 1.2])
FAMILY_FLOOR_MM = np.array([0.0, 40.0, 60.0, 80.0])
FAMILY_STOP_DAYS_BEFORE_END = np.array([0, 10, 20, 30])
FAMILY_CONSTANTS_MM = np.array([0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 15.0])


def _family_stop_days(days: int) -> np.ndarray:
    """The stop day of every family member (k, floor, stop in meshgrid order) of a ``days``-day season."""
    return np.meshgrid(FAMILY_K, FAMILY_FLOOR_MM, days - FAMILY_STOP_DAYS_BEFORE_END, indexing="ij")[2].ravel()


def _search(context: SeasonContext, family: np.ndarray, finest_step_mm: float = 1 / 8, first_step_mm: float = 16.0,
            max_rounds_per_step: int = 60, shift_window_days: int = 5):
    """One season's search (the module docstring's method) as a generator: it yields each batch of
    candidates to score (a :class:`_Request`), receives their :class:`_Evaluation`, and returns the
    :class:`OracleResult`."""
    days = len(context.rain_mm)
    evaluations = 0
    # 1. parametric family
    kk, ff, ss = [a.ravel() for a in np.meshgrid(FAMILY_K, FAMILY_FLOOR_MM, days - FAMILY_STOP_DAYS_BEFORE_END,
                                                 indexing="ij")]
    constants = FAMILY_CONSTANTS_MM
    candidates = np.concatenate([family, np.broadcast_to(constants, (days, constants.size))], axis=1)
    scored = yield _Request(context, candidates)
    returns = scored.returns
    evaluations += candidates.shape[1]
    best_i = int(np.argmax(returns))
    best = candidates[:, best_i].copy()
    best_return = float(returns[best_i])
    best_final = (scored.mature[best_i], scored.maturity_day[best_i], scored.biomass_kg_ha[best_i])
    family_return = best_return
    family_params = ({"k": float(kk[best_i]), "floor_mm": float(ff[best_i]), "stop_day": int(ss[best_i])}
                     if best_i < kk.size else {"constant_mm": float(constants[best_i - kk.size])})
    # 2. coordinate refinement
    active_days = int(best_final[1]) + 1 if best_final[0] else days
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
            # column 0: the current schedule on the active days, the base every move starts from
            full = np.zeros((days, 1 + moves.shape[1]))
            full[:active_days, 0] = best[:active_days]
            full[:active_days, 1:] = moves
            scored = yield _Request(context, full, record=True)
            r = scored.returns[1:]
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
                joined = yield _Request(context, combined[:, None], base=scored.trajectory)
                evaluations += 1
                if joined.returns[0] > best_return + gains.max():
                    new, new_return = combined, float(joined.returns[0])
                    best_final = (joined.mature[0], joined.maturity_day[0], joined.biomass_kg_ha[0])
            if new is None:
                j = int(np.argmax(gains))
                new, new_return = full[:, 1 + j].copy(), float(r[j])
                best_final = (scored.mature[1 + j], scored.maturity_day[1 + j], scored.biomass_kg_ha[1 + j])
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
                                 + context.et0_mm[last] * (1.0 / WATER_UPTAKE_COEFFICIENT - 1.0)))
    stress_free_bound = potential + context.water_cost_per_mm * water_floor
    mature, final_maturity_day, biomass = best_final
    harvest_index = float(np.broadcast_to(context.params.harvest_index, (1,))[0])
    yield_t_ha = float(biomass * harvest_index / 1000.0) if mature else 0.0
    end = int(final_maturity_day) + 1 if mature else days
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

    @staticmethod
    def _key(context: SeasonContext) -> tuple:
        return (context.name, len(context.rain_mm), float(np.sum(context.rain_mm)), float(np.sum(context.et0_mm)),
                context.water_cost_per_mm)

    def plan(self, context: SeasonContext) -> OracleResult:
        """The best schedule of ``context`` (searched once per season, then cached)."""
        return self.plans([context])[0]

    def plans(self, contexts: list[SeasonContext]) -> list[OracleResult]:
        """The best schedule of each context; the seasons not planned yet are searched side by side (one
        batched model run per search round for all of them), then cached."""
        keys = [self._key(c) for c in contexts]
        unplanned = {key: c for key, c in zip(keys, contexts) if key not in self._cache}
        for key, result in zip(unplanned, find_best_schedules(list(unplanned.values()), **self.search_options)):
            self._cache[key] = result
        return [self._cache[key] for key in keys]

    def begin_season(self, context) -> None:
        self.results = self.plans(list(context) if isinstance(context, (list, tuple)) else [context])

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
