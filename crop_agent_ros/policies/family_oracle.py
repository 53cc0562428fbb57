"""The task family's hindsight oracle: each field's best irrigation schedule under its quota, capacity, event
cost and prices, found knowing the season's true weather.

The task family (``crop_sim_ros.task.core``) pays, per field and episode, in reward units (USD/ha)::

    value_per_t x dry yield t/ha on the maturity day - water_cost_per_mm x applied mm (every day up to and
    including the maturity day) - event_cost x (days with water)

and applies ``min(request, capacity_mm_per_day, quota left)``. The oracle plans every field's whole schedule
before the season, knowing its true weather (every future rain), its episode terms (value per t, water cost
per mm, quota mm) and the task's constants (capacity mm/d, event cost): a :class:`FieldProblem`. Every
schedule it returns is feasible (each day in [0, capacity], total <= quota, nothing after maturity), so the
environment applies it unchanged and pays the planned return.

Method (all fields of a call are searched side by side: each round's candidates of every field are the
columns of one batched run of :func:`crop_sim_ros.model.step`; a candidate that differs from its field's
current schedule from day d on joins the run on day d from that schedule's state):

1. **Starts** (:data:`START_NAMES`; by default "plan" and "family", and the best end wins):

   - ``"plan"``: the best of the global plans of :func:`crop_agent_ros.policies.family_dp.plan`, a dynamic
     programme over the soil water and SIMPLE's senescence state with the quota priced by a sweep of
     multipliers (see that module): no start schedule or rule involved.
   - ``"family"``: the best member of a parametric family that generalises the paper oracle's just-in-time
     refill (:mod:`crop_agent_ros.policies.oracle`): each day the least water that brings the soil, after
     runoff and drainage, to ``max(k ET0 / 0.096, floor_mm)`` (the level at which SIMPLE's crop transpires k
     ET0), cut to the capacity and to the quota left, only on days ``start_day <= d < stop_day`` and only when
     the need is at least a least amount (event costs); a grid over k (levels below 1 spread a quota's
     stress), floor, start day (keep the quota for later), stop day (before the TT maturity day) and least
     amount, and constant amounts.
   - ``"uniform"``: the quota (without one: the season's ET0 - rain - initial soil water) spread evenly over
     the days to the TT maturity day, at most the capacity.
   - or given feasible schedules (e.g. a rule's realised schedule).
2. **Local search with feasibility-preserving moves** at step s = min(16, capacity) mm, halved down to
   ``finest_step_mm`` (1/8 mm): +s on a day (within the capacity; accepted only within the quota), -s on a
   day, shifts of s mm from day i to day j (the total kept: the moves that matter under a binding quota) for
   ``|i - j| <= shift_window_days``, and, in a second batch of the same round, shifts between the
   ``pair_days`` days where +s gains most and those where -s loses least (any distance apart); with an event
   cost also "drop a day" and "merge a day into a wet day". Each round takes the best feasible move, or the
   greedy combination of the improving feasible moves on disjoint days when it gains more. At the finest
   step no move improves: a local optimum of this neighbourhood.

Why several starts: under a binding quota the return is far from concave in the schedule (water stress on
any day advances senescence, so the crop is better stressed hard in some spells and kept unstressed in
others); measured on benton-quota, the returns along the straight line between two searches' ends dip by
15-40 USD/ha, and single starts end up to 1 % apart. The plan start is the strongest; the family start
rescues the fields where it is not.

Evidence (:func:`report`, this module's command line): the searches from the plan, family and uniform
starts end close together, and :func:`crop_agent_ros.policies.family_dp.upper_bound` is a rigorous upper
bound on every feasible schedule's return (tight without a quota; loose under a binding one, where it
ignores the senescence that water stress advances); ``potential_bound`` (value x the season's yield
without water stress) is a second, looser one.

    python -m crop_agent_ros.policies.family_oracle --task benton-quota --seasons 0..9 [--bound-step-mm 0.25]
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, fields, replace

import numpy as np

from crop_sim_ros import model
from crop_sim_ros.model.simple import WATER_UPTAKE_COEFFICIENT
from crop_sim_ros.task import core
from crop_sim_ros.task.layout import EXTENDED

from .base import DAYS_SINCE_SOWING, BasePolicy, SeasonContext
from .family_dp import plan, upper_bound, water_input_for
from .rollout import contexts_with_terms, draw_terms, scenario_of, season_contexts, season_range

TERM_NAMES = ("yield_value_per_t", "water_cost_per_mm", "quota_mm")  # core.EpisodeTerms, in SeasonContext.extra
QUOTA_MARGIN_MM = 1e-6


@dataclass(frozen=True)
class TaskConstants:
    """What every field of a task shares: the most applied in one day (mm d-1: the system's capacity, or the
    action bound when it has none) and the cost of each day with irrigation (reward units)."""

    capacity_mm_per_day: float
    event_cost: float = 0.0

    @classmethod
    def of_scenario(cls, scenario) -> "TaskConstants":
        params = core.task_params(scenario_of(scenario))
        return cls(float(min(params.capacity_mm_per_day, params.max_irrigation_mm)), float(params.event_cost))


@dataclass(frozen=True)
class FieldProblem:
    """One field's planning problem: its season (true weather, one field's parameters) and terms.

    ``yield_value_per_t``: reward units per t ha-1 of dry yield; ``water_cost_per_mm``: reward units per mm
    applied (>= 0); ``quota_mm``: the season's allocation (inf: none); ``capacity_mm_per_day``: most applied
    in one day; ``event_cost``: reward units per day with water; ``frozen_days``: the schedule's first
    ``frozen_days`` days are already applied, and the search keeps them as the start schedule has them (a
    causal planner's re-plan in mid-season, experiments/planners_mpc.py; such problems need given starts)."""

    context: SeasonContext
    yield_value_per_t: float
    water_cost_per_mm: float
    quota_mm: float
    capacity_mm_per_day: float
    event_cost: float = 0.0
    frozen_days: int = 0

    def __post_init__(self) -> None:
        if not 0 <= int(self.frozen_days) <= self.days:
            raise ValueError(f"family oracle: frozen_days of {self.context.name!r} must be in [0, {self.days}] "
                             f"(the season's days), got {self.frozen_days!r}")
        object.__setattr__(self, "frozen_days", int(self.frozen_days))
        for name in ("yield_value_per_t", "water_cost_per_mm", "quota_mm", "capacity_mm_per_day", "event_cost"):
            value = float(getattr(self, name))
            if np.isnan(value) or value < 0 or (np.isinf(value) and name != "quota_mm"):
                raise ValueError(f"family oracle: {name} of {self.context.name!r} must be a finite number >= 0"
                                 f"{' (quota: or inf)' if name == 'quota_mm' else ''}, got {getattr(self, name)!r}")
            object.__setattr__(self, name, value)
        if self.context.params.n_fields != 1:
            raise ValueError(f"family oracle: season {self.context.name!r} has parameters for "
                             f"{self.context.params.n_fields} fields, not one")

    @property
    def days(self) -> int:
        return len(self.context.rain_mm)


def field_problems(contexts: list[SeasonContext], constants: TaskConstants) -> list[FieldProblem]:
    """The problems of fields whose contexts carry their episode terms (``context.extra["terms"]``, as
    :func:`crop_agent_ros.policies.rollout.contexts_with_terms` attaches them)."""
    problems = []
    for context in contexts:
        terms = context.extra.get("terms")
        if terms is None or any(name not in terms for name in TERM_NAMES):
            raise ValueError(f"family oracle: season {context.name!r} carries no episode terms "
                             f"(context.extra['terms'] with {', '.join(TERM_NAMES)}): see rollout.contexts_with_terms")
        problems.append(FieldProblem(context, *(float(terms[name]) for name in TERM_NAMES),
                                     constants.capacity_mm_per_day, constants.event_cost))
    return problems


class _Fields:
    """The arrays of P field problems that every batched run reads: weather by day (D, 5, P) in DailyWeather
    order (each season padded with its last day), lengths, terms, parameters (shared when equal), and each
    field's TT maturity day (the last day any schedule can be counted on)."""

    def __init__(self, problems: list[FieldProblem]):
        self.problems = problems
        self.n = len(problems)
        self.n_days = np.array([p.days for p in problems])
        self.width = int(self.n_days.max())
        weather = np.empty((self.width, 5, self.n))
        for i, p in enumerate(problems):
            c = p.context
            for v, series in enumerate((c.tmax_degc, c.tmin_degc, c.srad_mj_m2, c.rain_mm, c.et0_mm)):
                series = np.asarray(series, dtype=float)
                weather[:len(series), v, i] = series
                weather[len(series):, v, i] = series[-1]
        self.weather = weather
        self.value_per_t = np.array([p.yield_value_per_t for p in problems])
        self.cost_per_mm = np.array([p.water_cost_per_mm for p in problems])
        # Plans stay QUOTA_MARGIN_MM within the quota, so that the environment's running sum of the applied
        # water (float rounding) never cuts a planned amount.
        self.quota_mm = np.maximum(np.array([p.quota_mm for p in problems]) - QUOTA_MARGIN_MM, 0.0)
        self.capacity_mm = np.array([p.capacity_mm_per_day for p in problems])
        self.event_cost = np.array([p.event_cost for p in problems])
        self.first_free_day = np.array([p.frozen_days for p in problems], dtype=np.int64)
        first = problems[0].context.params
        self.shared = all(all(np.array_equal(getattr(p.context.params, f.name), getattr(first, f.name))
                              for f in fields(model.FieldParameters)) for p in problems[1:])
        self.params = first if self.shared else model.stack_parameters([p.context.params for p in problems])
        harvest_index = np.broadcast_to(self.params.harvest_index, (self.n,))
        # reward units per kg ha-1 of biomass at maturity
        self.value_per_kg_biomass = self.value_per_t * harvest_index / 1000.0
        self.tt_maturity_day = self._tt_maturity_days()

    def params_of(self, owner: np.ndarray):
        """FieldParameters of columns owned by the fields ``owner`` (shared: the one field, broadcast)."""
        if self.shared:
            return self.params
        return model.FieldParameters(**{f.name: getattr(self.params, f.name)[owner]
                                        for f in fields(model.FieldParameters)})

    def _tt_maturity_days(self) -> np.ndarray:
        """The day each field's crop reaches its thermal time to maturity (water cannot change it; stress can
        only bring maturity earlier, by senescence); the season's last day if it never does."""
        p = self.params
        tmean = 0.5 * (self.weather[:, 0] + self.weather[:, 1])
        dtt = np.maximum(tmean - np.broadcast_to(p.base_temperature_degc, (self.n,)), 0.0)
        next_tt = np.broadcast_to(p.initial_thermal_time_degc_d, (self.n,)) + np.cumsum(dtt, axis=0)
        matures = next_tt > np.broadcast_to(p.thermal_time_to_maturity_degc_d, (self.n,))
        day = np.where(matures.any(axis=0), matures.argmax(axis=0), self.width)
        return np.minimum(day, self.n_days - 1)


@dataclass
class _Runs:
    """Per column of a batched run: return (reward units), maturity, maturity day, water (mm) and events
    counted (days up to and including the maturity day, or the season's last day)."""

    returns: np.ndarray
    mature: np.ndarray
    maturity_day: np.ndarray
    water_mm: np.ndarray
    events: np.ndarray
    biomass_kg_ha: np.ndarray


def _run(fs: _Fields, bases: np.ndarray, base_owner: np.ndarray, cand_base: np.ndarray | None = None,
         cand_days: np.ndarray | None = None, cand_values: np.ndarray | None = None) -> tuple[_Runs, _Runs]:
    """Run B base schedules (``bases`` (D, B), column b for field ``base_owner[b]``) from the sowing day and C
    candidates, each its base ``cand_base[c]`` with up to two days changed (``cand_days`` (C, 2), -1 for
    none; ``cand_values`` (C, 2) the new mm). A candidate joins the batch on its first changed day from its
    base's state that day (before it, it is its base), so a move late in the season costs only its days.
    The run stops when every column is mature or past its season. Returns the bases' and the candidates'
    :class:`_Runs`."""
    b = bases.shape[1]
    if cand_base is None:
        cand_base = np.zeros(0, dtype=np.int64)
        cand_days = np.zeros((0, 2), dtype=np.int64)
        cand_values = np.zeros((0, 2))
    c = len(cand_base)
    never = np.iinfo(np.int64).max
    join = np.where(cand_days >= 0, cand_days, never).min(axis=1) if c else np.zeros(0, dtype=np.int64)
    order = np.argsort(join, kind="stable")
    col_base = np.concatenate([np.arange(b), cand_base[order]])
    col_owner = base_owner[col_base]
    col_join = np.concatenate([np.zeros(b, dtype=np.int64), join[order]])
    day1 = np.concatenate([np.full(b, -1), cand_days[order, 0]])
    day2 = np.concatenate([np.full(b, -1), cand_days[order, 1]])
    value1 = np.concatenate([np.zeros(b), cand_values[order, 0]])
    value2 = np.concatenate([np.zeros(b), cand_values[order, 1]])
    total = b + c
    end_day = fs.n_days[col_owner] - 1
    joined = np.searchsorted(col_join, np.arange(fs.width), side="right")
    value_per_kg = fs.value_per_kg_biomass[col_owner]
    final_mature = np.zeros(total, dtype=bool)
    final_day = np.full(total, -1, dtype=np.int64)
    final_biomass = np.zeros(total)
    params_all = fs.params_of(col_owner)

    def prefix(count: int):  # the parameters of the first ``count`` batch columns
        return params_all if fs.shared else replace(
            params_all, **{f.name: getattr(params_all, f.name)[:count] for f in fields(model.FieldParameters)})

    k = b
    params = prefix(k)
    state = model.initial_state(model.repeat_parameters(fs.params, k) if fs.shared else params)
    water = np.zeros(k)
    events = np.zeros(k)
    ends = {int(d): np.flatnonzero(end_day == d) for d in np.unique(end_day)}
    recorded = np.zeros(total, dtype=bool)
    for d in range(fs.width):
        arriving = int(joined[d])
        if arriving > k:
            source = col_base[k:arriving]  # the bases sit at batch positions 0..b-1
            state = model.CropState(*(np.concatenate([a, a[source]]) for a in state))
            water = np.concatenate([water, water[source]])
            events = np.concatenate([events, events[source]])
            k = arriving
            params = prefix(k)
        irrigation = bases[d, col_base[:k]]
        irrigation = np.where(day1[:k] == d, value1[:k], irrigation)
        irrigation = np.where(day2[:k] == d, value2[:k], irrigation)
        counted = ~state.mature & (d <= end_day[:k])
        water = water + np.where(counted, irrigation, 0.0)
        events = events + (counted & (irrigation > 0.0))
        weather = model.DailyWeather(*np.take(fs.weather[d], col_owner[:k], axis=1))
        state, _ = model.step(params, state, weather, irrigation)
        if d in ends:
            done = ends[d][ends[d] < k]
            final_mature[done] = state.mature[done]
            final_day[done] = state.maturity_day[done]
            final_biomass[done] = state.biomass_kg_ha[done]
            recorded[done] = True
        if k == total and np.all(state.mature | (end_day[:k] <= d)):
            rest = ~recorded
            final_mature[rest] = state.mature[rest]
            final_day[rest] = state.maturity_day[rest]
            final_biomass[rest] = state.biomass_kg_ha[rest]
            break
    returns = (np.where(final_mature, value_per_kg * final_biomass, 0.0) - fs.cost_per_mm[col_owner] * water
               - fs.event_cost[col_owner] * events)
    runs = _Runs(returns, final_mature, final_day, water, events, final_biomass)
    position = np.empty(c, dtype=np.int64)
    position[order] = b + np.arange(c)

    def pick(index: np.ndarray) -> _Runs:
        return _Runs(*(getattr(runs, f.name)[index] for f in fields(_Runs)))

    return pick(np.arange(b)), pick(position)


# The family's grid (see the module docstring): level factor k, floor (mm), first day, days before the TT
# maturity day it stops, constant amounts (fractions of the capacity), and least amounts (fractions of the
# capacity; only with an event cost).
FAMILY_K = (0.6, 0.8, 0.9, 1.0, 1.05, 1.15)
FAMILY_FLOOR_MM = (0.0, 60.0, 90.0)
FAMILY_START_DAY = (0, 20, 40, 60)
FAMILY_STOP_BEFORE_MATURITY_DAYS = (0, 10, 20, 35)
FAMILY_CONSTANT_FRACTIONS = (0.0, 0.25, 0.5, 0.75, 1.0)
FAMILY_LEAST_AMOUNT_FRACTIONS = (0.0, 0.5, 1.0)


def _family_members(with_event_cost: bool) -> dict:
    """The family's members as arrays: k, floor_mm, start_day, stop_before (days), constant (fraction of the
    capacity; NaN: a refill member), least (fraction of the capacity)."""
    least = FAMILY_LEAST_AMOUNT_FRACTIONS if with_event_cost else (0.0,)
    grid = np.meshgrid(FAMILY_K, FAMILY_FLOOR_MM, FAMILY_START_DAY, FAMILY_STOP_BEFORE_MATURITY_DAYS, least,
                       indexing="ij")
    refill = dict(zip(("k", "floor_mm", "start_day", "stop_before", "least"), (g.ravel() for g in grid)))
    refill["constant"] = np.full(refill["k"].size, np.nan)
    n = len(FAMILY_CONSTANT_FRACTIONS)
    constant = {"k": np.zeros(n), "floor_mm": np.zeros(n), "start_day": np.zeros(n), "stop_before": np.zeros(n),
                "least": np.zeros(n), "constant": np.array(FAMILY_CONSTANT_FRACTIONS)}
    return {name: np.concatenate([refill[name], constant[name]]) for name in refill}


def _family_runs(fs: _Fields, owner: np.ndarray, members: dict, record: bool = False):
    """Returns (reward units) of the family members ``members`` (arrays, one per column) for the fields
    ``owner``, and with ``record`` their schedules (D, columns)."""
    n = len(owner)
    params = fs.params_of(owner)
    state = model.initial_state(model.repeat_parameters(fs.params, n) if fs.shared else params)
    capacity_soil = np.broadcast_to(params.capacity_mm, (n,))
    retention = np.broadcast_to(params.runoff_retention_mm, (n,))
    ddc = np.broadcast_to(params.deep_drainage_coefficient, (n,))
    cap = fs.capacity_mm[owner]
    quota = fs.quota_mm[owner]
    stop = fs.tt_maturity_day[owner] + 1 - members["stop_before"]
    constant = members["constant"] * cap
    is_constant = ~np.isnan(members["constant"])
    least = members["least"] * cap
    end_day = fs.n_days[owner] - 1
    used = np.zeros(n)
    water = np.zeros(n)
    events = np.zeros(n)
    schedules = np.zeros((fs.width, n)) if record else None
    for d in range(fs.width):
        weather = model.DailyWeather(*np.take(fs.weather[d], owner, axis=1))
        level = np.maximum(members["k"] * weather.et0_mm / WATER_UPTAKE_COEFFICIENT, members["floor_mm"])
        with np.errstate(divide="ignore"):
            before_drainage = np.where(level > capacity_soil,
                                       np.where(ddc < 1.0, capacity_soil + (level - capacity_soil) / (1.0 - ddc),
                                                np.inf), level)
        need = before_drainage - state.plant_available_water_mm
        refill = np.maximum(water_input_for(need, retention) - weather.rain_mm, 0.0)
        amount = np.where(is_constant, constant, refill)
        amount = np.where((amount >= least) & (members["start_day"] <= d) & (d < stop) & ~state.mature,
                          amount, 0.0)
        amount = np.minimum(np.minimum(amount, cap), np.maximum(quota - used, 0.0))
        amount = np.where(amount > 1e-9, amount, 0.0)
        counted = ~state.mature & (d <= end_day)
        used += amount
        water += np.where(counted, amount, 0.0)
        events += counted & (amount > 0.0)
        if record:
            schedules[d] = np.where(d <= end_day, amount, 0.0)
        state, _ = model.step(params, state, weather, amount)
        if np.all(state.mature | (end_day <= d)):
            break
    returns = (np.where(state.mature, fs.value_per_kg_biomass[owner] * state.biomass_kg_ha, 0.0)
               - fs.cost_per_mm[owner] * water - fs.event_cost[owner] * events)
    return returns, schedules


def _family_start(fs: _Fields, fields_chunk: int = 64) -> np.ndarray:
    """Each field's best family member's schedule (D, P)."""
    members = _family_members(bool(np.any(fs.event_cost > 0)))
    size = members["k"].size
    best = np.empty(fs.n, dtype=np.int64)
    for first in range(0, fs.n, fields_chunk):  # chunks bound the memory of fields x members columns
        chunk = np.arange(first, min(first + fields_chunk, fs.n))
        returns, _ = _family_runs(fs, np.repeat(chunk, size), {k: np.tile(v, len(chunk)) for k, v in members.items()})
        best[chunk] = returns.reshape(len(chunk), size).argmax(axis=1)
    return _family_runs(fs, np.arange(fs.n), {k: v[best] for k, v in members.items()}, record=True)[1]


def _uniform_start(fs: _Fields) -> np.ndarray:
    """Each field's quota (without one: the season's ET0 - rain - initial soil water to the TT maturity day)
    spread evenly over the days to the TT maturity day, at most the capacity: schedules (D, P)."""
    schedules = np.zeros((fs.width, fs.n))
    initial = np.broadcast_to(fs.params.initial_paw_mm, (fs.n,))
    for i in range(fs.n):
        days = int(fs.tt_maturity_day[i]) + 1
        deficit = float(np.sum(fs.weather[:days, 4, i] - fs.weather[:days, 3, i]) - initial[i])
        schedules[:days, i] = min(fs.capacity_mm[i], min(fs.quota_mm[i], max(deficit, 0.0)) / days)
    return schedules


def _plan_start(fs: _Fields) -> np.ndarray:
    """Each field's best plan of the dynamic programme (:func:`crop_agent_ros.policies.family_dp.plan`, one
    plan per quota multiplier): schedules (D, P)."""
    schedules = np.zeros((fs.width, fs.n))
    for i, problem in enumerate(fs.problems):
        candidates = plan(problem)
        plans = np.zeros((fs.width, candidates.shape[1]))
        plans[:problem.days] = candidates
        returns = _run(fs, plans, np.full(plans.shape[1], i))[0].returns
        schedules[:, i] = plans[:, int(np.argmax(returns))]
    return schedules


START_NAMES = ("plan", "family", "uniform")
DEFAULT_STARTS = ("plan", "family")


def _start_schedules(fs: _Fields, start) -> np.ndarray:
    """Start schedules (D, P): ``start`` is a START_NAMES entry, or one feasible (D,) schedule per field."""
    if isinstance(start, str):
        if np.any(fs.first_free_day > 0):
            raise ValueError(f"family oracle: the {start!r} start plans whole seasons; problems with frozen days "
                             f"need given start schedules (the applied days, then a plan)")
        makers = {"plan": _plan_start, "family": _family_start, "uniform": _uniform_start}
        if start not in makers:
            raise ValueError(f"family oracle: unknown start {start!r}; known: {', '.join(START_NAMES)}, or schedules")
        return makers[start](fs)
    schedules = np.zeros((fs.width, fs.n))
    if len(start) != fs.n:
        raise ValueError(f"family oracle: {len(start)} start schedules for {fs.n} fields")
    for i, (p, given) in enumerate(zip(fs.problems, start)):
        given = np.array(given, dtype=float)
        if given.shape != (p.days,):
            raise ValueError(f"family oracle: the start schedule of {p.context.name!r} has shape {given.shape}, "
                             f"not one amount per day of the season ({p.days},)")
        if not _feasible(given, p, QUOTA_MARGIN_MM):
            raise ValueError(f"family oracle: the start schedule of {p.context.name!r} is not feasible (each day "
                             f"in [0, {p.capacity_mm_per_day:g}] mm, total <= {p.quota_mm:g} mm)")
        # within the planning quota: an environment's realised schedule may use the quota to the last ulp
        schedules[:p.days, i] = within_quota(given, fs.quota_mm[i])
    return schedules


def within_quota(schedule: np.ndarray, quota_mm: float) -> np.ndarray:
    """``schedule`` (mm per day) with water taken off its last wet days until its total is within ``quota_mm``."""
    out = np.array(schedule, dtype=float)
    for d in np.flatnonzero(out)[::-1]:
        excess = out.sum() - quota_mm
        if excess <= 0.0:
            break
        out[d] = max(out[d] - excess, 0.0)
    return out


def _feasible(schedule: np.ndarray, problem: FieldProblem, tolerance_mm: float = 0.0) -> bool:
    """Each day in [0, capacity] and the total within the quota (+ ``tolerance_mm``): the environment applies
    it unchanged."""
    return bool(np.all(np.isfinite(schedule)) and np.all(schedule >= 0.0)
                and np.all(schedule <= problem.capacity_mm_per_day)
                and schedule.sum() <= problem.quota_mm + tolerance_mm)


# --- local search ---------------------------------------------------------------------------------------------

PLUS, MINUS, SHIFT, DROP, MERGE = range(5)  # kinds of moves


@dataclass
class _Moves:
    """Candidate moves of one field's schedule: the changed days (n, 2) (-1: none), their new values (n, 2)
    mm, the change of the season's water (n,) mm, and the kind of each move (PLUS .. MERGE)."""

    days: np.ndarray
    values: np.ndarray
    delta_mm: np.ndarray
    kind: np.ndarray

    def __len__(self) -> int:
        return len(self.kind)

    def applied(self, schedule: np.ndarray, index: int) -> np.ndarray:
        out = schedule.copy()
        for d, v in zip(self.days[index], self.values[index]):
            if d >= 0:
                out[d] = v
        return out


def _moves(a: np.ndarray, last: int, step: float, cap: float, window: int, event_cost: float,
           first: int = 0) -> _Moves:
    """+step and -step on each day of first..last (within [0, cap]), shifts of step mm between days at most
    ``window`` apart, and with an event cost "drop a day" and "merge a day into a wet day within window"
    (days before ``first`` are frozen: no move touches them)."""
    days = np.arange(last + 1)
    x = a[:last + 1]
    parts = []

    def add(d1, v1, d2, v2, kind):
        d2, v2 = np.broadcast_to(d2, d1.shape), np.broadcast_to(v2, d1.shape)
        delta = (v1 - x[d1]) + np.where(d2 >= 0, v2 - x[np.maximum(d2, 0)], 0.0)
        parts.append((np.stack([d1, d2], 1), np.stack([v1, v2], 1), delta, np.full(d1.size, kind)))

    room = x < cap
    add(days[room], np.minimum(x[room] + step, cap), -1, 0.0, PLUS)
    wet = x > 0.0
    add(days[wet], np.maximum(x[wet] - step, 0.0), -1, 0.0, MINUS)
    if event_cost > 0.0:
        big = x > step
        add(days[big], np.zeros(int(big.sum())), -1, 0.0, DROP)
    for offset in [o for o in range(-window, window + 1) if o]:
        i = days[max(0, -offset):last + 1 - max(0, offset)]
        j = i + offset
        ok = (x[i] > 0.0) & (x[j] < cap)
        amount = np.minimum(np.minimum(step, x[i]), cap - x[j])[ok]
        add(i[ok], x[i][ok] - amount, j[ok], x[j][ok] + amount, SHIFT)
        if event_cost > 0.0:
            ok = (x[i] > 0.0) & (x[j] > 0.0) & (x[i] + x[j] <= cap)
            add(i[ok], np.zeros(int(ok.sum())), j[ok], x[i][ok] + x[j][ok], MERGE)
    days_, values, delta, kind = (np.concatenate(z) for z in zip(*parts))
    free = np.all((days_ < 0) | (days_ >= first), axis=1)
    return _Moves(days_[free].astype(np.int64), values[free], delta[free], kind[free])


def _pair_moves(a: np.ndarray, moves: _Moves, gains: np.ndarray, step: float, cap: float, window: int,
                pairs: int) -> _Moves:
    """Shifts of step mm from each of the ``pairs`` days whose -step loses least to each of the ``pairs``
    days whose +step gains most, further apart than ``window`` (nearer pairs are among the moves already)."""
    plus, minus = moves.kind == PLUS, moves.kind == MINUS
    to_days = moves.days[plus, 0][np.argsort(-gains[plus], kind="stable")[:pairs]]
    from_days = moves.days[minus, 0][np.argsort(-gains[minus], kind="stable")[:pairs]]
    i, j = (g.ravel() for g in np.meshgrid(from_days, to_days, indexing="ij"))
    amount = np.minimum(np.minimum(step, a[i]), cap - a[j])
    keep = (np.abs(i - j) > window) & (amount > 0.0)
    i, j, amount = i[keep], j[keep], amount[keep]
    return _Moves(np.stack([i, j], 1), np.stack([a[i] - amount, a[j] + amount], 1), np.zeros(i.size),
                  np.full(i.size, SHIFT))


def _combined(a: np.ndarray, moves: _Moves, gains: np.ndarray, room_mm: float) -> np.ndarray | None:
    """The improving moves on disjoint days, best first, while the quota's ``room_mm`` lasts, all applied to
    ``a``: a new schedule, or None if fewer than two combine."""
    order = np.flatnonzero(gains > 0.0)
    order = order[np.argsort(-gains[order], kind="stable")]
    used: set = set()
    out = a.copy()
    taken = 0
    for index in order:
        days = [int(d) for d in moves.days[index] if d >= 0]
        if used.intersection(days) or moves.delta_mm[index] > room_mm:
            continue
        out = moves.applied(out, index)
        used.update(days)
        room_mm -= moves.delta_mm[index]
        taken += 1
    return out if taken >= 2 else None


def _stacked(moves: list[_Moves]):
    """(cand_base, cand_days, cand_values) of every field slot's moves, for :func:`_run`."""
    if not sum(len(mv) for mv in moves):
        return None, None, None
    return (np.concatenate([np.full(len(mv), slot, dtype=np.int64) for slot, mv in enumerate(moves)]),
            np.concatenate([mv.days for mv in moves]), np.concatenate([mv.values for mv in moves]))


def _local_search(fs: _Fields, schedules: np.ndarray, finest_step_mm: float, first_step_mm: float,
                  max_rounds_per_step: int, shift_window_days: int, pair_days: int) -> dict:
    """Improve every field's schedule by the module docstring's moves until none improves at the finest step
    (or ``max_rounds_per_step`` rounds at a step). Returns the schedules (D, P) (0 after each maturity day),
    their returns and per-field counts of rounds and evaluations, and the last accepted gain."""
    schedules = schedules.copy()
    runs, _ = _run(fs, schedules, np.arange(fs.n))
    returns = runs.returns.copy()
    last_day = np.where(runs.mature, runs.maturity_day, fs.n_days - 1)
    for i in range(fs.n):
        schedules[last_day[i] + 1:, i] = 0.0  # never applied: the episode ends on the maturity day
    step = np.minimum(first_step_mm, fs.capacity_mm)
    active = step >= finest_step_mm
    rounds = np.zeros(fs.n, dtype=np.int64)
    rounds_at_step = np.zeros(fs.n, dtype=np.int64)
    evaluations = np.zeros(fs.n, dtype=np.int64)
    last_gain = np.zeros(fs.n)
    while active.any():
        slots = np.flatnonzero(active)
        current = schedules[:, slots]
        room = fs.quota_mm[slots] - current.sum(axis=0)
        moves = [_moves(current[:, k], int(last_day[i]), step[i], fs.capacity_mm[i], shift_window_days,
                        fs.event_cost[i], int(fs.first_free_day[i])) for k, i in enumerate(slots)]
        base, runs = _run(fs, current, slots, *_stacked(moves))
        ends = np.cumsum([len(mv) for mv in moves])
        gains = [g - base.returns[k] for k, g in enumerate(np.split(runs.returns, ends[:-1]))]
        # second batch: long shifts between the best +step and -step days; each field's combination
        pairs = [_pair_moves(current[:, k], moves[k], gains[k], step[i], fs.capacity_mm[i], shift_window_days,
                             pair_days) for k, i in enumerate(slots)]
        combined = [_combined(current[:, k], moves[k], np.where(moves[k].delta_mm <= room[k], gains[k], -np.inf),
                              room[k]) for k in range(len(slots))]
        with_combined = [k for k, c in enumerate(combined) if c is not None]
        bases = np.concatenate([current] + [combined[k][:, None] for k in with_combined], axis=1)
        base2, runs2 = _run(fs, bases, np.concatenate([slots, slots[with_combined]]).astype(np.int64),
                            *_stacked(pairs))
        pair_ends = np.cumsum([len(mv) for mv in pairs])
        pair_gains = [g - base2.returns[k] for k, g in enumerate(np.split(runs2.returns, pair_ends[:-1]))]
        for k, i in enumerate(slots):
            options = []  # (gain, schedule, runs, column)
            feasible = np.flatnonzero(moves[k].delta_mm <= room[k])
            if feasible.size:
                j = feasible[np.argmax(gains[k][feasible])]
                options.append((gains[k][j], moves[k].applied(current[:, k], j), runs, ends[k] - len(moves[k]) + j))
            if len(pairs[k]):
                j = int(np.argmax(pair_gains[k]))
                options.append((pair_gains[k][j], pairs[k].applied(current[:, k], j), runs2,
                                pair_ends[k] - len(pairs[k]) + j))
            if combined[k] is not None:
                column = len(slots) + with_combined.index(k)
                options.append((base2.returns[column] - base2.returns[k], combined[k], base2, column))
            evaluations[i] += len(moves[k]) + len(pairs[k]) + (combined[k] is not None)
            rounds[i] += 1
            rounds_at_step[i] += 1
            gain, schedule, source, column = max(options, key=lambda o: o[0]) if options else (0.0, None, None, 0)
            if gain > 1e-10 * max(abs(returns[i]), 1.0) and rounds_at_step[i] <= max_rounds_per_step:
                last_day[i] = source.maturity_day[column] if source.mature[column] else fs.n_days[i] - 1
                schedule[last_day[i] + 1:] = 0.0
                schedules[:, i] = schedule
                returns[i] = source.returns[column]
                last_gain[i] = gain
            else:
                step[i] /= 2.0
                rounds_at_step[i] = 0
                active[i] = step[i] >= finest_step_mm
    return {"schedules": schedules, "returns": returns, "rounds": rounds, "evaluations": evaluations,
            "last_gain": last_gain}


# --- the oracle -------------------------------------------------------------------------------------------------

@dataclass
class FamilyOracleResult:
    """One field's planned schedule (``schedule_mm`` (D,): each day in [0, capacity], total <= quota, 0 after
    the maturity day) and how it was found. Money in reward units (USD/ha). ``start_returns``: the return the
    search reached from each start (``start``: the best); ``potential_bound``: value per t x the season's
    yield without water stress (no schedule returns more); ``last_gain``: the last accepted move's gain."""

    name: str
    schedule_mm: np.ndarray
    return_value: float
    start: str
    start_returns: dict
    yield_t_ha: float
    water_mm: float
    events: int
    maturity_day: int
    potential_bound: float
    rounds: int
    evaluations: int
    last_gain: float


def plan_fields(problems: list[FieldProblem], starts=DEFAULT_STARTS, finest_step_mm: float = 1 / 8,
                first_step_mm: float = 16.0, max_rounds_per_step: int = 40, shift_window_days: int = 2,
                pair_days: int = 8) -> list[FamilyOracleResult]:
    """Each field's best schedule (the module docstring's method): the local search from each of ``starts``
    (START_NAMES entries, or lists of one feasible (D,) schedule per field), every field and start searched
    side by side; the best end wins."""
    problems = list(problems)
    if not problems:
        return []
    starts = [starts] if isinstance(starts, str) else list(starts)
    if not starts:
        raise ValueError("family oracle: plan_fields needs at least one start")
    fs = _Fields(problems)
    names = [s if isinstance(s, str) else f"given{k}" for k, s in enumerate(starts)]
    everyone = _Fields(problems * len(starts))
    found = _local_search(everyone, np.concatenate([_start_schedules(fs, s) for s in starts], axis=1),
                          finest_step_mm, first_step_mm, max_rounds_per_step, shift_window_days, pair_days)
    ends = found["returns"].reshape(len(starts), fs.n)
    column = ends.argmax(axis=0) * fs.n + np.arange(fs.n)
    runs, _ = _run(fs, found["schedules"][:, column], np.arange(fs.n))
    results = []
    for i, p in enumerate(problems):
        j = column[i]
        schedule = found["schedules"][:p.days, j].copy()
        if not _feasible(schedule, p):
            raise RuntimeError(f"family oracle: planned an infeasible schedule for {p.context.name!r}")
        harvest_index = float(np.broadcast_to(p.context.params.harvest_index, (1,))[0])
        results.append(FamilyOracleResult(
            name=p.context.name, schedule_mm=schedule, return_value=float(runs.returns[i]), start=names[j // fs.n],
            start_returns={name: float(ends[k, i]) for k, name in enumerate(names)},
            yield_t_ha=float(runs.biomass_kg_ha[i] * harvest_index / 1000.0) if runs.mature[i] else 0.0,
            water_mm=float(runs.water_mm[i]), events=int(runs.events[i]),
            maturity_day=int(runs.maturity_day[i]) if runs.mature[i] else -1,
            potential_bound=p.yield_value_per_t * float(p.context.extra.get("potential_yield_t_ha", np.nan)),
            rounds=int(found["rounds"][j]), evaluations=int(found["evaluations"][j]),
            last_gain=float(found["last_gain"][j])))
    return results


class FamilyOraclePolicy(BasePolicy):
    """Plays each field's planned schedule by days since sowing. :meth:`begin_season` takes one
    :class:`SeasonContext` per field (or one for a single field), each carrying its episode terms in
    ``extra["terms"]`` (see :func:`crop_agent_ros.policies.rollout.contexts_with_terms`); ``constants``
    are the task's (:meth:`TaskConstants.of_scenario`). Plans are cached per season and terms."""

    name = "family-oracle"
    observation_sizes = (EXTENDED.size,)

    def __init__(self, constants: TaskConstants, **search_options):
        self.constants = constants
        self.search_options = search_options
        self.results: list[FamilyOracleResult] = []
        self._cache: dict = {}

    @classmethod
    def for_scenario(cls, scenario, **search_options) -> "FamilyOraclePolicy":
        return cls(TaskConstants.of_scenario(scenario), **search_options)

    @staticmethod
    def _key(problem: FieldProblem) -> tuple:
        c = problem.context
        return (c.name, len(c.rain_mm), float(np.sum(c.rain_mm)), float(np.sum(c.et0_mm)), problem.yield_value_per_t,
                problem.water_cost_per_mm, problem.quota_mm, problem.capacity_mm_per_day, problem.event_cost)

    def plans(self, contexts: list[SeasonContext]) -> list[FamilyOracleResult]:
        """The planned result of each field (fields not planned yet are searched side by side)."""
        problems = field_problems(contexts, self.constants)
        keys = [self._key(p) for p in problems]
        todo = {key: p for key, p in zip(keys, problems) if key not in self._cache}
        for key, result in zip(todo, plan_fields(list(todo.values()), **self.search_options)):
            self._cache[key] = result
        return [self._cache[key] for key in keys]

    def begin_season(self, context) -> None:
        self.results = self.plans(list(context) if isinstance(context, (list, tuple)) else [context])

    def _act_batch(self, obs):
        if not self.results:
            raise RuntimeError("family oracle: begin_season(contexts) with each field's season and terms comes first")
        if len(self.results) not in (1, len(obs)):
            raise ValueError(f"family oracle: {len(self.results)} planned fields for {len(obs)} observations")
        out = np.empty(len(obs))
        for i in range(len(obs)):
            schedule = self.results[i if len(self.results) > 1 else 0].schedule_mm
            day = int(np.rint(obs[i, DAYS_SINCE_SOWING]))
            out[i] = schedule[day] if 0 <= day < len(schedule) else 0.0
        return out

    def describe(self):
        return {"name": self.name, **({} if not self.results else {
            "return": [r.return_value for r in self.results], "start": [r.start for r in self.results]})}


# --- evidence: the report ---------------------------------------------------------------------------------------

def season_problems(scenario, seasons, seed: int = 0) -> list[FieldProblem]:
    """One problem per season index of ``scenario``, with one draw of the task's episode terms per season
    (:func:`crop_agent_ros.policies.rollout.draw_terms`, seeded by ``seed``)."""
    scenario = scenario_of(scenario)
    seasons = np.asarray(seasons, dtype=np.int64)
    contexts = season_contexts(scenario)
    fields_ = contexts_with_terms([contexts[k] for k in seasons], draw_terms(scenario, seasons, seed))
    return field_problems(fields_, TaskConstants.of_scenario(scenario))


def report(problems: list[FieldProblem], bound_step_mm: float = 0.25, log=print) -> list[dict]:
    """The oracle on ``problems`` (default starts, all fields at once; CPU seconds per field), the search from
    the uniform start (a second, independent start), and each field's rigorous upper bound
    (:func:`crop_agent_ros.policies.family_dp.upper_bound`; ``bound_step_mm`` 0: none): one row per field."""
    began = time.process_time()
    oracle = plan_fields(problems)
    seconds = (time.process_time() - began) / len(problems)
    uniform = plan_fields(problems, starts=("uniform",))
    rows = []
    for p, o, u in zip(problems, oracle, uniform):
        scale = max(abs(o.return_value), 1.0)
        row = {"field": p.context.name, "quota_mm": p.quota_mm, "return": o.return_value, "start": o.start,
               "family_vs_plan_pct": 100.0 * (o.start_returns["family"] - o.start_returns["plan"]) / scale,
               "uniform_vs_oracle_pct": 100.0 * (u.return_value - o.return_value) / scale,
               "potential_gap_pct": 100.0 * (o.potential_bound - o.return_value) / scale,
               "seconds_per_field": seconds}
        if bound_step_mm > 0:
            bound = upper_bound(p, water_step_mm=bound_step_mm).bound
            row["bound"] = bound
            row["bound_gap_pct"] = 100.0 * (bound - o.return_value) / scale
        rows.append(row)
    log(f"{'field':<22}{'quota mm':>9}{'return':>11}{'start':>7}{'fam-plan%':>10}{'unif-or%':>10}"
        f"{'bound%':>8}{'potent%':>8}")
    for r in rows:
        log(f"{r['field']:<22}{r['quota_mm']:>9.0f}{r['return']:>11.2f}{r['start']:>7}{r['family_vs_plan_pct']:>10.3f}"
            f"{r['uniform_vs_oracle_pct']:>10.3f}{r.get('bound_gap_pct', np.nan):>8.2f}{r['potential_gap_pct']:>8.2f}")
    log(f"oracle: {seconds:.2f} CPU s per field ({len(problems)} fields planned side by side)")
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m crop_agent_ros.policies.family_oracle",
                                     description="the family oracle's evidence table on seasons of a family task")
    parser.add_argument("--task", default="benton-quota", help="family scenario (default benton-quota)")
    parser.add_argument("--seasons", default="0..9", help="season indices 'A..B' (default 0..9)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the terms drawn per season (default 0)")
    parser.add_argument("--bound-step-mm", type=float, default=0.25,
                        help="water grid of the upper bound, mm (0: no bound; default 0.25)")
    args = parser.parse_args(argv)
    try:
        seasons = season_range(args.seasons)
        if not (args.bound_step_mm >= 0.0):
            raise ValueError(f"--bound-step-mm: expected a number >= 0, got {args.bound_step_mm}")
        scenario = scenario_of(args.task)
        if not scenario.is_family_task:
            raise ValueError(f"--task: {args.task!r} is not a family task (it has no money terms)")
        if seasons.max() >= len(core.scenario_table(scenario)):
            raise ValueError(f"--seasons: {args.task} has seasons 0..{len(core.scenario_table(scenario)) - 1}")
        problems = season_problems(scenario, seasons, args.seed)
    except (ValueError, KeyError) as error:
        print(f"family_oracle: {str(error).strip(chr(39))}", file=sys.stderr)
        return 2
    report(problems, args.bound_step_mm)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
